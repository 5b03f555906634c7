"""Safety supervisor around the attitude controller: arming, input checks, safe pose, pulse widths.

The ROS controller node is thin glue around :class:`ControlSupervisor`; the supervisor is thin glue
around :class:`~quadruped_control.control.controller.AttitudeController`, the same object the offline simulator
steps. Everything that decides *whether* the legs may stroke lives here, without rospy, so it is tested
with pytest:

* Unarmed: the controller is not stepped and no servo command is produced; the PWM driver's command
  watchdog then keeps the outputs in their failsafe. Arming resets the integral and the stroke cycle,
  so an old integral never kicks the legs.
* Arming is checked (:meth:`ControlSupervisor.arming_checks`): with a :class:`SafetyConfig`, IMU and every
  joint fresh and plausible, pwm_node's outputs enabled with the chip answering, besides the e-stop, the tether
  heartbeat and the pre-dive check. An arm asked for while a check fails is refused with every reason, or,
  asked for at start-up (``armed=True``), waits for the checks to pass.
* Soft start (with a :class:`SafetyConfig`): once armed, the legs travel from their measured angles to the
  nominal pose at no more than ``max_joint_speed`` (:class:`~quadruped_control.control.soft_start.JointSpeedLimiter`)
  before the first stroke, and the integral starts then; a hold's retrace to the nominal pose keeps the same bound.
* Servo tracking (with a :class:`SafetyConfig`): armed, each joint's feedback is judged against the servo's model
  run on the commands (:class:`~quadruped_control.control.servo_watch.ServoTrackingWatch`); a joint in ERROR
  makes the controller hold when ``tracking.hold_on_error`` says so.
* Armed with a usable IMU sample: one controller step (eq. error .. foot_integration), joint targets
  mapped to pulse widths and clamped to the per-channel limits.
* Setpoints (:meth:`ControlSupervisor.set_setpoint`) are read in a yaw reference
  (:mod:`~quadruped_control.control.yaw_reference`: relative, absolute, tilt; by default the controller
  configuration's ``yaw_reference``); every arm captures the heading a relative setpoint is turned by from the
  latest IMU sample (from the first stepped one when there is none), and the controller gets the world R_d.
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

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Set, Tuple

import numpy as np

from quadruped_common.imu_plausibility import ImplausibleSample, RateChangeCheck, SensorLimits, check_sample
from quadruped_common.monitoring import time_problem
from quadruped_common.robot import JOINT_NAMES, LEGS
from quadruped_common.so3 import quat_to_rot
from quadruped_control.control.controller import AttitudeController, ControllerOutput, estimate_body_torque
from quadruped_control.control.safety_config import SafetyConfig
from quadruped_control.control.servo_watch import ERROR, ServoTrackingWatch
from quadruped_control.control.soft_start import JointSpeedLimiter
from quadruped_control.control.yaw_reference import WorldSetpoint, YawReference, heading, world_setpoint
from quadruped_control.model.kinematics import joint_angles

#: s: a gap this long between two tether checks means the supervisor did not run (starved, stopped); the
#: heartbeats queued meanwhile get as long again to arrive before their absence counts as a lost tether.
TETHER_STALL = 0.25
#: What the tether failsafe does when the heartbeat is lost: stop stroking (the servos hold where they are), that
#: and every output off (limp), or stay armed holding the attitude the robot had (hold).
TETHER_ACTIONS = ("disarm", "limp", "hold")

#: health/<source> reason codes that say the measurement failed, not that the hazard it watches is there.
MEASUREMENT_FAULTS = frozenset(("stale", "no_reading", "no_answer", "absent", "implausible", "prom_crc", "dropped",
                                "not_fitted"))

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
    loss for this long disarms (:meth:`check_tether`, ``tether_action``: disarm, or limp as well);
    ``safety``: the checked arming and the soft start (None: neither, a bare supervisor for tests and fuzzing);
    ``health_sources``: the fitted hazard watchers (``health/<name>``, :meth:`set_health`): each fresh and not in
    error to arm, and armed, :meth:`check_health` takes its action (``safety.health_action``) on an error.
    """

    def __init__(self, controller: AttitudeController, pulse_map: PulseMap, max_imu_age: float = 0.05,
                 armed: bool = False, imu_limits: Optional[SensorLimits] = None, max_implausible_run: int = 3,
                 joint_margin: float = math.radians(15.0), max_joint_age: float = 0.1,
                 require_preflight: bool = False, heartbeat_timeout: Optional[float] = None,
                 tether_action: str = "disarm", safety: Optional[SafetyConfig] = None,
                 health_sources: Sequence[str] = ()) -> None:
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
        self._tether_holding = False  # a hold taken for the current loss of the heartbeat
        self._tether_checked: Optional[float] = None  # the clock of the last check_tether
        self._tether_grace_until = -math.inf
        self.clock_now = 0.0  # the node's clock at the last tick (the arming gate's heartbeat age)
        self.safety = safety
        self._limiter = JointSpeedLimiter(safety.max_joint_speed) if safety is not None else None
        self.tracking: Optional[ServoTrackingWatch] = None
        if safety is not None:
            speed = controller.robot.servo_no_load_speed * safety.tracking_speed_scale
            self.tracking = ServoTrackingWatch(dataclasses.replace(safety.tracking, max_speed=speed), JOINT_NAMES)
        self.tracking_levels: List[Tuple[str, int, float]] = []
        self._soft_start_due = False  # armed, the first tick starts the soft start
        self.soft_starting = False
        self.last_arm_failure = ""
        self._was_holding = False
        robot = controller.robot  # the nominal pose: where every stroke cycle starts and every hold ends
        self._nominal = np.array([joint_angles(robot.nominal_foot_body(leg), leg, robot) for leg in LEGS]).reshape(12)
        if health_sources and safety is None:
            raise ValueError("health_sources need a SafetyConfig (their actions and max age)")
        self.health_sources = tuple(health_sources)
        self._health: Dict[str, Tuple[bool, str, float, bool]] = {}  # source -> (in error, message, stamp, hazard)
        #: (source, hazard) episodes check_health has reported whose source is not well again
        self._health_episodes: Set[Tuple[str, bool]] = set()
        self.health_actions_taken = 0
        self._outputs_problem: Optional[str] = None  # pwm_node's outputs_state (None: never received)
        self._outputs_stamp = -math.inf
        self._imu: Optional[ImuInput] = None
        #: the operator's setpoint, its yaw reference and the heading at arming
        self.yaw = YawReference(controller.config.yaw_reference, controller.setpoint)
        self.yaw.mode = "tilt" if controller.yaw_free else "absolute"
        self._heading_due = False  # armed without an IMU sample: the first stepped one gives the heading
        self._joint_positions: Optional[np.ndarray] = None
        self._joint_velocities: Optional[np.ndarray] = None
        self._joint_stamp: Optional[float] = None
        self._armed = False
        #: an arm asked for at start-up waits for the checks (with ``safety``), and for the clock to reach
        #: ``arm_not_before`` (a fixed moment: lock-step runs then arm on the same tick); any disarm cancels it
        self.arm_pending = bool(armed) and safety is not None
        self.arm_not_before = -math.inf
        if armed and safety is None and self.arming_refusal() is None:
            self._arm()
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
        """The tether failsafe: armed, watching, and no heartbeat for ``heartbeat_timeout`` -> the configured action,
        returned once per loss: ``disarm`` or ``limp`` disarm (for limp the caller switches the outputs off), and
        when the heartbeat returns nothing moves until the next arm; ``hold`` keeps the robot armed with the
        attitude it has as its setpoint, until the operator sends another (``disarm`` when no IMU sample is
        usable to hold). After the supervisor itself stalled (no check for :data:`TETHER_STALL`: a starved
        process), the heartbeats waiting in its socket get :data:`TETHER_STALL` to arrive before a loss counts."""
        if self._tether_checked is not None and now - self._tether_checked > TETHER_STALL:
            self._tether_grace_until = now + TETHER_STALL
        self._tether_checked = now
        lost = self.watch_heartbeat and self.heartbeat_lost(now) and now >= self._tether_grace_until
        if not lost:
            self._tether_holding = False
        if not (self._armed and lost) or self._tether_holding:
            return None
        self.tether_losses += 1
        if self.tether_action == "hold" and self._imu is not None and self.imu_problem(now) is None:
            self.set_setpoint(self._imu_rotation(self._imu), "absolute")
            self._tether_holding = True
            return "hold"
        self._armed = False
        self.arm_pending = False
        return "limp" if self.tether_action == "limp" else "disarm"

    def set_estop(self, latched: bool) -> None:
        """The e-stop's state (pwm_node's ``estop_state``): latched disarms at once and refuses arming."""
        self.estop_latched = bool(latched)
        if latched:
            self._armed = False
            self.arm_pending = False

    def set_outputs_state(self, problem: str, now: float) -> None:
        """pwm_node's outputs_state at ``now``: empty when the outputs are enabled and the chip answers."""
        self._outputs_problem = str(problem)
        self._outputs_stamp = float(now)

    def set_health(self, source: str, error: bool, message: str, now: float, reason: str = "") -> None:
        """``health/<source>``'s status at ``now``: ``error`` (level ERROR), its message and its ``reason`` code(s)
        (comma-separated, each maybe ``<part>:<code>``). An error whose every code is a measurement fault
        (:data:`MEASUREMENT_FAULTS`: the sensor lost, stale, implausible) is not a hazard."""
        codes = [part.rsplit(":", 1)[-1] for part in str(reason).split(",") if part]
        hazard = bool(error) and not (codes and all(code in MEASUREMENT_FAULTS for code in codes))
        self._health[source] = (bool(error), str(message), float(now), hazard)

    def health_problem(self, source: str, now: float) -> Optional[str]:
        """Why ``source`` stops arming: no status yet, its status old, or in error (its message)."""
        status = self._health.get(source)
        if status is None:
            return "no health/%s status yet (is its node running?)" % source
        error, message, stamp, _ = status
        assert self.safety is not None
        age = now - stamp
        if not age <= self.safety.health_max_age:
            return "health/%s is %.1f s old (is its node running?)" % (source, age)
        return (message or "error") if error else None

    def check_health(self, now: float) -> List[Tuple[str, str, str]]:
        """Armed, each health source newly in trouble: (source, action, why), once until it is well again. A
        hazard (a critical pack, water inside) takes the source's action: ``disarm`` or ``limp`` disarm here (the
        caller switches the outputs off for limp); a lost or faulty measurement, or action ``warn``, is reported
        (``warn``) and the robot goes on: stopping it would not make the sensor come back. Arming stays refused
        (:meth:`arming_checks`) either way."""
        taken = []
        for source in self.health_sources:
            problem = self.health_problem(source, now)
            if problem is None:
                self._health_episodes.discard((source, True))
                self._health_episodes.discard((source, False))
                continue
            status = self._health.get(source)
            hazard = status is not None and now - status[2] <= self._health_max_age() and status[3]
            key = (source, hazard)
            if key in self._health_episodes or not self._armed:
                continue
            self._health_episodes.discard((source, not hazard))
            self._health_episodes.add(key)
            assert self.safety is not None
            action = self.safety.health_action(source) if hazard else "warn"
            taken.append((source, action, problem))
            if action != "warn":
                self._armed = False
                self.arm_pending = False
                self.health_actions_taken += 1
        return taken

    def _health_max_age(self) -> float:
        assert self.safety is not None
        return self.safety.health_max_age

    def arming_checks(self) -> List[Tuple[str, str]]:
        """Each arming precondition as (name, problem; empty when it holds), at the last tick's clock."""
        now = self.clock_now
        checks = [("e-stop", "the e-stop is latched: reset it (rosservice call /estop false) and enable the outputs"
                   if self.estop_latched else "")]
        if self.safety is not None:
            checks.append(("imu", self.imu_problem(now) or ""))
            checks.append(("joints", self.joint_problem(now) or ""))
            if self.safety.require_outputs:
                checks.append(("outputs", self.outputs_problem(now) or ""))
            checks += [(source, self.health_problem(source, now) or "") for source in self.health_sources]
        if self.watch_heartbeat:
            checks.append(("tether", "no tether heartbeat for %.1f s (tether/heartbeat: the monitor launch, or rosrun "
                           "underwater_quadruped heartbeat_node on the laptop)" % self.heartbeat_timeout
                           if self.heartbeat_lost(now) else ""))
        if self.require_preflight:
            checks.append(("pre-dive check", "" if self.preflight_passed else
                           "no pre-dive check has passed since the stack started (%s): run the check "
                           "(docs/on_the_robot.md), or start with require_preflight false"
                           % (self.preflight_summary or "none has run")))
        return checks

    def arming_refusal(self) -> Optional[str]:
        """Why arming is refused now (every reason, joined), or None."""
        return "; ".join("%s: %s" % (name, problem) for name, problem in self.arming_checks() if problem) or None

    def joint_problem(self, now: float) -> Optional[str]:
        """Why the joint feedback cannot start the legs: missing, stale, or a joint unusable (by name)."""
        if self._joint_positions is None:
            return "no joint feedback received yet"
        if self._joint_stamp is not None:
            stale = time_problem(self._joint_stamp, now, self.max_joint_age, "joint feedback")
            if stale:
                return stale
        bad = [JOINT_NAMES[i] for i in np.flatnonzero(~np.isfinite(self._joint_positions))]
        if bad:
            return "no usable reading (missing or outside the servo range) from %s" % ", ".join(bad)
        return None

    def outputs_problem(self, now: float) -> Optional[str]:
        """Why pwm_node's outputs cannot take commands: its state missing, old, or not ready."""
        if self._outputs_problem is None:
            return "no outputs_state from pwm_node yet (is it running?)"
        assert self.safety is not None
        age = now - self._outputs_stamp
        if not age <= self.safety.max_outputs_state_age:
            return "pwm_node's outputs_state is %.1f s old (is it running?)" % age
        return self._outputs_problem or None

    def set_setpoint(self, R: Sequence[Sequence[float]], mode: Optional[str] = None) -> WorldSetpoint:
        """The operator's setpoint R (3x3) in yaw reference ``mode`` (None: ``yaw.default``); returns what the
        controller now tracks. ValueError, nothing changed, for an unknown mode or a non-rotation."""
        mode = self.yaw.resolve(mode)
        R_s = np.array(R, dtype=float)
        target = world_setpoint(R_s, mode, self.yaw.psi_0)
        self.controller.set_setpoint(target.R_d, target.yaw_free)
        self.yaw.R_s, self.yaw.mode = R_s, mode
        return target

    @staticmethod
    def _imu_rotation(imu: ImuInput) -> np.ndarray:
        q = imu.orientation_xyzw
        return quat_to_rot(q / np.linalg.norm(q))

    def attitude(self) -> Optional[np.ndarray]:
        """The attitude of the latest plausible IMU sample (3x3, world ENU <- body FLU), fresh or not; None before
        the first."""
        return None if self._imu is None else self._imu_rotation(self._imu)

    def _take_heading(self, R: np.ndarray) -> None:
        """psi_0 := the heading of R; the controller's R_d follows."""
        self.yaw.psi_0 = heading(R)
        self._heading_due = False
        target = self.yaw.world()
        self.controller.set_setpoint(target.R_d, target.yaw_free)

    def _arm(self) -> None:
        self.controller.reset()
        self._heading_due = True
        if self._imu is not None:
            self._take_heading(self._imu_rotation(self._imu))
        self._armed = True
        self.arm_pending = False
        self._soft_start_due = self._limiter is not None
        self.soft_starting = False
        self._was_holding = False

    def arm(self, armed: bool) -> str:
        """Arm or disarm; returns a message for the caller. Arming starts the soft start, then a fresh stroke
        cycle; it is refused (the message says why, :meth:`arming_refusal`) while a check fails."""
        if not armed:
            self.arm_pending = False
        refusal = self.arming_refusal() if armed and not self._armed else None
        if refusal:
            return "arming refused: " + refusal
        if armed and not self._armed:
            self._arm()
            return "armed: legs to the nominal pose, then strokes" if self._limiter else "armed: legs will stroke"
        if not armed and self._armed:
            self._armed = False
            if self.safety is not None and self.safety.disarm_action == "limp":
                return "disarmed: no servo commands, every output off (limp)"
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
        if self.tracking is not None and stamp is not None:
            self.tracking.feedback(float(stamp), p)

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
        if self.arm_pending and now >= self.arm_not_before and self.arming_refusal() is None:
            self._arm()
        problem = self.imu_problem(now)
        imu = self._imu
        R = omega = None
        if self._armed and self._soft_start_due:
            problem = self._start_soft_start(t) or problem
        if self.tracking is not None:
            if not self._armed and self.tracking.active:
                self.tracking.stop()
            self.tracking_levels = self.tracking.levels(now)
            failing = [(name, rms) for name, level, rms in self.tracking_levels if level == ERROR]
            if failing and self.safety is not None and self.safety.tracking_hold and problem is None:
                problem = "servo tracking: %s off the servo model by RMS %s" % (
                    ", ".join(name for name, _ in failing), ", ".join("%.0f deg" % math.degrees(r) for _, r in failing))
        if not self._armed:
            output = self.controller.hold(t, "disarmed")
            problem = "disarmed"
        elif self.soft_starting:
            output = self.controller.hold(t, "soft start")
            problem = "soft start: legs to the nominal pose at <= %.2f rad/s" % self._limiter.max_speed
        elif problem is not None:
            output = self.controller.hold(t, problem)
        else:
            assert imu is not None
            R = self._imu_rotation(imu)
            omega = imu.angular_velocity
            if self._heading_due:
                self._take_heading(R)
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
            if self._limiter is not None:
                targets = self._limit(t, targets, holding=bool(problem))
            if self.tracking is not None:
                self.tracking.command(t, targets)
            pulses = np.asarray(self.pulse_map(targets), dtype=float)
        return SupervisorOutput(output=output, armed=self._armed, problem=problem or "",
                                pulse_widths_us=pulses, joint_targets=targets,
                                torque_estimated=self._estimated_torque(R, omega, now),
                                imu_stamp=None if imu is None else imu.stamp)

    def _start_soft_start(self, t: float) -> Optional[str]:
        """The first armed tick: the limiter starts at the measured angles, unless every joint is already within
        the tolerance of the nominal pose. Returns why it cannot start (the arm is then withdrawn), or None."""
        assert self._limiter is not None and self.safety is not None
        self._soft_start_due = False
        start = self._joint_positions
        if start is None or not np.all(np.isfinite(start)):
            self._armed = False
            self.last_arm_failure = "the joint feedback the soft start starts from was lost"
            return self.last_arm_failure
        if self.tracking is not None:
            self.tracking.start(t, start)
        if np.max(np.abs(start - self._nominal)) <= self.safety.soft_start_tolerance:
            self._limiter.engaged = False  # close enough: the strokes start at once
            return None
        self._limiter.engage(t, start)
        self.soft_starting = True
        return None

    def _limit(self, t: float, targets: np.ndarray, holding: bool) -> np.ndarray:
        """Apply the joint speed bound: engaged through the soft start and from the start of each hold until the
        targets are caught up. The soft start's end resets the controller: the integral starts then."""
        assert self._limiter is not None
        if holding and not self._was_holding and not self.soft_starting:
            self._limiter.engage(t)  # a hold begins: its retrace from the last targets keeps the bound
        self._was_holding = holding and not self.soft_starting
        limited = self._limiter.step(t, targets)
        if self.soft_starting and not self._limiter.engaged:
            self.soft_starting = False
            self.controller.reset()
        return limited

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
