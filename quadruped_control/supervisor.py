"""Safety supervisor around the attitude controller: arming, input checks, safe pose, pulse widths.

The ROS controller node is thin glue around :class:`ControlSupervisor`; the supervisor is thin glue
around :class:`~quadruped_control.controller.AttitudeController`, the same object the offline simulator
steps. Everything that decides *whether* the legs may stroke lives here, without rospy, so it is tested
with pytest:

* Unarmed: the controller is not stepped and no servo command is produced; the PWM driver's command
  watchdog then keeps the outputs in their failsafe. Arming resets the integral and the stroke cycle,
  so an old integral never kicks the legs.
* Armed with a usable IMU sample: one controller step (eq. error .. foot_integration), joint targets
  mapped to pulse widths and clamped to the per-channel limits.
* Armed with an unusable IMU sample (NaN, non-unit quaternion, stale; see
  :func:`~quadruped_control.monitoring.imu_sample_problem`) or a controller error: the controller's
  hold (no stroking, integral frozen, feet at the nominal pose) and the reason in the output.

The torque estimated from measured joint motion (eq. torque_leg summed over the legs) is computed
from the latest joint feedback for telemetry.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np

from quadruped_control.controller import AttitudeController, ControllerOutput, estimate_body_torque
from quadruped_control.monitoring import imu_sample_problem
from quadruped_control.so3 import quat_to_rot

#: Maps 12 joint angles (rad, JOINT_NAMES order) to 12 pulse widths (us), clamped to the limits.
PulseMap = Callable[[np.ndarray], np.ndarray]


@dataclass
class ImuInput:
    """The latest IMU sample: world ENU <- body FLU quaternion (x, y, z, w), body rate, stamp (s)."""

    orientation_xyzw: np.ndarray
    angular_velocity: np.ndarray
    stamp: float


@dataclass
class SupervisorOutput:
    """Result of one supervised control tick.

    ``pulse_widths_us`` / ``joint_targets`` are ``None`` when nothing may be sent to the servos
    (unarmed); ``output`` is the controller's output (its state record is always published);
    ``problem`` is the reason for holding (empty when stroking normally); ``imu_stamp`` is the stamp
    of the IMU sample this tick used (for the end-to-end latency measurement).
    """

    output: ControllerOutput
    armed: bool
    problem: str
    pulse_widths_us: Optional[np.ndarray]
    joint_targets: Optional[np.ndarray]
    torque_estimated: np.ndarray
    imu_stamp: Optional[float]


class ControlSupervisor:
    """Decides per tick between stroking, holding and staying passive; see the module docstring."""

    def __init__(self, controller: AttitudeController, pulse_map: PulseMap, max_imu_age: float = 0.05,
                 armed: bool = False) -> None:
        if not (math.isfinite(max_imu_age) and max_imu_age > 0):
            raise ValueError("max_imu_age must be a positive number of seconds, got %r" % (max_imu_age,))
        self.controller = controller
        self.pulse_map = pulse_map
        self.max_imu_age = float(max_imu_age)
        self._armed = bool(armed)
        self._imu: Optional[ImuInput] = None
        self._joint_positions: Optional[np.ndarray] = None
        self._joint_velocities: Optional[np.ndarray] = None
        self.ticks = 0
        self.holds = 0
        self.controller_errors = 0

    @property
    def armed(self) -> bool:
        return self._armed

    def arm(self, armed: bool) -> str:
        """Arm or disarm; returns a message for the caller. Arming starts a fresh stroke cycle."""
        if armed and not self._armed:
            self.controller.reset()
            self._armed = True
            return "armed: legs will stroke"
        if not armed and self._armed:
            self._armed = False
            return "disarmed: no servo commands, PWM watchdog takes the outputs to failsafe"
        return "already %s" % ("armed" if armed else "disarmed")

    def set_imu(self, orientation_xyzw: Sequence[float], angular_velocity: Sequence[float],
                stamp: float) -> None:
        """Store the latest IMU sample (checked at the next tick, not here: a stale sample is a
        property of time, not of the message)."""
        self._imu = ImuInput(np.array(orientation_xyzw, dtype=float),
                             np.array(angular_velocity, dtype=float), float(stamp))

    def set_joint_feedback(self, positions: Sequence[float], velocities: Sequence[float]) -> None:
        """Store measured joint positions and velocities (12, JOINT_NAMES order; NaN where unknown)."""
        p = np.array(positions, dtype=float)
        v = np.array(velocities, dtype=float)
        if p.shape != (12,) or v.shape != (12,):
            raise ValueError("joint feedback needs 12 positions and 12 velocities")
        self._joint_positions, self._joint_velocities = p, v

    def imu_problem(self, now: float) -> Optional[str]:
        if self._imu is None:
            return "no IMU sample received yet"
        return imu_sample_problem(self._imu.orientation_xyzw, self._imu.angular_velocity,
                                  self._imu.stamp, now, self.max_imu_age)

    def tick(self, t: float, now: float) -> SupervisorOutput:
        """One control tick at controller time ``t``; ``now`` is the clock the IMU stamps use."""
        self.ticks += 1
        problem = self.imu_problem(now)
        imu = self._imu
        R = omega = None
        if not self._armed:
            output = self.controller.hold(t, "disarmed")
            problem = "disarmed"
        elif problem is not None:
            output = self.controller.hold(t, problem)
        else:
            assert imu is not None
            R = quat_to_rot(imu.orientation_xyzw / np.linalg.norm(imu.orientation_xyzw))
            omega = imu.angular_velocity
            try:
                output = self.controller.step(t, R, omega)
            except ValueError as exc:  # the controller refuses input it cannot use: hold, say why
                self.controller_errors += 1
                problem = "controller rejected input: %s" % exc
                output = self.controller.hold(t, problem)
        if problem:
            self.holds += 1
        pulses = targets = None
        if self._armed:
            targets = np.asarray(output.joint_targets, dtype=float).reshape(12)
            pulses = np.asarray(self.pulse_map(targets), dtype=float)
        return SupervisorOutput(output=output, armed=self._armed, problem=problem or "",
                                pulse_widths_us=pulses, joint_targets=targets,
                                torque_estimated=self._estimated_torque(R, omega),
                                imu_stamp=None if imu is None else imu.stamp)

    def _estimated_torque(self, R: Optional[np.ndarray], omega: Optional[np.ndarray]) -> np.ndarray:
        """eq. (torque_leg) from measured joint motion; NaN when an input is missing or invalid."""
        nan = np.full(3, np.nan)
        if R is None or omega is None or self._joint_positions is None or self._joint_velocities is None:
            return nan
        q = self._joint_positions.reshape(4, 3)
        q_dot = self._joint_velocities.reshape(4, 3)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(q_dot))):
            return nan
        try:
            return np.asarray(estimate_body_torque(q, q_dot, R, omega, self.controller.robot), dtype=float)
        except ValueError:
            return nan
