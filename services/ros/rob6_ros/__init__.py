"""rob6 on ROS 2: the robot as a ROS 2 node in rmw_zenoh's format, on rob6's own Zenoh network."""
