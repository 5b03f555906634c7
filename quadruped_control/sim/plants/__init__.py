"""Plants: one set of equations of motion, configured.

- ``paper``: the paper's idealised model, eq. (trans), (rot) (:class:`~quadruped_control.sim.plants.paper.FloatingBaseModel`):
  free-floating, no added mass, centre of buoyancy on the centre of mass, torso weight and buoyancy
  balanced by the rope and left out. The default of every study that reproduces the paper's simulation.
- ``tank``: the same forces plus the test tank's rope, torso weight and buoyancy at separate centres,
  torso and paw added mass (:mod:`.tank`; its parameters, one schema: :mod:`.tank_params`, ``config/tank.yaml``).

Both take their forces from :mod:`quadruped_control.model.hydrodynamics` and share the rigid-body state,
input checks and SO(3) Runge-Kutta helpers of :mod:`.rigid_body`.
"""
from __future__ import annotations

from typing import Optional

from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.paper import FloatingBaseModel
from quadruped_control.sim.plants.tank import VALIDITY_NOTE, TankModel
from quadruped_control.sim.plants.tank_params import TankParams, load_tank_params

PLANTS = ("paper", "tank")

__all__ = ["PLANTS", "TankModel", "TankParams", "VALIDITY_NOTE", "load_tank_params", "make_plant"]


def make_plant(name: str, robot: RobotParams, tank: Optional[TankParams] = None) -> FloatingBaseModel:
    """Equations of motion of plant ``name`` ('paper' or 'tank'; ``tank`` default: config/tank.yaml)."""
    if name == "paper":
        return FloatingBaseModel(robot)
    if name == "tank":
        return TankModel(robot, tank if tank is not None else load_tank_params())
    raise ValueError("unknown plant %r (choose from %s)" % (name, ", ".join(PLANTS)))
