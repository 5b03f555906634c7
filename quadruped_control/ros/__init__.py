"""The ROS nodes of the controller package and their ROS-only helpers (visualisation markers, bag
recording, diagnostic analyzers). The only floor that imports rospy; nodes wire topics, parameters and
timers to the objects of the floors below."""
