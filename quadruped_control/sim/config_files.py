"""Every configuration file in ``config/`` and its typed loader (one table for the tests and the fuzz
campaign; each loader reads through the strict loader of :mod:`quadruped_common.config`)."""
from __future__ import annotations

from typing import Any, Callable, Dict

from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants import load_tank_params
from quadruped_control.sim.simulation import load_simulation_settings
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.vn100.settings import load_vn100_settings

#: The tank plants fitted to the paper's Table 1 that the repository ships (docs/tank_model.md, "Fitted to Table
#: 1"): ``--tank-yaml`` / ``sim.launch tank_yaml:=`` them; none is the tank plant's default.
TANK_ENSEMBLE = tuple("tank_ensemble/member_%02d.yaml" % member for member in range(8))

#: file name (relative to config/) -> loader(path) returning the typed, validated object (ParameterError
#: otherwise).
LOADERS: Dict[str, Callable[[str], Any]] = {
    "robot.yaml": load_robot_params,
    "controller.yaml": load_controller_config,
    "hardware.yaml": load_hardware_config,
    "servo_calibration.yaml": load_servo_calibration,
    "simulation.yaml": load_simulation_settings,
    "vn100.yaml": load_vn100_settings,
    "tank.yaml": load_tank_params,
    "tank_identified.yaml": load_tank_params,
    **{name: load_tank_params for name in TANK_ENSEMBLE},
}
