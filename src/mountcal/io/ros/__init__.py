"""ROS messages from their definitions: types (:mod:`.types`), field offsets on whole arrays (:mod:`.layout`),
and what mountcal reads from them (:mod:`.kinds`); the container-free part of reading a recording: which
topics (:mod:`.topics`), decoded blocks to samples (:mod:`.batches`, :mod:`.pieces`). Below both containers
(:mod:`mountcal.io.mcap`, :mod:`mountcal.io.bag`), which read through it."""
