"""Servo calibration maps: joint angle <-> pulse width (command side) and feedback volts <-> angle.

Angles are the paper's joint angles theta1, theta2 (five-bar, eq. ik_theta1245) and theta3 (hip,
eq. ik_theta3) in radians, in :data:`quadruped_common.robot.JOINT_NAMES` order. With the robot's
servo ranges (``config/robot.yaml`` joint_limits_deg: theta1 in [-230, -50], theta2 in [-130, 50],
theta3 in [0, 180] deg) each joint spans exactly the 180 deg travel of its servo, so the natural map
puts the middle of the range (-140, -40, 90 deg) at the 1500 us neutral pulse:

    pulse_us = neutral_us + direction * us_per_rad * (theta - neutral_angle_rad)          (command)
    theta    = feedback_slope * volts + feedback_offset                                 (feedback)

``us_per_rad`` = 2000 us / pi for a 180 deg, 500..2500 us servo. The feedback map is fitted by
``python -m quadruped_drivers.calibrate``; until then it is an estimate. Pulse limits are not applied
here: they are per-channel hardware limits enforced by :class:`~quadruped_drivers.pwm_output.ServoPwmOutput`.
"""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, replace
from typing import Any, Mapping, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, boolean, check_keys, integer, load_config, number
from quadruped_common.robot import JOINT_NAMES


@dataclass(frozen=True)
class JointCalibration:
    """Maps of one joint. Angles in rad, pulses in us, volts in V; ``feedback_slope`` in rad/V."""

    name: str
    neutral_angle_rad: float
    neutral_us: float
    direction: int
    us_per_rad: float
    feedback_slope: float
    feedback_offset: float
    feedback_fitted: bool = False
    feedback_rms_rad: Optional[float] = None


def _as_vector(values: Any, what: str, count: int = len(JOINT_NAMES)) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != (count,):
        raise ValueError("%s: expected %d values, got shape %s" % (what, count, array.shape))
    if not np.all(np.isfinite(array)):
        bad = [JOINT_NAMES[i] for i in np.flatnonzero(~np.isfinite(array))]
        raise ValueError("%s: non-finite value for %s" % (what, ", ".join(bad)))
    return array


class ServoCalibration:
    """All twelve joints' maps, vectorised. Build with :func:`load_servo_calibration`."""

    def __init__(self, joints: Sequence[JointCalibration]) -> None:
        if [joint.name for joint in joints] != list(JOINT_NAMES):
            raise ValueError("calibration joints must be exactly %s in that order" % (list(JOINT_NAMES),))
        self.joints: Tuple[JointCalibration, ...] = tuple(joints)
        self._neutral_angle = np.array([j.neutral_angle_rad for j in joints])
        self._neutral_us = np.array([j.neutral_us for j in joints])
        self._gain = np.array([j.direction * j.us_per_rad for j in joints])
        self._slope = np.array([j.feedback_slope for j in joints])
        self._offset = np.array([j.feedback_offset for j in joints])

    def angles_to_pulses(self, angles: Sequence[float]) -> np.ndarray:
        """Pulse widths (us) that put the servos at joint ``angles`` (rad); ValueError on NaN/inf/shape."""
        q = _as_vector(angles, "angles_to_pulses")
        return self._neutral_us + self._gain * (q - self._neutral_angle)

    def pulses_to_angles(self, pulses: Sequence[float]) -> np.ndarray:
        """Inverse of :meth:`angles_to_pulses` (the simulator's servo target from the PCA9685 pulses)."""
        p = _as_vector(pulses, "pulses_to_angles")
        return self._neutral_angle + (p - self._neutral_us) / self._gain

    def volts_to_angles(self, volts: Sequence[float]) -> np.ndarray:
        """Joint angles (rad) from feedback voltages (V)."""
        v = _as_vector(volts, "volts_to_angles")
        return self._slope * v + self._offset

    def angles_to_volts(self, angles: Sequence[float]) -> np.ndarray:
        """Inverse of :meth:`volts_to_angles` (the simulator feeding the fake ADCs)."""
        q = _as_vector(angles, "angles_to_volts")
        return (q - self._offset) / self._slope

    def with_feedback(self, index: int, slope: float, offset: float,
                      rms_rad: Optional[float] = None) -> "ServoCalibration":
        """A copy with joint ``index``'s feedback map replaced by a fitted one."""
        if not (math.isfinite(slope) and math.isfinite(offset)) or slope == 0.0:
            raise ValueError("feedback map of %s must be finite with a non-zero slope" % JOINT_NAMES[index])
        joints = list(self.joints)
        joints[index] = replace(joints[index], feedback_slope=float(slope), feedback_offset=float(offset),
                                feedback_fitted=True, feedback_rms_rad=None if rms_rad is None else float(rms_rad))
        return ServoCalibration(joints)


#: Keys of one joint's entry: (low, high) bounds of the numbers; the others are checked below.
_JOINT_NUMBERS = {
    "neutral_angle_deg": (-360.0, 360.0),   # a joint angle
    "neutral_us": (500.0, 2500.0),          # inside the servos' pulse range
    "us_per_deg": (1.0, 50.0),              # 180 deg over 2000 us is 11.1
    "feedback_deg_per_v": (-1e4, 1e4),      # |slope| of a 3.3 V potentiometer over ~180 deg is ~75
    "feedback_offset_deg": (-1e5, 1e5),
    "feedback_rms_deg": (0.0, 90.0),        # an RMS is non-negative
}
_JOINT_KEYS = tuple(_JOINT_NUMBERS) + ("direction", "feedback_fitted")
_JOINT_REQUIRED = ("neutral_angle_deg", "neutral_us", "direction", "us_per_deg", "feedback_deg_per_v",
                   "feedback_offset_deg")


