"""MCAP: the record layer (:mod:`.records`), the ROS 2 Imu reader (:mod:`.read`, :mod:`.inspect`), the topics
read through their definitions (:mod:`.topics`: ``--field``, a ROS 2 bag's MCAP storage) and writers
(:mod:`.write`)."""
