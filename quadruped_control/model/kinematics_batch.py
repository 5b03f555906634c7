"""The leg kinematics of :mod:`quadruped_control.model.kinematics` vectorised over trials and legs.

The batched simulator (:mod:`quadruped_control.sim.batch`) steps many closed-loop trials at once; its
controller needs the leg inverse kinematics of eq. (ee_body) inverted, (ik_theta3), (ik_dists),
(ik_alphas), (ik_theta1245) for every foot target of every trial. Here it takes arrays of shape
(..., 4, 3) (any leading trial axes, then legs 1..4, then the three coordinates) and returns a validity
mask instead of raising: in a batch, one trial's unreachable target must not stop the others. (The
batched plants' forward kinematics is the per-trial function itself,
:func:`~quadruped_control.model.kinematics.leg_row`, in a compiled loop.)

This is the array form of :func:`~quadruped_control.model.kinematics.joint_angles_floats` (the robot's
per-step float path): the same formulas in the same order, with the numpy ufuncs for the ``math`` ones.
The tests compare them over the workspace, boundary included.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

from quadruped_common.robot import LEGS, MIRROR_DIAG
from quadruped_common.so3 import TWO_PI
from quadruped_control.model.kinematics import _ANGLE_TOL, _ROUND_TOL
from quadruped_control.model.params import RobotParams

__all__ = ["LegGeometry", "joint_angles_batch"]


@dataclass(frozen=True)
class LegGeometry:
    """The kinematic constants of the four legs as arrays that broadcast against (..., 4) per-leg values.

    ``origin`` o_i^B (4, 3) and ``mirror`` diag(M_i) (4, 3) of eq. (ee_body); the five-bar links a1..a4
    and motor spacing c; the hip offsets l_y, l_z; ``low``, ``high`` (3,) the servo ranges.
    """

    origin: np.ndarray
    mirror: np.ndarray
    a1: float
    a2: float
    a3: float
    a4: float
    c: float
    l_y: float
    l_z: float
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def from_params(cls, params: RobotParams) -> "LegGeometry":
        fb, limits = params.five_bar, params.joint_limits
        bounds = np.array([limits.theta1, limits.theta2, limits.theta3], dtype=float)
        return cls(origin=np.array([params.leg_origins[leg] for leg in LEGS], dtype=float),
                   mirror=np.array([MIRROR_DIAG[leg] for leg in LEGS], dtype=float),
                   a1=float(fb.a1), a2=float(fb.a2), a3=float(fb.a3), a4=float(fb.a4), c=float(fb.c),
                   l_y=float(params.l_y), l_z=float(params.l_z), low=bounds[:, 0].copy(), high=bounds[:, 1].copy())


def _wrap_up(angle: np.ndarray, low: float) -> np.ndarray:
    """``angle + 2 pi k`` with the smallest k that brings it to at least ``low`` - 1e-9 rad
    (:func:`~quadruped_control.model.kinematics.wrap_into_range`)."""
    return angle + np.ceil((low - _ANGLE_TOL - angle) / TWO_PI) * TWO_PI


def joint_angles_batch(r: np.ndarray, geometry: LegGeometry,
                       legs: Optional[Sequence[int]] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Joint angles (..., 4, 3) for body-frame foot targets ``r`` (..., 4, 3), and the mask (..., 4) of
    the targets the legs reach (servo ranges included). ``legs``: the leg indices (0-based) of the
    second-last axis when it holds only some legs, e.g. (0, 2) for legs 1 and 3 with ``r`` (..., 2, 3).

    Where the mask is False the angles are meaningless (finite); the float path raises
    :class:`~quadruped_control.model.kinematics.UnreachableError` there. The angles are NOT clamped into
    the servo ranges (the wrap may leave them 1e-9 rad outside, as the float path does).
    """
    g = geometry
    index = slice(None) if legs is None else list(legs)
    rel = g.mirror[index] * (r - g.origin[index])
    x_d, y_d, z_d = rel[..., 0], rel[..., 1], rel[..., 2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        radius = np.hypot(y_d, z_d)
        ok = (radius >= g.l_z) & np.isfinite(x_d + radius)
        # eq. (ik_theta3), wrapped into the hip servo range
        theta3 = np.arctan2(z_d, y_d) - np.arccos(np.minimum(g.l_z / np.where(ok, radius, 1.0), 1.0)) - 0.5 * math.pi
        theta3 = _wrap_up(theta3, g.low[2])
        ok &= theta3 <= g.high[2] + _ANGLE_TOL
        y_prime = y_d * np.cos(theta3) + z_d * np.sin(theta3) - g.l_y
        # eq. (ik_dists), (ik_alphas)
        d13 = np.hypot(x_d, y_prime)
        d24 = np.hypot(x_d - g.c, y_prime)
        ok &= (d13 >= _ROUND_TOL) & (d24 >= _ROUND_TOL)
        k1 = (d13 * d13 + g.a1 * g.a1 - g.a3 * g.a3) / (2.0 * g.a1 * d13)
        k2 = (d24 * d24 + g.a2 * g.a2 - g.a4 * g.a4) / (2.0 * g.a2 * d24)
        k4 = (d13 * d13 - g.a1 * g.a1 - g.a3 * g.a3) / (2.0 * g.a1 * g.a3)
        k5 = (d24 * d24 - g.a2 * g.a2 - g.a4 * g.a4) / (2.0 * g.a2 * g.a4)
        ok &= (np.abs(k1) <= 1.0) & (np.abs(k2) <= 1.0) & (np.abs(k4) <= 1.0 + _ROUND_TOL) \
            & (np.abs(k5) <= 1.0 + _ROUND_TOL)
        # eq. (ik_theta1245), wrapped into the servo ranges
        theta1 = np.arctan2(y_prime, x_d) - np.arccos(np.clip(k1, -1.0, 1.0))
        theta2 = np.arctan2(y_prime, x_d - g.c) + np.arccos(np.clip(k2, -1.0, 1.0))
        theta1 = _wrap_up(theta1, g.low[0])
        theta2 = _wrap_up(theta2, g.low[1])
        ok &= (theta1 <= g.high[0] + _ANGLE_TOL) & (theta2 <= g.high[1] + _ANGLE_TOL)
    angles = np.stack((theta1, theta2, theta3), axis=-1)
    return np.where(ok[..., None], angles, 0.0), ok
