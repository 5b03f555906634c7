"""The operator's view of the attitude in degrees: measured and commanded roll, pitch, yaw and their difference.

Angles are REP-103 (R = Rz(yaw) Ry(pitch) Rx(roll), :func:`quadruped_common.so3.rot_to_rpy`) of rotations
world ENU <- body FLU: the measured attitude R and the controller's setpoint R_d, which is always the world one
(a relative setpoint's yaw is world yaw = heading at arming + the yaw the operator gave,
:mod:`quadruped_control.control.yaw_reference`). The error is setpoint - measured per angle, wrapped to
[-180, 180): what is left to turn, for plots and the operator's eye. The controller itself acts on the geodesic
error e_R (docs/controller.md), which these differences only approximate (not at all near pitch +-90 deg, where
roll and yaw lose their meaning). Pure Python, no ROS: the controller node publishes it (telemetry/*_rpy_deg).
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional, Tuple

import numpy as np

from quadruped_common.so3 import rot_to_rpy

__all__ = ["AttitudeDegrees", "RPY", "attitude_degrees", "rpy_degrees", "wrap_degrees"]

#: (roll, pitch, yaw), degrees
RPY = Tuple[float, float, float]
_UNKNOWN: RPY = (math.nan, math.nan, math.nan)


class AttitudeDegrees(NamedTuple):
    """Measured ``rpy``, commanded ``setpoint`` and ``error`` = setpoint - measured (wrapped), each (roll, pitch,
    yaw) in degrees; NaN where the attitude is not known yet."""

    rpy: RPY
    setpoint: RPY
    error: RPY


def wrap_degrees(angle: float) -> float:
    """``angle`` (deg) wrapped to [-180, 180); NaN stays NaN."""
    return (float(angle) + 180.0) % 360.0 - 180.0


def rpy_degrees(R: np.ndarray) -> RPY:
    """REP-103 (roll, pitch, yaw) of rotation R in degrees."""
    roll, pitch, yaw = rot_to_rpy(R)
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


def attitude_degrees(R: Optional[np.ndarray], R_d: np.ndarray) -> AttitudeDegrees:
    """The degrees of measured attitude R (None: no IMU sample yet, measured and error NaN) and setpoint R_d."""
    setpoint = rpy_degrees(R_d)
    if R is None:
        return AttitudeDegrees(_UNKNOWN, setpoint, _UNKNOWN)
    rpy = rpy_degrees(R)
    return AttitudeDegrees(rpy, setpoint, (wrap_degrees(setpoint[0] - rpy[0]), wrap_degrees(setpoint[1] - rpy[1]),
                                           wrap_degrees(setpoint[2] - rpy[2])))
