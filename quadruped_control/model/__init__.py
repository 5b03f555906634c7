"""The robot model of the paper (section "Mathematical Modeling"): parameters, kinematics, hydrodynamics.

Pure functions of the robot's parameters; the bottom floor of ``quadruped_control`` (imports only
``quadruped_common``)."""