def servo_calibration_from_dict(tree: Mapping[str, Any]) -> ServoCalibration:
    """Validate a parsed ``servo_calibration.yaml`` tree (degrees on disk, radians inside)."""
    check_keys(tree, "", ("joints",), ("joints",), what="calibration parameter")
    joints_tree = check_keys(tree["joints"], "joints", JOINT_NAMES, JOINT_NAMES, what="calibration parameter")
    joints = []
    for name in JOINT_NAMES:
        dotted = "joints.%s" % name
        entry = check_keys(joints_tree[name], dotted, _JOINT_KEYS, _JOINT_REQUIRED, what="calibration parameter")
        values = {key: number(entry[key], "%s.%s" % (dotted, key), low, high, what="calibration parameter")
                  for key, (low, high) in _JOINT_NUMBERS.items() if key in entry}
        direction = integer(entry["direction"], dotted + ".direction", -1, 1, what="calibration parameter")
        if direction == 0:
            raise ParameterError("calibration parameter '%s.direction' must be 1 or -1, got 0" % dotted)
        if values["feedback_deg_per_v"] == 0.0:
            raise ParameterError("calibration parameter '%s.feedback_deg_per_v' must not be 0" % dotted)
        fitted = boolean(entry.get("feedback_fitted", False), dotted + ".feedback_fitted", what="calibration parameter")
        rms = values.get("feedback_rms_deg")
        joints.append(JointCalibration(
            name=name,
            neutral_angle_rad=math.radians(values["neutral_angle_deg"]),
            neutral_us=values["neutral_us"],
            direction=direction,
            us_per_rad=values["us_per_deg"] * 180.0 / math.pi,
            feedback_slope=math.radians(values["feedback_deg_per_v"]),
            feedback_offset=math.radians(values["feedback_offset_deg"]),
            feedback_fitted=fitted,
            feedback_rms_rad=None if rms is None else math.radians(rms),
        ))
    return ServoCalibration(joints)


def load_servo_calibration(path: Optional[str] = None) -> ServoCalibration:
    """Load ``config/servo_calibration.yaml`` (or ``path``); ParameterError on any problem."""
    return load_config(path, "servo_calibration.yaml", servo_calibration_from_dict)


_HEADER = """\
# Servo calibration (loaded by quadruped_drivers/calibration.py). Degrees and microseconds on disk.
#
# Command map:  pulse_us = neutral_us + direction * us_per_deg * (angle_deg - neutral_angle_deg)
#   Angles are the paper's joint angles theta1 (motor1), theta2 (motor2), theta3 (hip). Each joint's
#   range (config/robot.yaml joint_limits_deg) is the servo's full 180 deg, so the middle of the range
#   (theta1 -140, theta2 -40, theta3 90 deg) sits at 1500 us and the range maps onto 500..2500 us
#   (us_per_deg = 2000 / 180).
#   [estimate] neutral_us and direction: the servo horn zero offsets are not in the paper; trim
#   neutral_us per joint so the leg sits at its mid angle, flip direction if a joint turns the wrong way.
# Feedback map: angle_deg = feedback_deg_per_v * volts + feedback_offset_deg
#   [estimate] unless feedback_fitted is true: assumes the feedback potentiometer reads 0.5 V .. 2.9 V
#   over the travel. Fit it with:  python -m quadruped_drivers.calibrate  (rewrites this file, keeping
#   the command maps).
"""


def calibration_to_yaml(calibration: ServoCalibration, note: str = "") -> str:
    """YAML text of ``calibration`` with the explanatory header (and ``note`` as a comment line)."""
    lines = [_HEADER.rstrip("\n")]
    if note:
        lines.append("# %s" % note)
    lines.append("joints:")
    for joint in calibration.joints:
        lines.append("  %s:" % joint.name)
        lines.append("    neutral_angle_deg: %.4f" % math.degrees(joint.neutral_angle_rad))
        lines.append("    neutral_us: %.2f" % joint.neutral_us)
        lines.append("    direction: %d" % joint.direction)
        lines.append("    us_per_deg: %.6f" % (joint.us_per_rad * math.pi / 180.0))
        lines.append("    feedback_deg_per_v: %.6f" % math.degrees(joint.feedback_slope))
        lines.append("    feedback_offset_deg: %.6f" % math.degrees(joint.feedback_offset))
        lines.append("    feedback_fitted: %s" % ("true" if joint.feedback_fitted else "false"))
        if joint.feedback_rms_rad is not None:
            lines.append("    feedback_rms_deg: %.6f" % math.degrees(joint.feedback_rms_rad))
    return "\n".join(lines) + "\n"


def save_servo_calibration(calibration: ServoCalibration, path: str, note: str = "") -> None:
    """Write ``calibration`` to ``path`` atomically (temporary file + rename)."""
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=".servo_calibration.", dir=directory)
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(calibration_to_yaml(calibration, note))
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


__all__ = ["JointCalibration", "ServoCalibration", "servo_calibration_from_dict", "load_servo_calibration",
           "calibration_to_yaml", "save_servo_calibration"]
