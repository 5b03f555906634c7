"""Servo calibration against the reference poses, the channel and speed checks: what finds a servo built wrong.

:meth:`ServoCheck.calibrate` (``python -m quadruped_control.bringup.calibrate``):

1. outputs off, the operator puts the limp legs in the ``open`` then the ``stance`` pose
   (:mod:`~quadruped_control.bringup.reference`); each joint's feedback map (volts -> angle) is the line
   through its two readings: fitted against the robot's geometry, not against a command;
2. outputs on, the legs held at ``stance``; each joint in turn swept symmetrically about it (inside its limits
   and the five-bar's safe set) while every joint's angle is read through those maps;
3. from the sweeps: each servo's zero (the pulse that puts it at its neutral angle), direction and gain.

:meth:`ServoCheck.check_channels` is step 2 with the maps of the calibration file (the pre-dive check).
:meth:`ServoCheck.check_speeds` (the pre-dive check's next step) commands each joint across a wide step at once
and times its 20-80 % rise: the servo model (:mod:`quadruped_control.model.servo`) inverted gives the speed it
turned at, as a fraction of the rated no-load speed (robot.yaml; the stand is in air, so no-load applies).

A joint whose feedback does not follow the geometry (stuck, or another servo's), whose sweep moves another
joint, which moves against its command (mounted reversed), whose zero is more than ``zero_tolerance_deg``
off (horn off a spline), or which follows only part of its command (blocked, overloaded) is a :class:`Finding`
naming the joint and the fix; with any finding the calibration writes nothing. The speed check's finding is a servo
slower than ``min_speed_fraction`` of its rating (worn, wet, a weak supply).
"""
from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field, replace
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_common.robot import JOINT_NAMES
from quadruped_control.bringup.reference import ReferencePose, sweep_half_width
from quadruped_control.control.safety_config import SAFETY_SCHEMA
from quadruped_control.model.params import RobotParams
from quadruped_control.model.servo import rate_limited_lag_step
from quadruped_drivers.calibration import ServoCalibration
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_rig import PoseDriver

__all__ = ["Bench", "DriverBench", "Finding", "ServoCheck", "ServoCheckResult", "ServoCheckSettings", "model_rise_time",
           "rise_time", "speed_fraction"]


@dataclass(frozen=True)
class ServoCheckSettings:
    """Tolerances and sweep of the check (degrees unless named otherwise)."""

    sweep_deg: float = 20.0           # largest sweep each side of the stance
    points: int = 5                   # sweep points per joint
    settle_s: float = 0.4             # wait at each point before reading
    samples: int = 5                  # feedback reads averaged per reading
    min_span_v: float = 0.05          # feedback must change this much between the reference poses
    slope_tolerance: float = 0.25     # |feedback slope| within this fraction of the servo's
    zero_tolerance_deg: float = 3.0   # a zero further off is a horn off its spline
    gain_tolerance: float = 0.2       # the joint follows 1 +- this of its command
    cross_motion_deg: float = 3.0     # another joint moving more than this during a sweep is wired wrong
    speed_step_deg: float = 60.0      # the speed check's step across the stance, commanded at once
    speed_steps: int = 3              # steps per joint, alternately each way: the median rise is judged
    speed_record_s: float = 0.5       # feedback recorded after each step (one at 0.2 of its speed finishes in it)
    min_speed_fraction: float = 0.7   # a servo slower than this fraction of its rated speed is a finding
    time_constant: float = SAFETY_SCHEMA["tracking.time_constant"].default  # s, the servo model's lag

    def __post_init__(self) -> None:
        if not 0.0 < self.min_speed_fraction <= 1.0:
            raise ParameterError("min_speed_fraction must be in (0, 1], got %r" % (self.min_speed_fraction,))
        if not (self.speed_steps >= 1 and self.speed_record_s > 0.0 and 0.0 < self.speed_step_deg <= 120.0):
            raise ParameterError("the speed check needs speed_steps >= 1, speed_record_s > 0 and speed_step_deg in "
                                 "(0, 120], got %r, %r, %r" % (self.speed_steps, self.speed_record_s,
                                                                self.speed_step_deg))
        if not (math.isfinite(self.time_constant) and self.time_constant >= 0.0):
            raise ParameterError("time_constant must be >= 0 s, got %r" % (self.time_constant,))


