"""Servo calibration maps: joint angle <-> pulse width (command side) and feedback volts <-> angle.

Angles are the paper's joint angles theta1, theta2 (five-bar, eq. ik_theta1245) and theta3 (hip,
eq. ik_theta3) in radians, in :data:`quadruped_common.robot.JOINT_NAMES` order. With the robot's
servo ranges (``config/robot.yaml`` joint_limits_deg: theta1 in [-230, -50], theta2 in [-130, 50],
theta3 in [0, 180] deg) each joint spans exactly the 180 deg travel of its servo, so the natural map
puts the middle of the range (-140, -40, 90 deg) at the 1500 us neutral pulse:

    pulse_us = neutral_us + direction * us_per_rad * (theta - neutral_angle_rad)          (command)
    theta    = feedback_slope * volts + feedback_offset                                 (feedback)

``us_per_rad`` = 2000 us / pi for a 180 deg, 500..2500 us servo. Both maps are fitted against the robot's
reference poses by ``python -m quadruped_control.bringup.calibrate``; until then they are estimates. Pulse limits are not applied
here: they are per-channel hardware limits enforced by :class:`~quadruped_drivers.pwm_output.ServoPwmOutput`.
The file lists every joint; each parameter of a joint's entry is declared once, in :data:`CALIBRATION_SCHEMA`.
"""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, replace
from typing import Any, Mapping, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import load_config
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.schema import Param, Schema


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


def _nonzero(value: float) -> Optional[str]:
    return "must not be 0" if value == 0 else None


def _direction(value: int) -> Optional[str]:
    return "must be 1 or -1" if value == 0 else None


#: ``config/servo_calibration.yaml`` (written by ``python -m quadruped_control.bringup.calibrate``): every joint's
#: command and feedback maps, in degrees and microseconds.
CALIBRATION_SCHEMA = Schema("servo_calibration.yaml", (
    Param("joints.<joint>.neutral_angle_deg", "deg", "joint angle commanded by neutral_us (middle of its "
          "robot.yaml joint_limits_deg range)", -360.0, 360.0),
    Param("joints.<joint>.neutral_us", "us", "pulse that puts the servo at neutral_angle_deg (trim it so the leg "
          "sits at its mid angle)", 500.0, 2500.0, source="estimate"),
    Param("joints.<joint>.direction", "", "1 or -1: sign of the pulse change per degree (flip it if the joint "
          "turns the wrong way)", -1, 1, kind="integer", source="estimate", check=_direction),
    Param("joints.<joint>.us_per_deg", "us/deg", "pulse change per degree (2000 us over the servo's 180 deg = "
          "11.1)", 1.0, 50.0),
    Param("joints.<joint>.feedback_deg_per_v", "deg/V", "feedback map's slope: angle_deg = feedback_deg_per_v x "
          "volts + feedback_offset_deg (not 0)", -1e4, 1e4, source="estimate", check=_nonzero),
    Param("joints.<joint>.feedback_offset_deg", "deg", "feedback map's offset (angle at 0 V)", -1e5, 1e5,
          source="estimate"),
    Param("joints.<joint>.feedback_fitted", "", "true once the feedback map was fitted to a sweep; false: an "
          "estimate", kind="boolean", default=False),
    Param("joints.<joint>.feedback_rms_deg", "deg", "RMS residual of the fitted feedback map (written by the "
          "fit)", 0.0, 90.0, optional=True),
), names={"joint": JOINT_NAMES}, what="calibration parameter")


def servo_calibration_from_dict(tree: Mapping[str, Any]) -> ServoCalibration:
    """Validate a parsed ``servo_calibration.yaml`` tree against :data:`CALIBRATION_SCHEMA` (degrees on disk,
    radians inside)."""
    v = CALIBRATION_SCHEMA.read(tree)
    joints = []
    for name in JOINT_NAMES:
        key = "joints.%s." % name
        rms = v[key + "feedback_rms_deg"]
        joints.append(JointCalibration(
            name=name,
            neutral_angle_rad=math.radians(v[key + "neutral_angle_deg"]),
            neutral_us=v[key + "neutral_us"],
            direction=v[key + "direction"],
            us_per_rad=v[key + "us_per_deg"] * 180.0 / math.pi,
            feedback_slope=math.radians(v[key + "feedback_deg_per_v"]),
            feedback_offset=math.radians(v[key + "feedback_offset_deg"]),
            feedback_fitted=v[key + "feedback_fitted"],
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
#   [estimate] neutral_us and direction until calibrated: the servo horn zero offsets are not in the paper.
# Feedback map: angle_deg = feedback_deg_per_v * volts + feedback_offset_deg
#   [estimate] unless feedback_fitted is true: assumes the feedback potentiometer reads 0.5 V .. 2.9 V
#   over the travel. Calibrate both against the reference poses (docs/on_the_robot.md):
#   python -m quadruped_control.bringup.calibrate  (rewrites this file; a servo built wrong is reported).
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


__all__ = ["CALIBRATION_SCHEMA", "JointCalibration", "ServoCalibration", "servo_calibration_from_dict",
           "load_servo_calibration", "calibration_to_yaml", "save_servo_calibration"]
