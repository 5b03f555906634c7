"""Safety supervisor around the attitude controller: arming, input checks, safe pose, pulse widths.

The ROS controller node is thin glue around :class:`ControlSupervisor`; the supervisor is thin glue
around :class:`~quadruped_control.control.controller.AttitudeController`, the same object the offline simulator
steps. Everything that decides *whether* the legs may stroke lives here, without rospy, so it is tested
with pytest:

* Unarmed: the controller is not stepped and no servo command is produced; the PWM driver's command
  watchdog then keeps the outputs in their failsafe. Arming resets the integral and the stroke cycle,
  so an old integral never kicks the legs.
* Armed with a usable IMU sample: one controller step (eq. error .. foot_integration), joint targets
  mapped to pulse widths and clamped to the per-channel limits.
* Armed with an unusable IMU sample (NaN, non-unit quaternion, stale; see
  :func:`~quadruped_common.monitoring.imu_sample_problem`) or a controller error: the controller's
  hold (no stroking, integral frozen, feet at the nominal pose) and the reason in the output.

Input plausibility. Every IMU sample is checked when it arrives (:meth:`ControlSupervisor.set_imu`)
against what a working sensor can report (:mod:`quadruped_common.imu_plausibility`, the check the
VN-100 driver applies too: finite, unit quaternion, rate and acceleration within the sensor's range): an implausible sample is dropped
(never stored, so it never reaches the controller), counted per reason and reported; the previous
sample stays in use while it is fresh, and ``max_implausible_run`` implausible samples in a row make
the controller hold until a plausible one arrives. Time is checked at every tick
(:func:`~quadruped_common.monitoring.time_problem`): a non-finite stamp or clock is never fresh.
Joint feedback outside the servo ranges (``config/robot.yaml`` joint limits widened by
``joint_margin``) or older than ``max_joint_age`` is unusable (NaN) and counted.

The torque estimated from measured joint motion (eq. torque_leg summed over the legs) is computed
from the latest usable joint feedback for telemetry.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, Optional, Sequence

import numpy as np

from quadruped_common.imu_plausibility import ImplausibleSample, RateChangeCheck, SensorLimits, check_sample
from quadruped_common.monitoring import time_problem
from quadruped_common.so3 import quat_to_rot
from quadruped_control.control.controller import AttitudeController, ControllerOutput, estimate_body_torque

#: What the tether failsafe does when the heartbeat is lost: stop stroking (the servos hold where they are), or
#: that and every output off (limp).
TETHER_ACTIONS = ("disarm", "limp")

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
    """Decides per tick between stroking, holding and staying passive; see the module docstring.

    ``imu_limits``: the sensor's plausible ranges; ``max_implausible_run``: this many implausible IMU
    samples in a row hold the controller; ``joint_margin`` (rad): how far beyond the servo range a joint
    reading is still plausible; ``max_joint_age`` (s): older joint feedback is not used;
    ``require_preflight``: arming is refused until :meth:`set_preflight` reports a passed pre-dive check;
    ``heartbeat_timeout`` (None: not watched): arming needs a tether heartbeat no older than this, and armed, its
    loss for this long disarms (:meth:`check_tether`, ``tether_action``: disarm, or limp as well).
    """

    def __init__(self, controller: AttitudeController, pulse_map: PulseMap, max_imu_age: float = 0.05,
                 armed: bool = False, imu_limits: Optional[SensorLimits] = None, max_implausible_run: int = 3,
                 joint_margin: float = math.radians(15.0), max_joint_age: float = 0.1,
                 require_preflight: bool = False, heartbeat_timeout: Optional[float] = None,
                 tether_action: str = "disarm") -> None:
        if not (math.isfinite(max_imu_age) and max_imu_age > 0):
            raise ValueError("max_imu_age must be a positive number of seconds, got %r" % (max_imu_age,))
        if not (isinstance(max_implausible_run, int) and max_implausible_run >= 1):
            raise ValueError("max_implausible_run must be a positive integer, got %r" % (max_implausible_run,))
        if not (math.isfinite(joint_margin) and joint_margin >= 0 and math.isfinite(max_joint_age) and max_joint_age > 0):
            raise ValueError("joint_margin must be >= 0 and max_joint_age > 0, got %r, %r" % (joint_margin, max_joint_age))
        self.controller = controller
        self.pulse_map = pulse_map
        self.max_imu_age = float(max_imu_age)
        self.imu_limits = imu_limits or SensorLimits()
        self._rate_check = RateChangeCheck(self.imu_limits)
        self.max_implausible_run = max_implausible_run
        self.max_joint_age = float(max_joint_age)
        limits = controller.robot.joint_limits.as_array()  # rows theta1..3, columns low, high
        self._joint_low = np.tile(limits[:, 0] - joint_margin, 4)
        self._joint_high = np.tile(limits[:, 1] + joint_margin, 4)
        self.require_preflight = bool(require_preflight)
        self.preflight_passed = False
        self.preflight_summary = ""
        self.estop_latched = False
        if heartbeat_timeout is not None and not (math.isfinite(heartbeat_timeout) and heartbeat_timeout > 0):
            raise ValueError("heartbeat_timeout must be a positive number of seconds, got %r" % (heartbeat_timeout,))
        if tether_action not in TETHER_ACTIONS:
            raise ValueError("tether_action must be one of %s, got %r" % (", ".join(TETHER_ACTIONS), tether_action))
        self.watch_heartbeat = heartbeat_timeout is not None
        self.heartbeat_timeout = float(heartbeat_timeout or 0.0)
        self.tether_action = tether_action
        self.last_heartbeat: Optional[float] = None
        self.tether_losses = 0
        self.clock_now = 0.0  # the node's clock at the last tick (the arming gate's heartbeat age)
        self._armed = bool(armed) and self.arming_refusal() is None
        self._imu: Optional[ImuInput] = None
        self._joint_positions: Optional[np.ndarray] = None
        self._joint_velocities: Optional[np.ndarray] = None
        self._joint_stamp: Optional[float] = None
        self.ticks = 0
        self.holds = 0
        self.controller_errors = 0
        self.imu_received = 0
        self.imu_dropped = 0
        self.imu_drop_reasons: Dict[str, int] = {}
        self.last_imu_drop = ""
        self.implausible_run = 0
        self.joint_readings_implausible = 0

    @property
    def armed(self) -> bool:
        return self._armed

    def set_preflight(self, passed: bool, summary: str) -> None:
        """The latest pre-dive check's verdict (the arming gate of :attr:`require_preflight`)."""
        self.preflight_passed = bool(passed)
        self.preflight_summary = str(summary)

    def set_heartbeat(self, now: float) -> None:
        """A tether heartbeat arrived at ``now`` (the node's clock)."""
        self.last_heartbeat = float(now)

    def heartbeat_lost(self, now: float) -> bool:
        """Is the heartbeat missing (never seen, or none for :attr:`heartbeat_timeout`)?"""
        return self.last_heartbeat is None or now - self.last_heartbeat > self.heartbeat_timeout

    def check_tether(self, now: float) -> Optional[str]:
        """The tether failsafe: armed, watching, and no heartbeat for ``heartbeat_timeout`` -> disarm and return
        the configured action (``disarm`` or ``limp``: the caller switches the outputs off) once; else None.
        When the heartbeat returns nothing moves until the next arm."""
        if not (self._armed and self.watch_heartbeat and self.heartbeat_lost(now)):
            return None
        self._armed = False
        self.tether_losses += 1
        return self.tether_action

    def set_estop(self, latched: bool) -> None:
        """The e-stop's state (pwm_node's ``estop_state``): latched disarms at once and refuses arming."""
        self.estop_latched = bool(latched)
        if latched:
            self._armed = False

    def arming_refusal(self) -> Optional[str]:
        """Why arming is refused now (every reason, joined), or None."""
        reasons = []
        if self.estop_latched:
            reasons.append("the e-stop is latched: reset it (rosservice call /estop false) and enable the outputs")
        if self.watch_heartbeat and self.heartbeat_lost(self.clock_now):
            reasons.append("no tether heartbeat for %.1f s (tether/heartbeat: the monitor launch, or rosrun "
                           "underwater_quadruped heartbeat_node on the laptop)" % self.heartbeat_timeout)
        if self.require_preflight and not self.preflight_passed:
            reasons.append("no pre-dive check has passed since the stack started (%s): run the check "
                           "(docs/on_the_robot.md), or start with require_preflight false"
                           % (self.preflight_summary or "none has run"))
        return "; ".join(reasons) or None

    def arm(self, armed: bool) -> str:
        """Arm or disarm; returns a message for the caller. Arming starts a fresh stroke cycle; it is refused
        (the message says why, :meth:`arming_refusal`) while a gate is closed."""
        refusal = self.arming_refusal() if armed and not self._armed else None
        if refusal:
            return "arming refused: " + refusal
        if armed and not self._armed:
            self.controller.reset()
            self._armed = True
            return "armed: legs will stroke"
        if not armed and self._armed:
            self._armed = False
            return "disarmed: no servo commands, PWM watchdog takes the outputs to failsafe"
        return "already %s" % ("armed" if armed else "disarmed")

    def set_imu(self, orientation_xyzw: Sequence[float], angular_velocity: Sequence[float],
                stamp: float, linear_acceleration: Optional[Sequence[float]] = None) -> Optional[str]:
        """Check an IMU sample's values and store it, or drop and count it; returns the reason for a drop.

        The checks: the sensor's ranges (:func:`~quadruped_common.imu_plausibility.check_sample`) and the
        physical rate, how fast the body's rate can change between stamps
        (:class:`~quadruped_common.imu_plausibility.RateChangeCheck`).

        Freshness is checked at each tick instead (a stale sample is a property of time, not of the
        message).
        """
        self.imu_received += 1
        try:
            stamp_value = float(stamp)
        except (TypeError, ValueError, OverflowError):
            stamp_value = math.nan  # never fresh (tick's time check); the rate change is not judged
        try:
            _, rate, _ = check_sample(orientation_xyzw, angular_velocity, linear_acceleration, self.imu_limits)
            self._rate_check.check(stamp_value, rate)
        except (ImplausibleSample, ValueError, TypeError, OverflowError) as exc:
            reason = exc.reason if isinstance(exc, ImplausibleSample) else "malformed"
            problem = "implausible IMU sample (%s): %s" % (reason, exc)
            self.imu_dropped += 1
            self.implausible_run += 1
            self.imu_drop_reasons[reason] = self.imu_drop_reasons.get(reason, 0) + 1
            self.last_imu_drop = problem
            return problem
        self.implausible_run = 0
        self._imu = ImuInput(np.array(orientation_xyzw, dtype=float),
                             np.array(angular_velocity, dtype=float), stamp_value)
        return None

    def set_joint_feedback(self, positions: Sequence[float], velocities: Sequence[float],
                           stamp: Optional[float] = None) -> None:
        """Store measured joint positions and velocities (12, JOINT_NAMES order; NaN where unknown).

        A position outside its servo range (plus ``joint_margin``) cannot be a real reading: that joint
        is marked unusable (NaN) and counted. ``stamp``: time of the reading (the clock of ``tick``'s
        ``now``); without it the feedback is taken as fresh.
        """
        p = np.array(positions, dtype=float)
        v = np.array(velocities, dtype=float)
        if p.shape != (12,) or v.shape != (12,):
            raise ValueError("joint feedback needs 12 positions and 12 velocities")
        implausible = np.isfinite(p) & ((p < self._joint_low) | (p > self._joint_high))
        if np.any(implausible):
            self.joint_readings_implausible += int(np.count_nonzero(implausible))
            p[implausible] = np.nan
            v[implausible] = np.nan
        self._joint_positions, self._joint_velocities = p, v
        self._joint_stamp = None if stamp is None else float(stamp)

    def imu_problem(self, now: float) -> Optional[str]:
        if self.implausible_run >= self.max_implausible_run:
            return "%d implausible IMU samples in a row (last: %s)" % (self.implausible_run, self.last_imu_drop)
        if self._imu is None:
            return "no IMU sample received yet"
        return time_problem(self._imu.stamp, now, self.max_imu_age)

    def tick(self, t: float, now: float) -> SupervisorOutput:
        """One control tick at controller time ``t``; ``now`` is the clock the IMU stamps use."""
        self.ticks += 1
        self.clock_now = now
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
                                torque_estimated=self._estimated_torque(R, omega, now),
                                imu_stamp=None if imu is None else imu.stamp)

    def _estimated_torque(self, R: Optional[np.ndarray], omega: Optional[np.ndarray], now: float) -> np.ndarray:
        """eq. (torque_leg) from measured joint motion; NaN when an input is missing, stale or invalid."""
        nan = np.full(3, np.nan)
        if R is None or omega is None or self._joint_positions is None or self._joint_velocities is None:
            return nan
        if self._joint_stamp is not None and time_problem(self._joint_stamp, now, self.max_joint_age, "joint feedback"):
            return nan
        q = self._joint_positions.reshape(4, 3)
        q_dot = self._joint_velocities.reshape(4, 3)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(q_dot))):
            return nan
        try:
            return np.asarray(estimate_body_torque(q, q_dot, R, omega, self.controller.robot), dtype=float)
        except ValueError:
            return nan
