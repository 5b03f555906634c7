"""Fit each servo's feedback map (volts -> joint angle) by sweeping it through its range.

    python -m quadruped_drivers.calibrate [--fake] [--bus N] [--out PATH] [--joints NAME ...]
                                          [--points 7] [--settle 0.3]

For each selected joint, one at a time, with every other joint held at its neutral angle (the middle
of its range, ``config/servo_calibration.yaml``): ramp (at ``--speed`` deg/s) through ``--points``
angles spread over the joint's range (``config/robot.yaml`` joint_limits_deg, shrunk by ``--margin``
and kept inside the channel's pulse limits from ``config/hardware.yaml``), wait ``--settle`` s at
each, average a few feedback samples, then return to neutral. A least-squares line
angle = slope * volts + offset is fitted per joint; a joint whose feedback barely changes ("does not
move") or whose fit is poor (RMS residual over ``--max-rms`` deg, |r| < 0.99) is rejected with an
error and nothing is written. The result replaces the feedback maps in the calibration file and keeps
the command (pulse) maps. The PWM watchdog is fed throughout; outputs are switched off at the end.

``--fake`` runs the same code against the fake hardware with :class:`SimulatedServoRig`: servos that
follow the PCA9685 pulse widths at a limited speed and produce feedback volts through a known map
(the file's map, slope x1.04, offset +3 deg) plus noise. It writes to ``out/`` unless ``--out`` is given.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, config_path
from quadruped_common.robot import JOINT_NAMES, load_joint_limits
from quadruped_drivers.calibration import ServoCalibration, load_servo_calibration, save_servo_calibration
from quadruped_drivers.hardware_config import HardwareConfig, load_hardware_config
from quadruped_drivers.i2c.fake_devices import FakeHardware, build_fake_hardware
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray

#: Command period while holding or ramping (s): well inside the PWM watchdog timeout.
COMMAND_PERIOD = 0.02


class CalibrationError(RuntimeError):
    """A joint could not be calibrated (no feedback, does not move, or a poor fit)."""


@dataclass
class JointFit:
    """Result for one joint: angle = slope * volts + offset (rad, V), with quality figures."""

    index: int
    name: str
    slope: float
    offset: float
    rms_rad: float
    correlation: float
    angles: np.ndarray
    volts: np.ndarray


def fit_feedback(name: str, angles: Sequence[float], volts: Sequence[float], min_span_v: float = 0.1,
                 max_rms_deg: float = 2.0, min_correlation: float = 0.99) -> Tuple[float, float, float, float]:
    """Least-squares angle = slope * volts + offset. Returns (slope, offset, rms_rad, correlation).

    Raises :class:`CalibrationError` if the feedback spans less than ``min_span_v`` (the joint does not
    move or its feedback wire is open), or the fit is poor.
    """
    q = np.asarray(angles, dtype=float)
    v = np.asarray(volts, dtype=float)
    if q.shape != v.shape or q.size < 3:
        raise CalibrationError("%s: need at least 3 (angle, volts) pairs, got %d" % (name, min(q.size, v.size)))
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
        raise CalibrationError("%s: non-finite samples in the sweep" % name)
    span = float(v.max() - v.min())
    if span < min_span_v:
        raise CalibrationError("%s: feedback changed by only %.3f V over a %.0f deg sweep: the joint does not move "
                               "or its feedback is not connected" % (name, span, math.degrees(q.max() - q.min())))
    design = np.column_stack([v, np.ones_like(v)])
    (slope, offset), *_ = np.linalg.lstsq(design, q, rcond=None)
    residual = q - (slope * v + offset)
    rms = float(np.sqrt(np.mean(residual ** 2)))
    correlation = float(np.corrcoef(v, q)[0, 1])
    if abs(correlation) < min_correlation or math.degrees(rms) > max_rms_deg:
        raise CalibrationError("%s: poor fit (RMS residual %.2f deg, correlation %.4f; limits %.2f deg, %.2f): "
                               "check the servo is free to move and the feedback wiring"
                               % (name, math.degrees(rms), correlation, max_rms_deg, min_correlation))
    return float(slope), float(offset), rms, correlation


class SimulatedServoRig:
    """Fake hardware plus twelve servos that follow the pulse widths the fake PCA9685 holds.

    Each servo moves toward ``calibration.pulses_to_angles(pulse)`` at ``speed`` rad/s (an output that
    is off holds its angle) and its feedback voltage is ``(angle - true_offset) / true_slope`` plus
    Gaussian noise of ``noise_v``. Time is virtual: :meth:`sleep` advances it in 1 ms steps.
    """

    def __init__(self, hardware_config: HardwareConfig, calibration: ServoCalibration, slope_scale: float = 1.04,
                 offset_shift_deg: float = 3.0, noise_v: float = 0.002, speed: float = math.radians(570.0),
                 seed: int = 0) -> None:
        self.hardware: FakeHardware = build_fake_hardware(hardware_config)
        self.calibration = calibration
        self.true_slope = np.array([j.feedback_slope for j in calibration.joints]) * slope_scale
        self.true_offset = (np.array([j.feedback_offset for j in calibration.joints])
                            + math.radians(offset_shift_deg))
        self.noise_v = noise_v
        self.speed = speed
        self.rng = np.random.default_rng(seed)
        self.time = 0.0
        self.angles = np.array([j.neutral_angle_rad for j in calibration.joints])
        self._feed()

    @property
    def bus(self):
        """The fake bus the drivers talk to."""
        return self.hardware.bus

    def clock(self) -> float:
        """Virtual time (s)."""
        return self.time

    def _feed(self) -> None:
        volts = (self.angles - self.true_offset) / self.true_slope
        volts = volts + self.rng.normal(0.0, self.noise_v, volts.shape) if self.noise_v > 0 else volts
        self.hardware.set_joint_voltages(np.clip(volts, -0.3, 5.3))

    def sleep(self, seconds: float) -> None:
        """Advance virtual time by ``seconds``, moving the servos and updating the feedback voltages."""
        steps = max(1, int(math.ceil(seconds / 0.001)))
        dt = seconds / steps
        pulses = self.hardware.pulse_widths_us()  # only commands change them, never during a sleep
        on = pulses > 0.0
        target = self.calibration.pulses_to_angles(np.where(on, pulses, 1500.0))
        for _ in range(steps):
            step = np.clip(target - self.angles, -self.speed * dt, self.speed * dt)
            self.angles = np.where(on, self.angles + step, self.angles)
        self.time += seconds
        self._feed()


class Calibrator:
    """Drives the sweeps through the real driver objects (``pwm``, ``feedback``)."""

    def __init__(self, pwm: ServoPwmOutput, feedback: ServoFeedbackArray, calibration: ServoCalibration,
                 joint_ranges: np.ndarray, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, speed: float = math.radians(90.0),
                 samples: int = 5, log: Callable[[str], None] = print) -> None:
        self.pwm = pwm
        self.feedback = feedback
        self.calibration = calibration
        self.joint_ranges = joint_ranges
        self.clock = clock
        self.sleep = sleep
        self.speed = speed
        self.samples = samples
        self.log = log
        self.neutral = np.array([j.neutral_angle_rad for j in calibration.joints])
        self.current = self.neutral.copy()

    def hold(self, angles: np.ndarray, duration: float) -> None:
        """Command ``angles`` for ``duration`` s, re-sending every COMMAND_PERIOD (feeds the watchdog)."""
        pulses = self.calibration.angles_to_pulses(angles)
        end = self.clock() + duration
        while True:
            self.pwm.command(pulses)
            self.pwm.update()
            remaining = end - self.clock()
            if remaining <= 0:
                break
            self.sleep(min(COMMAND_PERIOD, remaining))
        self.current = np.array(angles, dtype=float)

    def move_to(self, angles: np.ndarray) -> None:
        """Ramp from the current pose to ``angles`` at ``speed`` rad/s."""
        target = np.asarray(angles, dtype=float)
        distance = float(np.max(np.abs(target - self.current)))
        steps = max(1, int(math.ceil(distance / (self.speed * COMMAND_PERIOD))))
        start = self.current.copy()
        for step in range(1, steps + 1):
            self.hold(start + (target - start) * step / steps, COMMAND_PERIOD)

    def measure(self, index: int) -> float:
        """Mean feedback volts of joint ``index`` over ``samples`` reads."""
        values = []
        for _ in range(self.samples):
            reading = self.feedback.read()
            if np.isfinite(reading.volts[index]):  # read from the bus (plausible or not: we are fitting the map)
                values.append(float(reading.volts[index]))
            self.hold(self.current, 0.01)
        if not values:
            raise CalibrationError("%s: no valid feedback (ADC not answering?)" % JOINT_NAMES[index])
        return float(np.mean(values))

    def sweep_angles(self, index: int, points: int, margin: float) -> np.ndarray:
        """``points`` angles across joint ``index``'s range, shrunk by ``margin`` rad at both ends."""
        low, high = self.joint_ranges[index]
        low, high = low + margin, high - margin
        if high <= low:
            raise CalibrationError("%s: range [%.1f, %.1f] deg is empty after the margin"
                                   % (JOINT_NAMES[index], math.degrees(low), math.degrees(high)))
        return np.linspace(low, high, points)

    def calibrate_joint(self, index: int, points: int, settle: float, margin: float) -> JointFit:
        """Sweep joint ``index`` from the neutral pose and fit its feedback map."""
        angles = self.sweep_angles(index, points, margin)
        volts = []
        self.move_to(self.neutral)
        for angle in angles:
            pose = self.neutral.copy()
            pose[index] = angle
            self.move_to(pose)
            self.hold(pose, settle)
            volts.append(self.measure(index))
        self.move_to(self.neutral)
        slope, offset, rms, correlation = fit_feedback(JOINT_NAMES[index], angles, volts)
        return JointFit(index, JOINT_NAMES[index], slope, offset, rms, correlation, angles, np.array(volts))

    def run(self, indices: Sequence[int], points: int, settle: float, margin: float) -> List[JointFit]:
        """Calibrate ``indices`` one after the other; stops at the first failure (CalibrationError)."""
        fits = []
        self.move_to(self.neutral)
        self.hold(self.neutral, settle)
        for index in indices:
            fit = self.calibrate_joint(index, points, settle, margin)
            self.log("%-12s angle = %8.3f deg/V * V %+9.3f deg   (RMS %.3f deg, r = %.5f)"
                     % (fit.name, math.degrees(fit.slope), math.degrees(fit.offset), math.degrees(fit.rms_rad),
                        fit.correlation))
            fits.append(fit)
        return fits


