"""The pre-dive check: the robot on its stand, the stack running disarmed; five checks and a report.

1. **sensors**: the IMU and the joint feedback arrive at rate, every joint has an angle;
2. **IMU mount**: gravity at the operator's level and two guided tilts (:mod:`~quadruped_control.bringup.imu_check`);
3. **channels**: each PWM channel moves its own joint, only it, the right way, by its command, its zero at the
   stance marks, read through the calibration file (:meth:`~quadruped_control.bringup.servo_check.ServoCheck.
   check_channels`);
4. **servo speed**: each joint stepped across 60 deg at once turns at no less than 0.7 of its rated speed
   (:meth:`~quadruped_control.bringup.servo_check.ServoCheck.check_speeds`): a worn or wet servo, which tracks
   the slow strokes of a hold and lags only in the fast ones, shows here before the dive;
5. **strokes**: a small torque command about each body axis makes strokes whose drag turns the body that way
   (:mod:`~quadruped_control.bringup.stroke_check`).

A check that cannot run because an earlier one failed is reported as skipped, never as passed; the summary names
the joints a failed check found. The report is markdown and json (:meth:`PreflightReport.markdown`,
:meth:`PreflightReport.as_dict`); the ROS node saves it beside the bags and publishes the verdict the controller's
arming gate waits for.
"""
from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List

import numpy as np

from quadruped_control.bringup.imu_check import GUIDED_POSES, GUIDED_TILT_DEG, check_imu_mount
from quadruped_control.bringup.reference import reference_poses
from quadruped_control.bringup.servo_check import Bench, ServoCheck, ServoCheckSettings
from quadruped_control.bringup.stroke_check import check_strokes
from quadruped_control.model.params import RobotParams
from quadruped_drivers.calibration import ServoCalibration

__all__ = ["CheckItem", "PreflightReport", "SensorReadings", "run_preflight"]


@dataclass
class CheckItem:
    """One check: ``name``, ``status`` (passed, FAILED, skipped), what was seen, its figures and the ``parts`` (joints)
    it found at fault."""

    name: str
    status: str
    detail: str
    figures: Dict[str, Any] = field(default_factory=dict)
    parts: List[str] = field(default_factory=list)


@dataclass
class PreflightReport:
    """The checks in order; :attr:`passed` only when every one passed."""

    items: List[CheckItem] = field(default_factory=list)
    started: float = field(default_factory=time.time)
    notes: List[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.items) and all(item.status == "passed" for item in self.items)

    def summary(self) -> str:
        """One line: the verdict and the failed checks, each with the joints it found."""
        failed = [item.name + (" (%s)" % ", ".join(item.parts) if item.parts else "")
                  for item in self.items if item.status != "passed"]
        return "passed" if self.passed else "FAILED: %s" % ", ".join(failed)

    def as_dict(self) -> Dict[str, Any]:
        return OrderedDict([("passed", self.passed), ("summary", self.summary()),
                            ("started", time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.started))),
                            ("notes", self.notes),
                            ("checks", [OrderedDict([("name", i.name), ("status", i.status), ("detail", i.detail),
                                                     ("parts", i.parts), ("figures", i.figures)])
                                        for i in self.items])])

    def markdown(self) -> str:
        lines = ["# Pre-dive check: %s" % self.summary(), "", "Started %s." % self.as_dict()["started"], ""]
        lines += ["- %s" % note for note in self.notes] + ([""] if self.notes else [])
        lines += ["| check | status | what was seen |", "|---|---|---|"]
        for item in self.items:
            lines.append("| %s | %s | %s |" % (item.name, item.status, item.detail.replace("|", "/")))
        return "\n".join(lines) + "\n"


class SensorReadings:
    """What the check reads from the running stack (the ROS node's topics)."""

    def rates(self, seconds: float) -> Dict[str, float]:
        """Messages per second of ``imu`` and ``joints`` over ``seconds``."""
        raise NotImplementedError

    def joint_angles(self) -> np.ndarray:
        """The latest joint angles (rad, JOINT_NAMES order; NaN: none)."""
        raise NotImplementedError

    def specific_force(self, seconds: float) -> np.ndarray:
        """The IMU's mean specific force over ``seconds`` (m/s^2, body axes as reported)."""
        raise NotImplementedError


