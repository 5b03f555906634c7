"""ROS glue that the driver nodes and the controller's nodes share (the only part of quadruped_common that
imports rospy): how every node starts."""
