"""MCAP: the record layer (:mod:`.records`), the ROS 2 Imu reader (:mod:`.read`, :mod:`.inspect`) and
writers (:mod:`.write`)."""
