"""The robot's numbering that every layer shares: legs, joint names and order, the legs' mirror table,
the servos' joint limits (paper "Underwater quadruped ...", section "Mathematical Modeling", eq. (M_legs))
and the leg pairs that stroke together (section "Power and Recovery Stroke Cycle"; the controller's
``pairs``, which the bag analysis needs to read a record's pair phases).

The drivers need the joint order (PWM channels, ADC map) and the joint limits (the calibration sweep);
the controller and the model need all of it. It lives here, below both, so that neither imports the
other for it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

from quadruped_common.config import ParameterError, load_config, lookup, number, vector

LEGS: Tuple[int, ...] = (1, 2, 3, 4)
"""Leg numbers as in the paper."""

#: Mirroring matrices M_i of eq. (M_legs): leg frame -> body frame orientation, per leg.
MIRROR_DIAG: Dict[int, Tuple[float, float, float]] = {
    1: (-1.0, 1.0, 1.0),
    2: (-1.0, -1.0, 1.0),
    3: (1.0, -1.0, 1.0),
    4: (1.0, 1.0, 1.0),
}

#: Servo / joint order used everywhere (PWM channels, ADC map, /joint_states, /servo_command):
#: leg 1..4, each (theta1, theta2, theta3) = (five-bar motor 1, five-bar motor 2, hip). Index of leg i,
#: joint j (1-based) is 3 * (i - 1) + (j - 1).
JOINT_NAMES: Tuple[str, ...] = tuple(
    "leg%d_%s" % (leg, joint) for leg in LEGS for joint in ("motor1", "motor2", "hip"))


def joint_index(leg: int, joint: int) -> int:
    """Index of joint ``joint`` (1: theta1, 2: theta2, 3: theta3) of ``leg`` in :data:`JOINT_NAMES`."""
    if leg not in LEGS or joint not in (1, 2, 3):
        raise ValueError("no joint %r of leg %r" % (joint, leg))
    return 3 * (leg - 1) + (joint - 1)


@dataclass(frozen=True)
class JointLimits:
    """Servo ranges [low, high] in radians for theta1, theta2 (five-bar) and theta3 (hip)."""

    theta1: Tuple[float, float]
    theta2: Tuple[float, float]
    theta3: Tuple[float, float]

    def as_array(self) -> np.ndarray:
        """3x2 array: rows theta1, theta2, theta3; columns low, high."""
        return np.array([self.theta1, self.theta2, self.theta3])


def joint_limits_from_dict(tree: Mapping[str, Any]) -> JointLimits:
    """``joint_limits_deg`` of a parsed ``robot.yaml``: each [low, high] in degrees, low < high, at most
    one turn; :class:`ParameterError` naming the key otherwise."""
    limits = {}
    for name in ("theta1", "theta2", "theta3"):
        key = "joint_limits_deg." + name
        low, high = vector(lookup(tree, key), key, 2, -360.0, 360.0)
        if not low < high:
            raise ParameterError("parameter '%s' needs low < high, got [%g, %g]" % (key, low, high))
        if high - low > 360.0:
            raise ParameterError("parameter '%s' spans more than 360 degrees" % key)
        limits[name] = (math.radians(low), math.radians(high))
    return JointLimits(**limits)


def load_joint_limits(path: Optional[str] = None) -> JointLimits:
    """The joint limits of ``robot.yaml`` (default: the package's ``config/robot.yaml``)."""
    return load_config(path, "robot.yaml", joint_limits_from_dict)


def servo_no_load_speed_from_dict(tree: Mapping[str, Any]) -> float:
    """``servo.no_load_speed_rpm`` of a parsed ``robot.yaml`` in rad/s: the fastest a servo can turn (the
    simulated servos' rate limit, and the drivers' bound on how far a joint can move between readings)."""
    rpm = number(lookup(tree, "servo.no_load_speed_rpm"), "servo.no_load_speed_rpm", 0.0, 10000.0, low_open=True)
    return rpm * 2.0 * math.pi / 60.0


def load_servo_no_load_speed(path: Optional[str] = None) -> float:
    """The servos' no-load speed (rad/s) of ``robot.yaml`` (default: the package's ``config/robot.yaml``)."""
    return load_config(path, "robot.yaml", servo_no_load_speed_from_dict)


#: Two pairs of leg numbers; the controller's default (config/controller.yaml ``pairs``): the paper's intent,
#: diagonal pairs, under its mirroring matrices (see quadruped_control.control.controller_config).
LegPairs = Tuple[Tuple[int, int], Tuple[int, int]]
DEFAULT_LEG_PAIRS: LegPairs = ((1, 3), (2, 4))


def leg_pairs(pairs: Any) -> LegPairs:
    """``pairs`` checked to be two pairs of leg numbers forming a partition of legs 1..4, as tuples;
    :class:`ParameterError` otherwise."""
    try:
        as_tuples = tuple(tuple(pair) for pair in pairs)
    except TypeError:
        raise ParameterError("pairs must be two pairs of leg numbers, e.g. [[1, 3], [2, 4]], got %r"
                             % (pairs,)) from None
    if len(as_tuples) != 2 or any(len(pair) != 2 for pair in as_tuples):
        raise ParameterError("pairs must be two pairs of leg numbers, e.g. [[1, 3], [2, 4]], got %r" % (pairs,))
    legs = []
    for pair in as_tuples:
        for leg in pair:
            if isinstance(leg, bool) or not isinstance(leg, int):
                raise ParameterError("pairs must contain integer leg numbers, got %r" % (pairs,))
            legs.append(int(leg))
    if sorted(legs) != list(LEGS):
        raise ParameterError("pairs %r must be a partition of the legs %s (each leg in exactly one pair)"
                             % (pairs, LEGS))
    first, second = as_tuples
    return (int(first[0]), int(first[1])), (int(second[0]), int(second[1]))


def load_leg_pairs(path: Optional[str] = None) -> LegPairs:
    """The leg pairs of ``controller.yaml`` (default: the package's ``config/controller.yaml``), or
    :data:`DEFAULT_LEG_PAIRS` where it names none."""
    return load_config(path, "controller.yaml", lambda tree: leg_pairs(tree.get("pairs", DEFAULT_LEG_PAIRS)))