@dataclass(frozen=True)
class Finding:
    """One problem: the ``joints`` it concerns, its ``kind`` (feedback, wiring, reversed, zero, tracking, slow),
    what was seen and the fix."""

    joints: Tuple[str, ...]
    kind: str
    seen: str
    fix: str

    def __str__(self) -> str:
        return "%s: %s. Fix: %s" % (", ".join(self.joints), self.seen, self.fix)


@dataclass
class JointSweep:
    """One joint's sweep: the commanded offsets (rad, in the stack's angles) and every joint's angle read."""

    offsets: np.ndarray
    angles: np.ndarray  # points x 12, through the feedback maps; NaN where a map is unusable

    def gain_and_zero(self, index: int) -> Tuple[float, float, float]:
        """Line angle = zero + gain * offset through joint ``index``'s readings: (gain, zero, rms) (rad)."""
        y = self.angles[:, index]
        if not np.all(np.isfinite(y)):
            return math.nan, math.nan, math.nan
        gain, zero = np.polyfit(self.offsets, y, 1)
        rms = float(np.sqrt(np.mean((y - (zero + gain * self.offsets)) ** 2)))
        return float(gain), float(zero), rms


@dataclass
class ServoCheckResult:
    """Findings, each joint's sweep, and the new calibration (None when anything was found)."""

    findings: List[Finding] = field(default_factory=list)
    sweeps: Dict[str, JointSweep] = field(default_factory=dict)
    calibration: Optional[ServoCalibration] = None
    speeds: Dict[str, float] = field(default_factory=dict)  # check_speeds: fraction of the rated speed per joint

    @property
    def passed(self) -> bool:
        """No finding."""
        return not self.findings

    def named(self) -> List[str]:
        """Every joint some finding names."""
        return sorted({name for finding in self.findings for name in finding.joints})


class Bench:
    """What the procedures drive: the servos through the calibration file's command map, and the feedback.
    :class:`DriverBench` is the driver objects on a bus; the pre-dive check's is the running stack's topics."""

    #: the pose last commanded (rad, JOINT_NAMES order)
    current: np.ndarray

    def outputs(self, on: bool) -> None:
        """PWM outputs on, or off (every servo limp)."""
        raise NotImplementedError

    def hold(self, angles: np.ndarray, duration: float) -> None:
        """Command ``angles`` for ``duration`` s (feeding the PWM watchdog)."""
        raise NotImplementedError

    def move_to(self, angles: np.ndarray) -> None:
        """Ramp from :attr:`current` to ``angles`` at a bounded joint speed."""
        raise NotImplementedError

    def step(self, angles: np.ndarray, duration: float) -> Tuple[np.ndarray, np.ndarray]:
        """Command ``angles`` at once (no ramp) and hold them ``duration`` s; the feedback read meanwhile: (times in
        s on one clock, angles rad: readings x 12)."""
        raise NotImplementedError

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass without commanding (outputs off)."""
        raise NotImplementedError

    def read_volts(self) -> np.ndarray:
        """One feedback reading, volts per joint (NaN: none); ValueError where only angles are available."""
        raise NotImplementedError

    def read_angles(self) -> np.ndarray:
        """One feedback reading through the calibration file's feedback map, rad per joint (NaN: none)."""
        raise NotImplementedError


class DriverBench(Bench):
    """The driver objects on a bus (the calibration CLI, the simulated rig)."""

    def __init__(self, driver: PoseDriver, pwm: ServoPwmOutput) -> None:
        self.driver = driver
        self.pwm = pwm

    @property
    def current(self) -> np.ndarray:  # type: ignore[override]
        return self.driver.current

    @current.setter
    def current(self, angles: np.ndarray) -> None:
        self.driver.current = np.array(angles, dtype=float)

    def outputs(self, on: bool) -> None:
        if on:
            self.pwm.enable()
        else:
            self.pwm.disable()

    def hold(self, angles: np.ndarray, duration: float) -> None:
        self.driver.hold(angles, duration)

    def move_to(self, angles: np.ndarray) -> None:
        self.driver.move_to(angles)

    def step(self, angles: np.ndarray, duration: float) -> Tuple[np.ndarray, np.ndarray]:
        start = self.driver.clock()
        times, rows = [], []
        while self.driver.clock() - start < duration:
            self.driver.hold(angles, 0.005)
            rows.append(self.read_angles())
            times.append(self.driver.clock())
        return np.array(times), np.array(rows)

    def wait(self, seconds: float) -> None:
        self.driver.sleep(seconds)

    def read_volts(self) -> np.ndarray:
        return np.asarray(self.driver.feedback.read().volts, dtype=float)

    def read_angles(self) -> np.ndarray:
        volts = self.read_volts()
        good = np.isfinite(volts)
        return np.where(good, self.driver.calibration.volts_to_angles(np.where(good, volts, 0.0)), math.nan)