def run_preflight(bench: Bench, sensors: SensorReadings, guide: Callable[[str, str, float, float], None],
                  params: RobotParams, calibration: ServoCalibration, expected_rates: Dict[str, float],
                  settings: ServoCheckSettings = ServoCheckSettings(),
                  log: Callable[[str], None] = print, min_rate_fraction: float = 0.9) -> PreflightReport:
    """The five checks of the module docstring. ``guide(name, instruction, roll_deg, pitch_deg)`` has the operator
    hold the robot in a guided pose (returns when it is held); ``expected_rates``: ``imu`` and ``joints`` (Hz), each
    passing from ``min_rate_fraction`` of it."""
    report = PreflightReport()
    stance = reference_poses(params)[0]

    log("pre-dive check 1/5: sensors")
    rates = sensors.rates(2.0)
    angles = sensors.joint_angles()
    slow = ["%s %.0f Hz (expected %.0f)" % (name, rates.get(name, 0.0), rate)
            for name, rate in expected_rates.items() if not rates.get(name, 0.0) >= min_rate_fraction * rate]
    missing = int(np.count_nonzero(~np.isfinite(angles)))
    problems = slow + (["%d joints without an angle" % missing] if missing else [])
    report.items.append(CheckItem("sensors", "FAILED" if problems else "passed",
                                  "; ".join(problems) or "IMU %.0f Hz, joints %.0f Hz, every joint read" % (
                                      rates.get("imu", 0.0), rates.get("joints", 0.0)),
                                  {"rates_hz": {k: round(v, 1) for k, v in rates.items()}}))
    sensors_ok = not problems

    log("pre-dive check 2/5: IMU mount (guided poses)")
    if rates.get("imu", 0.0) > 0.0:
        readings = []
        for name, instruction, (roll_sign, pitch_sign) in GUIDED_POSES:
            guide(name, instruction, roll_sign * GUIDED_TILT_DEG, pitch_sign * GUIDED_TILT_DEG)
            readings.append(sensors.specific_force(0.5))
        guide("level", "back to level", 0.0, 0.0)
        imu = check_imu_mount(readings)
        detail = "; ".join(imu.problems) or "up axis %.1f deg, heading %+.1f deg from the body's" % (
            imu.tilt_deg, imu.heading_deg)
        report.items.append(CheckItem("IMU mount", "passed" if imu.passed else "FAILED", detail,
                                      {"specific_force": np.round(np.array(readings), 3).tolist(),
                                       "error_deg": None if math.isnan(imu.error_deg) else round(imu.error_deg, 2)}))
    else:
        report.items.append(CheckItem("IMU mount", "skipped", "no IMU data"))

    log("pre-dive check 3/5: channels")
    check = ServoCheck(bench, params, calibration, lambda pose: None, settings, log)
    if sensors_ok:
        channels = check.check_channels(stance)
        report.items.append(CheckItem("channels", "passed" if channels.passed else "FAILED",
                                      "; ".join(str(f) for f in channels.findings) or
                                      "each channel moves its own joint, the right way, zero at the marks",
                                      {"findings": [str(f) for f in channels.findings]}, channels.named()))
    else:
        channels = None
        report.items.append(CheckItem("channels", "skipped", "the sensors check failed"))

    log("pre-dive check 4/5: servo speed")
    if channels is not None and channels.passed:
        speeds = check.check_speeds(stance)
        slowest = min(speeds.speeds, key=lambda name: speeds.speeds[name])
        report.items.append(CheckItem("servo speed", "passed" if speeds.passed else "FAILED",
                                      "; ".join(str(f) for f in speeds.findings) or
                                      "every servo at %.2f or more of its rated speed (slowest: %s, %.2f)" % (
                                          settings.min_speed_fraction, slowest, speeds.speeds[slowest]),
                                      {"speed_fraction": {k: round(v, 3) for k, v in speeds.speeds.items()}},
                                      speeds.named()))
    else:
        report.items.append(CheckItem("servo speed", "skipped", "the channels check did not pass"))

    log("pre-dive check 5/5: strokes")
    if channels is not None and channels.passed:
        strokes = check_strokes(bench, params, stance)
        report.items.append(CheckItem("strokes", "passed" if strokes.passed else "FAILED",
                                      "; ".join(strokes.problems) or "drag torque within %s deg of roll, pitch, "
                                      "yaw" % ", ".join("%.0f" % a for a in strokes.angles_deg),
                                      {"angles_deg": strokes.angles_deg}))
    else:
        report.items.append(CheckItem("strokes", "skipped", "the channels check did not pass"))
    return report

