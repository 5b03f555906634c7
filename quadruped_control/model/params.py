"""Typed, validated robot model parameters loaded from ``config/robot.yaml``.

Every quantity of the paper's model (section "Mathematical Modeling") that is a number lives here:
five-bar link lengths (eq. fk_EFG), hip offsets l_y, l_z (eq. fk_T), leg-frame origins o_i and
mirroring matrices M_i (eq. M_legs, ee_body), paw drag constant k = 1/2 rho C_D A (eq. drag),
paw buoyancy (eq. buoy_force), body mass and inertia (eq. trans, rot, inertia_box).

Loading never returns a half-valid object: a missing key or an out-of-range value raises
:class:`ParameterError` naming the file, the key and the reason (the strict loader of
:mod:`quadruped_common.config`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional

import numpy as np

from quadruped_common.config import ParameterError, check_keys, load_config, lookup, number, vector
from quadruped_common.robot import LEGS, MIRROR_DIAG, JointLimits, joint_limits_from_dict, servo_no_load_speed_from_dict


def _number(tree: Mapping[str, Any], dotted: str, low: float = -math.inf, high: float = math.inf,
            low_open: bool = False) -> float:
    return number(lookup(tree, dotted), dotted, low, high, low_open=low_open)


def _vector(tree: Mapping[str, Any], dotted: str, length: int, low: float = -math.inf,
            high: float = math.inf) -> np.ndarray:
    return np.array(vector(lookup(tree, dotted), dotted, length, low, high))


@dataclass(frozen=True)
class FiveBar:
    """Planar five-bar linkage of one leg (Fig. 3b): actuated links a1, a2, passive a3, a4, motor spacing c."""

    a1: float
    a2: float
    a3: float
    a4: float
    c: float


@dataclass(frozen=True)
class RobotParams:
    """All parameters of the paper's robot model. Build with :func:`load_robot_params`.

    Attributes use the paper's symbols: ``m``, ``inertia`` (I), ``rho``, ``beta`` (viscosity),
    ``paw_mass`` (m_s), ``paw_volume`` (V_s), ``l_y``, ``l_z``, ``leg_origins[i]`` (o_i^B),
    ``mirror[i]`` (M_i).
    """

    mass: float
    inertia: np.ndarray  # 3x3, body frame, principal axes
    body_dimensions: np.ndarray
    rho: float
    beta: float
    gravity: float
    paw_diameter: float
    drag_coefficient: float
    paw_mass: float
    paw_volume: float
    five_bar: FiveBar
    l_y: float
    l_z: float
    leg_origins: Dict[int, np.ndarray]
    joint_limits: JointLimits
    nominal_foot_leg: np.ndarray
    servo_stall_torque: float
    servo_no_load_speed: float  # rad/s
    imu_mount_xyz: np.ndarray  # m, origin of imu_link in base_link (axes aligned with base_link)
    mirror: Dict[int, np.ndarray] = field(default_factory=lambda: {
        leg: np.diag(diag) for leg, diag in MIRROR_DIAG.items()})

    @property
    def paw_area(self) -> float:
        """Cross-sectional area A of the spherical paw, m^2 (eq. drag)."""
        return math.pi * (0.5 * self.paw_diameter) ** 2

    @property
    def drag_constant(self) -> float:
        """k = 1/2 rho C_D A of eq. (force_leg), N s^2 / m^2."""
        return 0.5 * self.rho * self.drag_coefficient * self.paw_area

    @property
    def paw_net_buoyancy(self) -> float:
        """Net upward force on one submerged paw, g rho V_s - m_s g (eq. buoy_force), N."""
        return self.gravity * (self.rho * self.paw_volume - self.paw_mass)

    def nominal_foot_body(self, leg: int) -> np.ndarray:
        """Nominal foot position of ``leg`` in the body frame, o_i + M_i p_nominal (eq. ee_body)."""
        return self.leg_origins[leg] + self.mirror[leg] @ self.nominal_foot_leg


def robot_params_from_dict(tree: Mapping[str, Any]) -> RobotParams:
    """Validate a parsed ``robot.yaml`` mapping and build :class:`RobotParams`."""
    inertia_diag = _vector(tree, "body.inertia_diag", 3, -100.0, 100.0)  # kg m^2
    if np.any(inertia_diag <= 0.0):
        raise ParameterError("parameter 'body.inertia_diag' must be positive, got %s" % inertia_diag)
    ixx, iyy, izz = inertia_diag
    # The inertia-box model (eq. inertia_box) takes square roots of I_yy + I_zz - I_xx etc.: a
    # physical body satisfies the triangle inequality on its principal moments.
    if ixx > iyy + izz or iyy > izz + ixx or izz > ixx + iyy:
        raise ParameterError("parameter 'body.inertia_diag' %s violates the triangle inequality of "
                             "principal moments (no physical body has it)" % inertia_diag)
    dims = _vector(tree, "body.dimensions", 3, -5.0, 5.0)  # m
    if np.any(dims <= 0.0):
        raise ParameterError("parameter 'body.dimensions' must be positive, got %s" % dims)

    five_bar = FiveBar(
        a1=_number(tree, "five_bar.a1", 0.0, 1.0, low_open=True),
        a2=_number(tree, "five_bar.a2", 0.0, 1.0, low_open=True),
        a3=_number(tree, "five_bar.a3", 0.0, 1.0, low_open=True),
        a4=_number(tree, "five_bar.a4", 0.0, 1.0, low_open=True),
        c=_number(tree, "five_bar.c", 0.0, 1.0),
    )
    # The paper's FK (eq. fk_EFG) and IK exploit the symmetric mechanism a1 = a2, a3 = a4.
    if not (math.isclose(five_bar.a1, five_bar.a2) and math.isclose(five_bar.a3, five_bar.a4)):
        raise ParameterError("the paper's five-bar kinematics need a1 == a2 and a3 == a4, got %s" % (five_bar,))

    # Keys are the leg numbers as strings ("1".."4"; the strict loader refuses non-string keys).
    leg_keys = [str(leg) for leg in LEGS]
    origins_raw = check_keys(lookup(tree, "leg_origins"), "leg_origins", leg_keys, leg_keys)
    leg_origins = {leg: np.array(vector(origins_raw[str(leg)], "leg_origins.%d" % leg, 3, -2.0, 2.0)) for leg in LEGS}

    return RobotParams(
        mass=_number(tree, "body.mass", 0.0, 1000.0, low_open=True),
        inertia=np.diag(inertia_diag),
        body_dimensions=dims,
        rho=_number(tree, "fluid.density", 0.0, 2000.0, low_open=True),
        beta=_number(tree, "fluid.viscosity", 0.0, 1.0),
        gravity=_number(tree, "fluid.gravity", 0.0, 20.0),
        paw_diameter=_number(tree, "paw.diameter", 0.0, 1.0, low_open=True),
        drag_coefficient=_number(tree, "paw.drag_coefficient", 0.0, 10.0, low_open=True),
        paw_mass=_number(tree, "paw.mass", 0.0, 10.0),
        paw_volume=_number(tree, "paw.volume", 0.0, 0.01),
        five_bar=five_bar,
        l_y=_number(tree, "hip.l_y", -1.0, 1.0),
        l_z=_number(tree, "hip.l_z", 0.0, 1.0, low_open=True),
        leg_origins=leg_origins,
        joint_limits=joint_limits_from_dict(tree),
        nominal_foot_leg=_vector(tree, "nominal_foot_leg", 3, -1.0, 1.0),
        servo_stall_torque=_number(tree, "servo.stall_torque", 0.0, 100.0, low_open=True),
        servo_no_load_speed=servo_no_load_speed_from_dict(tree),
        imu_mount_xyz=_imu_mount(tree, dims),
    )


def _imu_mount(tree: Mapping[str, Any], dims: np.ndarray) -> np.ndarray:
    """``imu.mount_xyz``: where the IMU sits in base_link; it must lie inside the body's box."""
    xyz = _vector(tree, "imu.mount_xyz", 3)
    if np.any(np.abs(xyz) > 0.5 * dims):
        raise ParameterError("parameter 'imu.mount_xyz' %s lies outside the body (half extents %s)"
                             % (xyz.tolist(), (0.5 * dims).tolist()))
    return xyz


def load_robot_params(path: Optional[str] = None) -> RobotParams:
    """Load and validate ``robot.yaml`` (default: the package's ``config/robot.yaml``)."""
    return load_config(path, "robot.yaml", robot_params_from_dict)