class ServoCheck:
    """Runs the procedures of the module docstring on a :class:`Bench` with the calibration file's maps
    ``calibration``; ``place`` is the operator putting the limp legs in a pose (a prompt on the robot, the
    rig's hand in simulation)."""

    def __init__(self, bench: Bench, params: RobotParams, calibration: ServoCalibration,
                 place: Callable[[ReferencePose], None], settings: ServoCheckSettings = ServoCheckSettings(),
                 log: Callable[[str], None] = print) -> None:
        self.bench = bench
        self.params = params
        self.place = place
        self.settings = settings
        self.log = log
        self.calibration = calibration

    # ---- readings --------------------------------------------------------------------------------

    def _mean(self, read: Callable[[], np.ndarray], powered: bool) -> np.ndarray:
        """The mean of ``samples`` readings (NaN where a joint was never read); holds the pose if powered."""
        rows = []
        for _ in range(self.settings.samples):
            rows.append(read())
            if powered:
                self.bench.hold(self.bench.current, 0.01)
            else:
                self.bench.wait(0.01)
        rows_array = np.array(rows, dtype=float)
        counts = np.sum(np.isfinite(rows_array), axis=0)
        sums = np.nansum(rows_array, axis=0)
        return np.where(counts > 0, sums / np.maximum(counts, 1), math.nan)

    def reference_maps(self, poses: Sequence[ReferencePose]) -> Tuple[np.ndarray, np.ndarray, List[Finding]]:
        """Outputs off, the legs placed in ``poses`` (two) by the operator: each joint's feedback line through
        its readings, (slope rad/V, offset rad), NaN where unusable, and the findings."""
        self.bench.outputs(False)
        volts, angles = [], []
        for pose in poses:
            self.log("place the limp legs: %s (%s)" % (pose.name, pose.instruction))
            self.place(pose)
            volts.append(self._mean(self.bench.read_volts, powered=False))
            angles.append(pose.joint_angles())
        (v0, v1), (q0, q1) = volts, angles
        slope = (q1 - q0) / (v1 - v0)
        offset = q0 - slope * v0
        expected = np.array([j.feedback_slope for j in self.calibration.joints])
        findings = []
        for i, name in enumerate(JOINT_NAMES):
            span = abs(v1[i] - v0[i])
            if not span >= self.settings.min_span_v:
                findings.append(Finding((name,), "feedback", "its feedback reads %.3f V and %.3f V in the two "
                                        "reference poses (%.1f deg apart): it does not follow its servo"
                                        % (v0[i], v1[i], math.degrees(abs(q1[i] - q0[i]))),
                                        "check the feedback wire to its ADC input (stuck ADC, open wire, or "
                                        "the wire of a joint that did not move)"))
                slope[i] = offset[i] = math.nan
            elif abs(abs(slope[i] / expected[i]) - 1.0) > self.settings.slope_tolerance:
                findings.append(Finding((name,), "feedback", "its feedback changes %.1f deg/V between the poses, "
                                        "the servo's is %.1f deg/V" % (math.degrees(slope[i]),
                                                                      math.degrees(expected[i])),
                                        "its ADC input reads another joint's servo: check the feedback wiring"))
                slope[i] = offset[i] = math.nan
        return slope, offset, findings

    def _half_width(self, stance: ReferencePose, degrees: float) -> float:
        """The narrowest of the three joints' safe sweeps up to ``degrees``: a channel wired to another joint's
        servo turns that one."""
        return min(sweep_half_width(self.params, stance.leg_angles, j, math.radians(degrees)) for j in range(3))

    def sweep(self, index: int, stance: ReferencePose, read: Callable[[], np.ndarray]) -> JointSweep:
        """Sweep joint ``index`` symmetrically about ``stance`` (others held), reading every joint's angle."""
        half = self._half_width(stance, self.settings.sweep_deg)
        offsets = np.linspace(-half, half, self.settings.points)
        hold = stance.joint_angles()
        rows = []
        for delta in offsets:
            pose = hold.copy()
            pose[index] += delta
            self.bench.move_to(pose)
            self.bench.hold(pose, self.settings.settle_s)
            rows.append(self._mean(read, powered=True))
        self.bench.move_to(hold)
        return JointSweep(offsets, np.array(rows))

    # ---- judgement -------------------------------------------------------------------------------

    def judge(self, index: int, sweep: JointSweep, stance: ReferencePose) -> List[Finding]:
        """The findings of joint ``index``'s sweep (module docstring)."""
        s = self.settings
        name = JOINT_NAMES[index]
        readable = np.all(np.isfinite(sweep.angles), axis=0)
        filled = np.where(readable, sweep.angles, 0.0)
        moved = filled.max(axis=0) - filled.min(axis=0)
        span = float(sweep.offsets[-1] - sweep.offsets[0])
        others = [k for k in range(len(JOINT_NAMES)) if k != index and moved[k] > math.radians(s.cross_motion_deg)]
        gain, zero, _ = sweep.gain_and_zero(index)
        findings = []
        if others:
            other_names = tuple(JOINT_NAMES[k] for k in others)
            findings.append(Finding((name,) + other_names, "wiring", "commanding %s's channel moved %s by %s deg"
                                    % (name, ", ".join(other_names),
                                       ", ".join("%.0f" % math.degrees(moved[k]) for k in others)),
                                    "the PWM cables or the feedback wires of these joints are swapped: jog %s and "
                                    "watch which servo turns (it is its PWM cable if another one does, "
                                    "its feedback wire if it does)" % name))
        if not math.isfinite(gain):
            return findings  # its feedback map is unusable: said by the reference maps
        if gain < -(1.0 - s.gain_tolerance):
            findings.append(Finding((name,), "reversed", "it turns against its command (%.2f deg per commanded "
                                    "deg)" % gain, "the servo is mounted reversed: turn it round (or, if your "
                                    "robot mounts it so, set its direction to -1 in servo_calibration.yaml)"))
        elif abs(gain - 1.0) > s.gain_tolerance and not others:
            findings.append(Finding((name,), "tracking", "it follows %.2f of its command over a %.0f deg sweep"
                                    % (gain, math.degrees(span)), "it is blocked, overloaded or unpowered (free "
                                    "it, check its supply, give it longer: --settle), or its feedback wire is on "
                                    "another joint's input"))
        else:
            error = math.degrees(zero - stance.joint_angles()[index])
            if abs(error) > s.zero_tolerance_deg:
                findings.append(Finding((name,), "zero", "at its stance pulse it sits %+.1f deg from the stance "
                                        "marks" % error, "its horn is off its spline: re-seat it so the joint is "
                                        "within %.0f deg of the marks at the stance pulse (one spline of a 25-tooth "
                                        "horn is 14.4 deg), then calibrate again" % s.zero_tolerance_deg))
        return findings

    # ---- procedures ------------------------------------------------------------------------------

    def calibrate(self, poses: Tuple[ReferencePose, ReferencePose],
                  indices: Sequence[int] = tuple(range(len(JOINT_NAMES)))) -> ServoCheckResult:
        """The calibration of the module docstring; ``poses``: (stance, open). The legs end placed at stance."""
        stance, opened = poses
        slope, offset, findings = self.reference_maps((opened, stance))
        self.bench.current = stance.joint_angles()  # where the operator left the legs
        result = self._sweeps(stance, lambda: slope * self.bench.read_volts() + offset, indices)
        result.findings = _merge(findings + result.findings)
        if result.passed:
            result.calibration = self._new_calibration(result, stance, slope, offset, indices)
        return result

    def check_channels(self, stance: ReferencePose,
                       indices: Sequence[int] = tuple(range(len(JOINT_NAMES)))) -> ServoCheckResult:
        """Each channel moves its own joint, only it, the right way, by its command, with its zero at the stance
        marks: the sweeps read through the calibration file's maps. The servos start where they are (held at
        their feedback angles) and are ramped to ``stance``."""
        self.bench.current = self._mean(self.bench.read_angles, powered=False)
        if not np.all(np.isfinite(self.bench.current)):
            missing = [JOINT_NAMES[i] for i in np.flatnonzero(~np.isfinite(self.bench.current))]
            return ServoCheckResult([Finding(tuple(missing), "feedback", "no feedback angle",
                                             "check the feedback node and the ADCs (/diagnostics)")])
        result = self._sweeps(stance, self.bench.read_angles, indices)
        result.findings = _merge(result.findings)
        return result

    def check_speeds(self, stance: ReferencePose,
                     indices: Sequence[int] = tuple(range(len(JOINT_NAMES)))) -> ServoCheckResult:
        """Each joint, the others held at ``stance``, stepped ``speed_steps`` times across ``speed_step_deg``
        (alternately each way) while its feedback is recorded: the median 20-80 % rise inverted through the servo
        model gives its speed as a fraction of the rated one (:attr:`ServoCheckResult.speeds`); below
        ``min_speed_fraction`` it is a finding. Run it after :meth:`check_channels` passed (a channel on the wrong
        servo would step that one). The joints end at ``stance``."""
        s = self.settings
        result = ServoCheckResult()
        half = self._half_width(stance, s.speed_step_deg / 2.0)
        rated = self.params.servo_no_load_speed
        hold = stance.joint_angles()
        self.bench.outputs(True)
        for index in indices:
            name = JOINT_NAMES[index]
            pose = hold.copy()
            pose[index] -= half
            self.bench.move_to(pose)
            self.bench.hold(pose, s.settle_s)
            rises = []
            for _ in range(s.speed_steps):
                start = float(self._mean(self.bench.read_angles, powered=True)[index])
                offset = start - pose[index]  # the joint's own small zero error, carried to the step's end
                pose = hold.copy()
                pose[index] += half if start < hold[index] else -half
                times, angles = self.bench.step(pose, s.speed_record_s)
                rises.append(rise_time(times, angles[:, index] if len(angles) else angles, start,
                                       pose[index] + offset))
                self.bench.current = pose
            self.bench.move_to(hold)
            timed = [r for r in rises if not math.isnan(r)]
            rise = statistics.median(timed) if timed else math.nan
            fraction = speed_fraction(rise, 2.0 * half, rated, s.time_constant)
            result.speeds[name] = fraction
            if not fraction >= s.min_speed_fraction:
                healthy = model_rise_time(2.0 * half, rated, s.time_constant)
                seen = ("its steps could not be timed: each was past 20 %% at the first reading (is the joint "
                        "feedback at its rate?)" if math.isnan(rise) else
                        "it did not turn 80 %% of a %.0f deg step within %.2f s" % (math.degrees(2 * half),
                                                                                   s.speed_record_s)
                        if math.isinf(rise) else
                        "it turns at %.2f of its rated speed: 20-80 %% of a %.0f deg step in %.3f s (median of %d), "
                        "a servo at its rated speed %.3f s" % (fraction, math.degrees(2 * half), rise, len(timed),
                                                              healthy))
                result.findings.append(Finding((name,), "slow", seen, "a worn gearbox, water in the servo or a "
                                               "weak supply: check the motor pack's voltage and the servo's cable, "
                                               "then replace the servo"))
        return result

    def _sweeps(self, stance: ReferencePose, read: Callable[[], np.ndarray],
                indices: Sequence[int]) -> ServoCheckResult:
        result = ServoCheckResult()
        self.bench.outputs(True)
        self.bench.hold(self.bench.current, self.settings.settle_s)
        self.bench.move_to(stance.joint_angles())
        self.bench.hold(stance.joint_angles(), self.settings.settle_s)
        for index in indices:
            sweep = self.sweep(index, stance, read)
            result.sweeps[JOINT_NAMES[index]] = sweep
            result.findings.extend(self.judge(index, sweep, stance))
        return result

    def _new_calibration(self, result: ServoCheckResult, stance: ReferencePose, slope: np.ndarray,
                         offset: np.ndarray, indices: Sequence[int]) -> ServoCalibration:
        """The file's maps with each swept joint's feedback line, zero and gain from the sweeps."""
        joints = list(self.calibration.joints)
        for index in indices:
            joint = joints[index]
            gain, zero, rms = result.sweeps[JOINT_NAMES[index]].gain_and_zero(index)
            # the stance pulse puts the joint at `zero`; the joint turns `gain` per commanded radian
            stance_angle = stance.joint_angles()[index]
            stance_us = joint.neutral_us + joint.direction * joint.us_per_rad * (stance_angle - joint.neutral_angle_rad)
            us_per_rad = joint.us_per_rad / gain
            neutral_us = stance_us + joint.direction * us_per_rad * (joint.neutral_angle_rad - zero)
            joints[index] = replace(joint, neutral_us=float(neutral_us), us_per_rad=float(us_per_rad),
                                    feedback_slope=float(slope[index]), feedback_offset=float(offset[index]),
                                    feedback_fitted=True, feedback_rms_rad=float(rms))
        return ServoCalibration(joints)


