"""ROS 2 messages: the CDR codec of sensor_msgs (:mod:`.cdr`) and the message definitions (:mod:`.definitions`)."""
