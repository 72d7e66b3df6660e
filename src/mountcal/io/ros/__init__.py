"""ROS messages from their definitions: types (:mod:`.types`), field offsets on whole arrays (:mod:`.layout`),
and what mountcal reads from them (:mod:`.kinds`)."""