def rise_time(times: np.ndarray, angles: np.ndarray, start: float, end: float, low: float = 0.2,
              high: float = 0.8) -> float:
    """The time (s) a joint's readings ``angles`` at ``times`` took from ``low`` to ``high`` of the way from
    ``start`` to ``end`` (first crossings, interpolated between readings); inf if it never reached ``high``, NaN if
    it was past ``low`` at the first reading (it cannot be timed)."""
    span = end - start
    if not (math.isfinite(span) and abs(span) > 0.0) or len(times) == 0:
        return math.nan
    progress = (np.asarray(angles, dtype=float) - start) / span
    crossings = []
    for level in (low, high):
        above = np.flatnonzero(progress >= level)
        if len(above) == 0:
            return math.inf
        k = int(above[0])
        if k == 0:
            return math.nan
        p0, p1 = progress[k - 1], progress[k]
        t0, t1 = float(times[k - 1]), float(times[k])
        crossings.append(t0 + (t1 - t0) * (level - p0) / (p1 - p0) if p1 > p0 else t1)
    return crossings[1] - crossings[0]


def model_rise_time(span: float, speed: float, time_constant: float, low: float = 0.2, high: float = 0.8) -> float:
    """The ``low``-``high`` rise time (s) of the servo model
    (:func:`~quadruped_control.model.servo.rate_limited_lag_step`) with ``speed`` (rad/s) and ``time_constant`` (s)
    after a step of ``span`` (rad): the times its error falls to (1 - low) and (1 - high) of ``span``."""
    def reach(error: float) -> float:
        # the exact solution from rate_limited_lag_step, solved for the time at which |e| = error
        lo, hi = 0.0, span / speed + 50.0 * time_constant + 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if abs(span - rate_limited_lag_step(0.0, span, speed, time_constant, mid)) > error:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)
    return reach((1.0 - high) * span) - reach((1.0 - low) * span)


def speed_fraction(rise: float, span: float, rated_speed: float, time_constant: float) -> float:
    """The fraction of ``rated_speed`` at which the servo model has the measured 20-80 % ``rise`` (s) after a
    step of ``span`` (rad): 0 for a joint that never finished (``rise`` inf), NaN when not timed; capped at 10 (a
    rise shorter than the model's lag alone allows)."""
    if math.isnan(rise):
        return math.nan
    if math.isinf(rise):
        return 0.0
    lo, hi = 1e-3, 10.0
    if model_rise_time(span, hi * rated_speed, time_constant) >= rise:
        return hi
    if model_rise_time(span, lo * rated_speed, time_constant) <= rise:
        return lo
    for _ in range(50):  # the rise shortens as the speed grows
        mid = math.sqrt(lo * hi)
        if model_rise_time(span, mid * rated_speed, time_constant) > rise:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


def _merge(findings: List[Finding]) -> List[Finding]:
    """One finding per wiring fault: the sweep of each of two swapped joints reports the other."""
    out: List[Finding] = []
    pairs = set()
    for finding in findings:
        if finding.kind == "wiring":
            key = frozenset(finding.joints)
            if key in pairs:
                continue
            pairs.add(key)
        out.append(finding)
    return out
