"""Small pieces shared by the controller (``quadruped_control``) and the drivers (``quadruped_drivers``)
without either depending on the other: the strict configuration loader and the table of live-tunable
controller parameters (also read by ``cfg/AttitudeController.cfg``)."""
