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

from quadruped_common.config import ParameterError, load_config, lookup
from quadruped_common.schema import Param, Schema

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


def _limits_span(value: Any) -> Optional[str]:
    low, high = value
    if not low < high:
        return "needs low < high"
    return None if high - low <= 360.0 else "spans more than 360 degrees"


def _principal_moments(value: Any) -> Optional[str]:
    # The inertia-box model (eq. inertia_box) takes square roots of I_yy + I_zz - I_xx etc.
    ixx, iyy, izz = value
    if ixx > iyy + izz or iyy > izz + ixx or izz > ixx + iyy:
        return "violates the triangle inequality of principal moments (no physical body has it)"
    return None


_LINK = dict(low=0.0, high=1.0, low_open=True, source="paper")
#: ``config/robot.yaml``: the paper's model (section "Mathematical Modeling"), one row per value.
ROBOT_SCHEMA = Schema("robot.yaml", (
    Param("body.mass", "kg", "body mass m", 0.0, 1000.0, low_open=True, source="paper"),
    Param("body.dimensions", "m", "body extent along x (forward), y (left), z (up)", 0.0, 5.0, kind="vector",
          length=3, low_open=True, source="paper"),
    Param("body.inertia_diag", "kg m^2", "principal moments of inertia I (eq. inertia_box); a physical body's obey "
          "the triangle inequality", 0.0, 100.0, kind="vector", length=3, low_open=True, source="estimate",
          check=_principal_moments),
    Param("fluid.density", "kg/m^3", "water density rho", 0.0, 2000.0, low_open=True, source="paper"),
    Param("fluid.viscosity", "Pa s", "dynamic viscosity beta", 0.0, 1.0, source="estimate"),
    Param("fluid.gravity", "m/s^2", "gravitational acceleration g", 0.0, 20.0),
    Param("paw.diameter", "m", "spherical paw diameter (area A of eq. drag)", **_LINK),
    Param("paw.drag_coefficient", "", "paw drag coefficient C_D (eq. drag)", 0.0, 10.0, low_open=True,
          source="paper"),
    Param("paw.mass", "kg", "flooded paw's shell mass m_s (eq. buoy_force)", 0.0, 10.0, source="estimate"),
    Param("paw.volume", "m^3", "flooded paw's shell volume V_s (eq. buoy_force)", 0.0, 0.01, source="estimate"),
    Param("five_bar.a1", "m", "actuated link of motor 1 (eq. fk_EFG)", **_LINK),
    Param("five_bar.a2", "m", "actuated link of motor 2 (= a1)", **_LINK),
    Param("five_bar.a3", "m", "passive link on motor 1's side", **_LINK),
    Param("five_bar.a4", "m", "passive link on motor 2's side (= a3)", **_LINK),
    Param("five_bar.c", "m", "distance between the two lateral motor axes", 0.0, 1.0, source="paper"),
    Param("hip.l_y", "m", "five-bar plane origin along the leg's in-plane direction (eq. fk_T)", -1.0, 1.0,
          source="estimate"),
    Param("hip.l_z", "m", "five-bar plane's lateral distance from the hip axis (eq. fk_T)", 0.0, 1.0,
          low_open=True, source="estimate"),
    Param("leg_origins.<leg>", "m", "origin o_i of leg frame F_L,i in the body frame (eq. ee_body)", -2.0, 2.0,
          kind="vector", length=3, source="estimate"),
    Param("joint_limits_deg.theta1", "deg", "servo range [low, high] of theta1 (five-bar motor 1)", -360.0, 360.0,
          kind="vector", length=2, source="estimate", check=_limits_span),
    Param("joint_limits_deg.theta2", "deg", "servo range of theta2 (five-bar motor 2)", -360.0, 360.0,
          kind="vector", length=2, source="estimate", check=_limits_span),
    Param("joint_limits_deg.theta3", "deg", "servo range of theta3 (hip)", -360.0, 360.0, kind="vector", length=2,
          source="estimate", check=_limits_span),
    Param("nominal_foot_leg", "m", "nominal foot point in the leg frame; every power stroke starts here "
          "(eq. foot_integration)", -1.0, 1.0, kind="vector", length=3, source="estimate"),
    Param("servo.stall_torque", "N m", "IB53BHU stall torque", 0.0, 100.0, low_open=True, source="paper"),
    Param("servo.no_load_speed_rpm", "rpm", "IB53BHU no-load speed", 0.0, 10000.0, low_open=True, source="paper"),
    Param("imu.mount_xyz", "m", "imu_link's origin in base_link (inside the body; rviz and TF only)",
          kind="vector", length=3, source="estimate"),
), names={"leg": tuple(str(leg) for leg in LEGS)})


def _robot_value(tree: Mapping[str, Any], key: str) -> Any:
    return ROBOT_SCHEMA[key].read(lookup(tree, key), key)


def joint_limits_from_dict(tree: Mapping[str, Any]) -> JointLimits:
    """``joint_limits_deg`` of a parsed ``robot.yaml`` (:data:`ROBOT_SCHEMA`) in radians; :class:`ParameterError`
    naming the key otherwise."""
    limits = {}
    for name in ("theta1", "theta2", "theta3"):
        low, high = _robot_value(tree, "joint_limits_deg." + name)
        limits[name] = (math.radians(low), math.radians(high))
    return JointLimits(**limits)


def load_joint_limits(path: Optional[str] = None) -> JointLimits:
    """The joint limits of ``robot.yaml`` (default: the package's ``config/robot.yaml``)."""
    return load_config(path, "robot.yaml", joint_limits_from_dict)


def servo_no_load_speed_from_dict(tree: Mapping[str, Any]) -> float:
    """``servo.no_load_speed_rpm`` of a parsed ``robot.yaml`` in rad/s: the fastest a servo can turn (the
    simulated servos' rate limit, and the drivers' bound on how far a joint can move between readings)."""
    rpm = _robot_value(tree, "servo.no_load_speed_rpm")
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
