"""The attitude controller that runs on the robot (paper section "Attitude Controller Design"):
controller configuration, PID on SO(3), torque allocation, stroke schemes, and the supervisor the ROS
node wraps around it. Imports ``model`` and ``quadruped_common`` only."""