def joint_ranges(hardware_config: HardwareConfig, calibration: ServoCalibration) -> np.ndarray:
    """Per joint [low, high] (rad): the robot's joint limits intersected with the pulse limits."""
    limits = load_joint_limits().as_array()
    ranges = np.array([limits[index % 3] for index in range(len(JOINT_NAMES))])
    at_min = calibration.pulses_to_angles(hardware_config.min_us)
    at_max = calibration.pulses_to_angles(hardware_config.max_us)
    pulse_low, pulse_high = np.minimum(at_min, at_max), np.maximum(at_min, at_max)
    return np.column_stack([np.maximum(ranges[:, 0], pulse_low), np.minimum(ranges[:, 1], pulse_high)])


def _parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m quadruped_drivers.calibrate", description=__doc__.split("\n\n")[0])
    parser.add_argument("--fake", action="store_true", help="run against the fake hardware and simulated servos")
    parser.add_argument("--bus", type=int, default=None, help="I2C bus number (default: hardware.yaml i2c.bus)")
    parser.add_argument("--hardware", default=None, help="hardware.yaml (default: config/hardware.yaml)")
    parser.add_argument("--calibration", default=None, help="calibration to start from (default: config/servo_calibration.yaml)")
    parser.add_argument("--out", default=None, help="where to write the result (default: the --calibration file; "
                        "with --fake: out/servo_calibration.fake.yaml)")
    parser.add_argument("--joints", nargs="+", default=None, metavar="NAME", help="joints to calibrate (default: all)")
    parser.add_argument("--points", type=int, default=7, help="sweep points per joint (>= 3)")
    parser.add_argument("--settle", type=float, default=0.3, help="settling time per point (s)")
    parser.add_argument("--margin", type=float, default=5.0, help="stay this far inside each joint range (deg)")
    parser.add_argument("--speed", type=float, default=90.0, help="ramp speed between points (deg/s)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed of the simulated servos (--fake)")
    args = parser.parse_args(argv)
    if args.points < 3:
        parser.error("--points must be >= 3")
    if not (math.isfinite(args.settle) and args.settle >= 0):
        parser.error("--settle must be >= 0")
    if not (math.isfinite(args.speed) and args.speed > 0):
        parser.error("--speed must be > 0")
    if args.joints:
        unknown = [name for name in args.joints if name not in JOINT_NAMES]
        if unknown:
            parser.error("unknown joints %s; choose from %s" % (unknown, " ".join(JOINT_NAMES)))
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """CLI entry point; returns the process exit code (0 ok, 1 calibration failed, 2 set-up error)."""
    args = _parse_args(argv)
    try:
        hardware = load_hardware_config(args.hardware)
        source = args.calibration or config_path("servo_calibration.yaml")
        calibration = load_servo_calibration(source)
        ranges = joint_ranges(hardware, calibration)
    except (ParameterError, ValueError) as exc:
        print("calibrate: configuration error: %s" % exc, file=sys.stderr)
        return 2
    if args.fake:
        rig = SimulatedServoRig(hardware, calibration, seed=args.seed)
        bus, clock, sleep = rig.bus, rig.clock, rig.sleep
        out = args.out or os.path.join("out", "servo_calibration.fake.yaml")
    else:
        from quadruped_drivers.i2c.real_bus import I2CBackendError, open_i2c_bus
        try:
            bus = open_i2c_bus(hardware.i2c_bus if args.bus is None else args.bus)
        except (I2CBackendError, ValueError) as exc:
            print("calibrate: %s" % exc, file=sys.stderr)
            return 2
        clock, sleep = time.monotonic, time.sleep
        out = args.out or source
    indices = [JOINT_NAMES.index(name) for name in (args.joints or JOINT_NAMES)]
    pwm = ServoPwmOutput(bus, hardware, clock=clock, sleep=sleep)
    feedback = ServoFeedbackArray(bus, hardware, calibration, clock=clock)
    try:
        pwm.start()
        missing = feedback.start()
        if missing:
            print("calibrate: warning: ADCs of %s did not answer at start-up" % [JOINT_NAMES[i] for i in missing],
                  file=sys.stderr)
        calibrator = Calibrator(pwm, feedback, calibration, ranges, clock=clock, sleep=sleep,
                                speed=math.radians(args.speed))
        fits = calibrator.run(indices, args.points, args.settle, math.radians(args.margin))
    except CalibrationError as exc:
        print("calibrate: FAILED: %s (nothing written)" % exc, file=sys.stderr)
        return 1
    except Exception as exc:  # bus or chip failure: report it, outputs go off in finally
        print("calibrate: error: %s: %s (nothing written)" % (type(exc).__name__, exc), file=sys.stderr)
        return 2
    finally:
        pwm.shutdown()
    result = calibration
    for fit in fits:
        result = result.with_feedback(fit.index, fit.slope, fit.offset, fit.rms_rad)
    note = "feedback fitted %s for %s%s" % (time.strftime("%Y-%m-%d %H:%M"), ", ".join(f.name for f in fits),
                                            " (FAKE hardware)" if args.fake else "")
    save_servo_calibration(result, out, note)
    print("calibrate: wrote %s" % out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
