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

from quadruped_common.config import ParameterError, load_config
from quadruped_common.robot import (LEGS, MIRROR_DIAG, ROBOT_SCHEMA, JointLimits, joint_limits_from_dict,
                                    servo_no_load_speed_from_dict)


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
    """Validate a parsed ``robot.yaml`` mapping against :data:`~quadruped_common.robot.ROBOT_SCHEMA` and build
    :class:`RobotParams`."""
    v = ROBOT_SCHEMA.read(tree)
    five_bar = FiveBar(*(v["five_bar." + name] for name in ("a1", "a2", "a3", "a4", "c")))
    # The paper's FK (eq. fk_EFG) and IK exploit the symmetric mechanism a1 = a2, a3 = a4.
    if not (math.isclose(five_bar.a1, five_bar.a2) and math.isclose(five_bar.a3, five_bar.a4)):
        raise ParameterError("the paper's five-bar kinematics need a1 == a2 and a3 == a4, got %s" % (five_bar,))
    dims = np.array(v["body.dimensions"])
    imu_mount = np.array(v["imu.mount_xyz"])
    if np.any(np.abs(imu_mount) > 0.5 * dims):
        raise ParameterError("parameter 'imu.mount_xyz' %s lies outside the body (half extents %s)"
                             % (imu_mount.tolist(), (0.5 * dims).tolist()))
    return RobotParams(
        mass=v["body.mass"],
        inertia=np.diag(v["body.inertia_diag"]),
        body_dimensions=dims,
        rho=v["fluid.density"],
        beta=v["fluid.viscosity"],
        gravity=v["fluid.gravity"],
        paw_diameter=v["paw.diameter"],
        drag_coefficient=v["paw.drag_coefficient"],
        paw_mass=v["paw.mass"],
        paw_volume=v["paw.volume"],
        five_bar=five_bar,
        l_y=v["hip.l_y"],
        l_z=v["hip.l_z"],
        leg_origins={leg: np.array(v["leg_origins.%d" % leg]) for leg in LEGS},
        joint_limits=joint_limits_from_dict(tree),
        nominal_foot_leg=np.array(v["nominal_foot_leg"]),
        servo_stall_torque=v["servo.stall_torque"],
        servo_no_load_speed=servo_no_load_speed_from_dict(tree),
        imu_mount_xyz=imu_mount,
    )


def load_robot_params(path: Optional[str] = None) -> RobotParams:
    """Load and validate ``robot.yaml`` (default: the package's ``config/robot.yaml``)."""
    return load_config(path, "robot.yaml", robot_params_from_dict)

