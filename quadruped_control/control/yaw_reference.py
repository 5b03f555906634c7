"""How an operator's attitude setpoint is referenced about the world vertical: the yaw reference.

The paper's controller (section "Attitude Controller Design") tracks a desired attitude R_d in the world
frame (ENU, so yaw is the magnetic heading): its experiments regulated yaw to zero from wherever the robot
started. A robot hanging on its rope, commanded yaw 0, first turns to face east and winds its tether. A
setpoint (a rotation R_s, or roll, pitch, yaw) is therefore read in one of three yaw references:

- ``relative``: R_s is given in the frame turned about the world vertical by the heading psi_0 measured at
  arming (REP-103 yaw of the IMU's attitude, re-captured at every arm): R_d = Rz(psi_0) R_s, so roll 30,
  pitch 0, yaw 0 rolls the robot by 30 degrees where it faces;
- ``absolute``: R_d = R_s in world ENU (the paper's; yaw = magnetic heading);
- ``tilt``: only the tilt of R_s is tracked, its yaw is not controlled at all: each step R_d is the rotation
  with R_s's tilt closest to the measured attitude (:func:`tilt_setpoint`), whose orientation error eq.
  (error) has no component about the world vertical, and the controller removes that component from its
  integral and torque (:meth:`~quadruped_control.control.controller.AttitudeController.set_setpoint`,
  ``yaw_free``): no torque about the vertical is demanded from the allocation eq. (foot_speed), (foot_vel).

:class:`YawReference` holds the operator's latest setpoint, its mode and psi_0; :meth:`YawReference.world`
gives the controller's input. Pure Python, no ROS; the supervisor owns one (docs/controller.md derives the
tilt setpoint).
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional, Tuple

import numpy as np

from quadruped_common.so3 import rot_to_rpy, rot_z
from quadruped_common.vec3 import Mat3, Vec3, add, dot, row, scale, sub

__all__ = ["YAW_REFERENCES", "WorldSetpoint", "YawReference", "heading", "mode_of_frame", "reject",
           "tilt_setpoint", "world_setpoint"]

#: The yaw references, the robot's default first.
YAW_REFERENCES: Tuple[str, ...] = ("relative", "absolute", "tilt")


class WorldSetpoint(NamedTuple):
    """The controller's input: ``R_d`` in world ENU and ``yaw_free`` (tilt only: R_d's yaw is not tracked)."""

    R_d: np.ndarray
    yaw_free: bool


def heading(R: np.ndarray) -> float:
    """The heading of attitude R (body -> world ENU): its REP-103 yaw, rad (0 at gimbal lock)."""
    return rot_to_rpy(R)[2]


def mode_of_frame(frame_id: str) -> Optional[str]:
    """The yaw reference a setpoint message names in its header.frame_id: one of :data:`YAW_REFERENCES`, or
    None for an empty frame_id (the node's default); ValueError for any other."""
    name = frame_id.strip().lstrip("/")
    if not name:
        return None
    if name not in YAW_REFERENCES:
        raise ValueError("frame_id %r names no yaw reference: leave it empty (the node's ~yaw_reference) or give "
                         "one of %s" % (frame_id, ", ".join(YAW_REFERENCES)))
    return name


def reject(v: Vec3, axis: Vec3) -> Vec3:
    """v without its component along the unit vector ``axis``: v - (v . axis) axis."""
    return sub(v, scale(dot(v, axis), axis))


def tilt_setpoint(R_s: Mat3, R: Mat3) -> Mat3:
    """The rotation Rz(psi) R_s with R_s's tilt closest to the measured attitude R, psi maximising tr(R_d^T R)
    (the smallest geodesic angle of eq. (error)): with M = R R_s^T, tr(Rz(psi)^T M) = cos psi (M_xx + M_yy) +
    sin psi (M_yx - M_xy) + M_zz, so psi = atan2(M_yx - M_xy, M_xx + M_yy). At that psi the derivative
    e_z . vee(R R_d^T - R_d R^T) = 2 e_z . (R e_R) vanishes: e_R of eq. (error) has no component about the world
    vertical. psi = 0 where the trace does not depend on psi (tilt errors near 180 degrees)."""
    r0, r1 = row(R, 0), row(R, 1)
    s0, s1 = row(R_s, 0), row(R_s, 1)
    psi = math.atan2(dot(r1, s0) - dot(r0, s1), dot(r0, s0) + dot(r1, s1))
    c, s = math.cos(psi), math.sin(psi)
    x = sub(scale(c, s0), scale(s, s1))
    y = add(scale(s, s0), scale(c, s1))
    return Mat3(x[0], x[1], x[2], y[0], y[1], y[2], R_s.zx, R_s.zy, R_s.zz)


def world_setpoint(R_s: np.ndarray, mode: str, psi_0: Optional[float]) -> WorldSetpoint:
    """The controller's input for setpoint ``R_s`` in yaw reference ``mode``: absolute R_s; relative
    Rz(psi_0) R_s (R_s itself while psi_0 is None: not armed yet); tilt R_s, ``yaw_free``."""
    if mode == "relative" and psi_0 is not None:
        return WorldSetpoint(rot_z(psi_0) @ R_s, False)
    return WorldSetpoint(R_s, mode == "tilt")


class YawReference:
    """The operator's setpoint ``R_s`` (3x3, as given), its ``mode`` (:data:`YAW_REFERENCES`) and ``psi_0``, the
    heading captured at arming (None before the first: a relative setpoint then reads as absolute).

    ``default``: the mode of a setpoint given without one; the initial setpoint ``R_s`` (identity by default)
    is absolute: a world R_d the controller already had. ValueError for an unknown mode.
    """

    def __init__(self, default: str = YAW_REFERENCES[0], R_s: Optional[np.ndarray] = None) -> None:
        self.default = self.resolve(default)
        self.R_s = np.eye(3) if R_s is None else np.array(R_s, dtype=float)
        self.mode = "absolute"
        self.psi_0: Optional[float] = None

    def resolve(self, mode: Optional[str]) -> str:
        """``mode``, or the default for None; ValueError unless one of :data:`YAW_REFERENCES`."""
        if mode is None:
            return self.default
        if mode not in YAW_REFERENCES:
            raise ValueError("yaw reference must be one of %s, got %r" % (", ".join(YAW_REFERENCES), mode))
        return mode

    def world(self) -> WorldSetpoint:
        """The controller's input for the setpoint held (:func:`world_setpoint`)."""
        return world_setpoint(self.R_s, self.mode, self.psi_0)
