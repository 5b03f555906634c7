"""A robot built wrong: hardware faults the configuration does not know, and the robot they make.

The stack believes ``config/hardware.yaml`` (which channel drives and reads which joint) and
``config/servo_calibration.yaml`` (how a pulse and a feedback voltage map to a joint angle). A real robot may
differ; :class:`HardwareFaults` declares how, and :class:`BuiltRobot` is that robot's physics of wires and
mounts, for the simulated robot (``sim_node ~hardware_faults``) and the offline rigs of calibration and the
pre-dive check. None by default. The faults (YAML, a file or one inline flow mapping)::

    reversed: [leg2_hip]                         # servo mounted the other way round
    horn_offset_deg: {leg1_motor1: 14.4}         # horn one spline off: the joint sits this far from its zero
    swapped_pwm: [[leg1_hip, leg3_hip]]          # their servos' PWM cables on each other's channels
    swapped_feedback: [[leg1_motor1, leg2_motor1]]  # their feedback wires on each other's ADC inputs
    stuck_feedback_v: {leg4_motor2: 1.2}         # the ADC input reads this constant voltage
    imu_mount_rpy_deg: [0.0, 0.0, 90.0]          # the IMU's real mount relative to the one configured
    servo_reversed: [leg3_motor2]                # the servo itself turns the other way (its feedback with it)
    servo_stuck: [leg1_hip]                      # the servo's shaft does not move (stalled, seized)
    servo_speed_scale: {leg2_motor1: 0.5}        # the servo reaches this fraction of its speed (worn, wet)

The physics: a servo's shaft turns by u = (pulse - neutral_us) / us_per_rad from its centre, and its feedback
potentiometer sits on the shaft, so it reads the volts the calibration gives for the angle
neutral + direction u. The joint turns by direction u (minus u when reversed) plus the horn offset. So a
reversed servo or an offset horn looks right to feedback fitted against the command; only a reference the
robot's geometry gives (docs/on_the_robot.md) shows it. The servo faults are the servo's own: a servo_reversed
shaft turns by minus u, a stuck one stays where it is, a slowed one follows at its fraction of the speed; the
feedback, on the shaft, sees each, so the tracking watch (quadruped_control/control/servo_watch.py) can.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, check_keys, load_yaml, number, parse_yaml, string, vector
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import quat_multiply, rot_to_quat, rpy_to_rot

__all__ = ["BuiltRobot", "HardwareFaults", "hardware_faults_from_dict", "load_hardware_faults"]

KINDS = ("reversed", "horn_offset_deg", "swapped_pwm", "swapped_feedback", "stuck_feedback_v", "imu_mount_rpy_deg",
         "servo_reversed", "servo_stuck", "servo_speed_scale")

Pair = Tuple[str, str]


@dataclass(frozen=True)
class HardwareFaults:
    """How the robot differs from its configuration (module docstring); the default: not at all."""

    reversed: Tuple[str, ...] = ()
    horn_offset_deg: Tuple[Tuple[str, float], ...] = ()
    swapped_pwm: Tuple[Pair, ...] = ()
    swapped_feedback: Tuple[Pair, ...] = ()
    stuck_feedback_v: Tuple[Tuple[str, float], ...] = ()
    imu_mount_rpy_deg: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    servo_reversed: Tuple[str, ...] = ()
    servo_stuck: Tuple[str, ...] = ()
    servo_speed_scale: Tuple[Tuple[str, float], ...] = ()

    def __bool__(self) -> bool:
        return self != HardwareFaults()

    def describe(self) -> List[str]:
        """One line per fault, e.g. ``reversed servo leg2_hip``."""
        lines = ["reversed servo %s" % name for name in self.reversed]
        lines += ["horn of %s off by %+.1f deg" % item for item in self.horn_offset_deg]
        lines += ["PWM cables of %s and %s swapped" % pair for pair in self.swapped_pwm]
        lines += ["feedback wires of %s and %s swapped" % pair for pair in self.swapped_feedback]
        lines += ["feedback ADC of %s stuck at %.2f V" % item for item in self.stuck_feedback_v]
        if any(self.imu_mount_rpy_deg):
            lines.append("IMU mounted rotated by rpy %s deg" % (list(self.imu_mount_rpy_deg),))
        lines += ["servo %s turns the other way" % name for name in self.servo_reversed]
        lines += ["servo %s stuck" % name for name in self.servo_stuck]
        lines += ["servo %s at %.0f %% of its speed" % (name, 100.0 * scale) for name, scale in self.servo_speed_scale]
        return lines


def _joint(value: Any, key: str) -> str:
    return string(value, key, JOINT_NAMES, what="hardware fault")


def _pairs(value: Any, key: str) -> Tuple[Pair, ...]:
    if not isinstance(value, list):
        raise ParameterError("hardware fault '%s' must be a list of joint pairs, got %r" % (key, value))
    pairs, seen = [], set()
    for i, pair in enumerate(value):
        if not (isinstance(pair, list) and len(pair) == 2):
            raise ParameterError("hardware fault '%s[%d]' must be two joint names, got %r" % (key, i, pair))
        a, b = _joint(pair[0], "%s[%d]" % (key, i)), _joint(pair[1], "%s[%d]" % (key, i))
        if a == b or {a, b} & seen:
            raise ParameterError("hardware fault '%s[%d]': %s and %s must be two joints in no other pair"
                                 % (key, i, a, b))
        seen |= {a, b}
        pairs.append((a, b))
    return tuple(pairs)


def _per_joint(value: Any, key: str, low: float, high: float) -> Tuple[Tuple[str, float], ...]:
    tree = check_keys(value, key, JOINT_NAMES, what="hardware fault")
    return tuple((name, number(tree[name], "%s.%s" % (key, name), low, high, what="hardware fault"))
                 for name in JOINT_NAMES if name in tree)


def _joints(tree: Mapping[str, Any], key: str) -> Tuple[str, ...]:
    value = tree.get(key, [])
    if not isinstance(value, list):
        raise ParameterError("hardware fault '%s' must be a list of joint names, got %r" % (key, value))
    return tuple(_joint(v, "%s[%d]" % (key, i)) for i, v in enumerate(value))


def hardware_faults_from_dict(tree: Optional[Mapping[str, Any]]) -> HardwareFaults:
    """Checked faults from a parsed mapping (None or empty: none); ParameterError naming the key."""
    tree = check_keys({} if tree is None else tree, "", KINDS, what="hardware fault")
    rpy = tuple(vector(tree.get("imu_mount_rpy_deg", [0.0, 0.0, 0.0]), "imu_mount_rpy_deg", 3, -180.0, 180.0,
                       what="hardware fault"))
    return HardwareFaults(
        reversed=_joints(tree, "reversed"),
        horn_offset_deg=_per_joint(tree.get("horn_offset_deg", {}), "horn_offset_deg", -90.0, 90.0),
        swapped_pwm=_pairs(tree.get("swapped_pwm", []), "swapped_pwm"),
        swapped_feedback=_pairs(tree.get("swapped_feedback", []), "swapped_feedback"),
        stuck_feedback_v=_per_joint(tree.get("stuck_feedback_v", {}), "stuck_feedback_v", -0.3, 5.3),
        imu_mount_rpy_deg=(rpy[0], rpy[1], rpy[2]),
        servo_reversed=_joints(tree, "servo_reversed"),
        servo_stuck=_joints(tree, "servo_stuck"),
        servo_speed_scale=_per_joint(tree.get("servo_speed_scale", {}), "servo_speed_scale", 0.05, 1.0),
    )


def load_hardware_faults(spec: Optional[str]) -> HardwareFaults:
    """Faults from ``spec``: empty/None (none), an inline YAML flow mapping (starts with ``{``) or a file."""
    spec = (spec or "").strip()
    if not spec:
        return HardwareFaults()
    try:
        tree = parse_yaml(spec) if spec.startswith("{") else load_yaml(spec)
        return hardware_faults_from_dict(tree)
    except ParameterError as exc:
        raise ParameterError("hardware faults %s: %s" % ("(inline)" if spec.startswith("{") else spec, exc)) from None


def _permutation(pairs: Sequence[Pair]) -> np.ndarray:
    """Index map: ``p[j]`` is the joint whose wire sits where joint j's should."""
    p = np.arange(len(JOINT_NAMES))
    for a, b in pairs:
        i, k = JOINT_NAMES.index(a), JOINT_NAMES.index(b)
        p[i], p[k] = k, i
    return p


class BuiltRobot:
    """The robot as built, seen through its wires (module docstring). ``calibration`` is the maps of the
    servos as bought (the configured ones); ``faults`` how the robot differs."""

    def __init__(self, calibration: Any, faults: HardwareFaults = HardwareFaults()) -> None:
        self.calibration = calibration
        self.faults = faults
        joints = calibration.joints
        self._neutral_angle = np.array([j.neutral_angle_rad for j in joints])
        self._neutral_us = np.array([j.neutral_us for j in joints])
        self._gain = np.array([j.direction * j.us_per_rad for j in joints])  # us per rad of shaft, signed
        self._mount = np.array([-1.0 if name in faults.reversed else 1.0 for name in JOINT_NAMES])
        self._turn = np.array([-1.0 if name in faults.servo_reversed else 1.0 for name in JOINT_NAMES])
        self._stuck_servo = np.array([name in faults.servo_stuck for name in JOINT_NAMES])
        scales = dict(faults.servo_speed_scale)
        #: each servo's fraction of its speed (1: as bought)
        self.speed_scale = np.array([scales.get(name, 1.0) for name in JOINT_NAMES])
        offsets = dict(faults.horn_offset_deg)
        self._horn = np.radians([offsets.get(name, 0.0) for name in JOINT_NAMES])
        self._pwm = _permutation(faults.swapped_pwm)
        self._feedback = _permutation(faults.swapped_feedback)
        stuck = dict(faults.stuck_feedback_v)
        self._stuck = np.array([stuck.get(name, math.nan) for name in JOINT_NAMES])
        self.imu_mount = rpy_to_rot(*np.radians(faults.imu_mount_rpy_deg))

    def joint_targets(self, joint_pulses: Sequence[float]) -> np.ndarray:
        """The angle each joint's servo turns to (rad) when the chip sends ``joint_pulses`` (us) on the channels
        the configuration gives the joints (JOINT_NAMES order); NaN where its servo gets no pulse (limp) or is
        stuck (either way it stays where it is)."""
        pulses = np.asarray(joint_pulses, dtype=float)[self._pwm]
        shaft = self._neutral_angle + self._turn * (pulses - self._neutral_us) / self._gain
        angles = self._neutral_angle + self._mount * (shaft - self._neutral_angle) + self._horn
        return np.where((pulses > 0.0) & ~self._stuck_servo, angles, math.nan)

    def feedback_volts(self, joint_angles: Sequence[float]) -> np.ndarray:
        """What each joint's configured ADC input reads (V) with the joints at ``joint_angles`` (rad)."""
        q = np.asarray(joint_angles, dtype=float)
        shaft = self._neutral_angle + self._mount * (q - self._horn - self._neutral_angle)
        volts = self.calibration.angles_to_volts(shaft)[self._feedback]
        return np.where(np.isnan(self._stuck), volts, self._stuck)

    def imu_output(self, quaternion_xyzw: Sequence[float], omega_body: Sequence[float],
                   specific_force_body: Sequence[float]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the IMU reports, in the axes the stack takes for base_link's, given the body's attitude
        (quaternion x, y, z, w), rate and specific force: rotated by its real mount."""
        mount_q = rot_to_quat(self.imu_mount)
        return (quat_multiply(quaternion_xyzw, mount_q), self.imu_mount.T @ np.asarray(omega_body, dtype=float),
                self.imu_mount.T @ np.asarray(specific_force_body, dtype=float))

