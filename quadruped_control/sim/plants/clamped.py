"""The tank plant with its body clamped: the bench on which the strokes' torque is measured.

A real robot's net stroke torque can be measured by holding its body still (a clamp on a load cell, or a
spring balance on a lever) while the controller strokes against a held attitude error. :class:`ClampedTank`
is the same bench in the simulator: the controller, the servos and the legs run as on the free robot,
the paws' wake builds up and decays, the loaded servos feel the paws' drag, and the body stays where it
was attached. After every step :attr:`ClampedTank.torques` gains the torque the clamp takes up,
:meth:`~quadruped_control.sim.plants.tank.TankModel.held_wrench` with the legs as held over that step.
:mod:`quadruped_control.studies.torque_map` runs it against the model's own controller.

It stands in for a plant in :class:`~quadruped_control.sim.simulation.PlantSimulator`, which calls
``attach``, ``leg_input``, ``step_trusted`` and reads ``joint_loads`` and ``imu_field_residual`` (the
closed loop's IMU); nothing else of the plant's interface is offered.
"""
from __future__ import annotations

from typing import Any, List, Optional, Tuple

import numpy as np

from quadruped_control.sim.plants.rigid_body import RigidBodyState
from quadruped_control.sim.plants.tank import TankModel

__all__ = ["ClampedTank"]


class ClampedTank:
    """``model`` (a :class:`~quadruped_control.sim.plants.tank.TankModel`) with its body held at rest at the
    state of the last :meth:`attach`. :attr:`torques`: one (x, y, z) torque in N m (body axes) per step
    since then."""

    def __init__(self, model: TankModel) -> None:
        self.model = model
        self.torques: List[Tuple[float, float, float]] = []
        self._held: Optional[RigidBodyState] = None

    @property
    def imu_field_residual(self) -> Optional[np.ndarray]:
        """The residual field at the IMU, as the model has it: on the bench the IMU reports as on the robot."""
        return self.model.imu_field_residual

    @property
    def joint_loads(self) -> Any:
        """The paws' loads on the joints at the last step (the loaded servos' input), as the model has them."""
        return self.model.joint_loads

    def attach(self, state: RigidBodyState) -> None:
        """Clamp the body at ``state`` (at rest: its velocities are set to zero) and clear :attr:`torques`."""
        self._held = RigidBodyState(position=np.array(state.position, dtype=float),
                                    rotation=np.array(state.rotation, dtype=float)).validate()
        self.model.attach(self._held)
        self.torques = []

    def leg_input(self, q: Any, q_dot: Any) -> Any:
        return self.model.leg_input(q, q_dot)

    def step_trusted(self, state: RigidBodyState, q: Any, q_dot: Any, dt: float) -> RigidBodyState:
        """One step of the legs against the clamped body: the model steps from the clamped state (so that
        its wake, floating block and joint loads advance) and its new body state is discarded; the clamp's
        torque is recorded. Returns the clamped state, whatever ``state`` is given."""
        held = self._held
        if held is None:
            raise RuntimeError("clamp not attached: call attach(state) first")
        self.model.step_trusted(held, q, q_dot, dt)
        x, y, z = self.model.held_wrench(held, q, q_dot)[3:6].tolist()
        self.torques.append((x, y, z))
        return held
