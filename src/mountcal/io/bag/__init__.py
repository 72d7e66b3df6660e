"""ROS bags: ROS 1 ``.bag`` files (:mod:`.ros1`) and ROS 2 bag folders (:mod:`.ros2`), located a block at a time
(:mod:`.read`, and :mod:`mountcal.io.mcap.topics` for MCAP storage) and read through the one ROS path
(:mod:`mountcal.io.ros.batches`) that MCAP logs read with ``--field`` share. Above :mod:`mountcal.io.mcap`:
a bag may store MCAP; MCAP never imports a bag module."""
