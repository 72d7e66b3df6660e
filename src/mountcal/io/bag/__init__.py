"""ROS bags: ROS 1 ``.bag`` files (:mod:`.ros1`) and ROS 2 bag folders (:mod:`.ros2`), read through one path
(:mod:`.read`) that MCAP logs read with ``--field`` share."""
