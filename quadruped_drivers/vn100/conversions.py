"""Frame conversion between the VN-100's conventions and ROS REP-103 / REP-145 (pure functions).

VN-100 (UM001 Sec. 4.4.4-4.4.6): body frame B = FRD (x forward, y right, z down); the quaternion
(x, y, z, w; scalar last) is the attitude of FRD relative to the local NED frame, i.e. as a Hamilton
quaternion it rotates FRD vectors into NED: ``v_NED = R(q_vn) v_FRD`` (equivalently yaw-pitch-roll
3-2-1 with yaw about Down, so a heading of +90 deg faces East). Angular rate (rad/s) and acceleration
(m/s^2) are FRD components; the acceleration "includes gravity": it is the specific force the
accelerometer senses, about (0, 0, -9.81) for a level sensor at rest (support force along -z_FRD).

ROS: world ENU (REP-103), body FLU (``imu_link``: x forward, y left, z up). ``sensor_msgs/Imu``
orientation = attitude of FLU relative to ENU (rotates FLU vectors into ENU); angular velocity and
linear acceleration are FLU components; REP-145: the acceleration is the specific force too, so a
level upright IMU at rest reads about +9.81 on z.

The maths (all matrices are proper rotations; both axis swaps are their own inverses)::

    R_ENU_NED = [[0, 1, 0],      # E = N-E-D's y, N = its x, U = -D
                 [1, 0, 0],
                 [0, 0, -1]]     (rotation by pi about (1, 1, 0)/sqrt 2; q = (s, s, 0, 0), s = sqrt 1/2)
    R_FRD_FLU = diag(1, -1, -1)  (rotation by pi about x; q = (1, 0, 0, 0))

    R_ENU_FLU = R_ENU_NED @ R_NED_FRD @ R_FRD_FLU          (orientation, here in quaternion form)
    w_FLU     = R_FLU_FRD @ w_FRD = (wx, -wy, -wz)           (angular velocity)
    f_FLU     = R_FLU_FRD @ f_FRD = (fx, -fy, -fz)           (specific force: no sign change, both
                                                            conventions are "specific force")

Check: level, facing North: R_NED_FRD = I, R_ENU_FLU = R_ENU_NED @ R_FRD_FLU = Rz(+90 deg): the robot
faces ENU +y = North, i.e. ROS yaw = 90 deg - VN heading. Facing East (VN yaw +90 deg) gives ROS
yaw 0. The inverse :func:`ros_to_vn` applies the same matrices in the opposite order.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Tuple, Union

import numpy as np

# The plausibility check (and its limits) is shared with the controller's supervisor; re-exported here.
from quadruped_common.imu_plausibility import (ACCEL_RANGE_M_S2, DEFAULT_LIMITS, GYRO_RANGE_RAD_S,  # noqa: F401
                                               UNIT_TOLERANCE, ImplausibleSample, SensorLimits,
                                               bounded_vector3, check_sample, unit_quaternion)
from quadruped_common.so3 import quat_multiply

ArrayLike = Union[Sequence[float], np.ndarray]

_S = math.sqrt(0.5)
#: R_ENU_NED as a quaternion (x, y, z, w) (its own inverse up to sign).
Q_ENU_NED = np.array([_S, _S, 0.0, 0.0])
#: R_FRD_FLU as a quaternion (x, y, z, w) (its own inverse up to sign).
Q_FRD_FLU = np.array([1.0, 0.0, 0.0, 0.0])
_FLIP_YZ = np.array([1.0, -1.0, -1.0])

@dataclass
class ImuReading:
    """An IMU sample in ROS frames (REP-103 / REP-145).

    ``orientation_xyzw``: attitude of the FLU body relative to ENU; ``angular_velocity``: FLU, rad/s;
    ``linear_acceleration``: FLU specific force, m/s^2 (+9.81 on z when level and upright).
    """

    orientation_xyzw: np.ndarray
    angular_velocity: np.ndarray
    linear_acceleration: np.ndarray


def _sandwich_matrix(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """4x4 matrix M with M @ q == left * q * right (Hamilton products are bilinear)."""
    return np.column_stack([quat_multiply(quat_multiply(left, e), right) for e in np.eye(4)])


_CONJ = np.array([-1.0, -1.0, -1.0, 1.0])
#: q_ENU_FLU = Q_ENU_NED * q_NED_FRD * Q_FRD_FLU as one matrix (a signed permutation).
_VN_TO_ROS = _sandwich_matrix(Q_ENU_NED, Q_FRD_FLU)
#: q_NED_FRD = Q_ENU_NED^-1 * q_ENU_FLU * Q_FRD_FLU^-1.
_ROS_TO_VN = _sandwich_matrix(Q_ENU_NED * _CONJ, Q_FRD_FLU * _CONJ)


def _canonical(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q)
    return -q if q[3] < 0.0 else q


def vn_to_ros(quaternion_xyzw: ArrayLike, angular_rate: ArrayLike, acceleration: ArrayLike,
              limits: SensorLimits = DEFAULT_LIMITS) -> ImuReading:
    """VN-100 (FRD body w.r.t. NED) -> ROS (FLU body w.r.t. ENU); see the module docstring.

    ``q_ENU_FLU = Q_ENU_NED * q_NED_FRD * Q_FRD_FLU`` (Hamilton products), rate and acceleration
    ``(x, -y, -z)``. Returns a quaternion with w >= 0. Every sample is checked against the sensor
    (``limits``) before it is converted: :class:`ImplausibleSample` (a ``ValueError``) for NaN/inf, a
    quaternion that is not unit length within ``limits.unit_tolerance``, or a rate or acceleration
    component beyond the sensor's range; ``ValueError`` for wrong shapes.
    """
    q_ned_frd, rate, accel = check_sample(quaternion_xyzw, angular_rate, acceleration, limits)
    q_enu_flu = _VN_TO_ROS @ q_ned_frd
    return ImuReading(orientation_xyzw=_canonical(q_enu_flu),
                      angular_velocity=rate * _FLIP_YZ,
                      linear_acceleration=accel * _FLIP_YZ)


def ros_to_vn(orientation_xyzw: ArrayLike, angular_velocity: ArrayLike,
              linear_acceleration: ArrayLike, unit_tolerance: float = UNIT_TOLERANCE,
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`vn_to_ros`: ROS (FLU w.r.t. ENU) -> VN-100 (FRD w.r.t. NED).

    ``q_NED_FRD = Q_NED_ENU * q_ENU_FLU * Q_FLU_FRD`` with ``Q_NED_ENU = Q_ENU_NED^-1`` and
    ``Q_FLU_FRD = Q_FRD_FLU^-1``. Returns ``(q_xyzw with w >= 0, rate_FRD, specific_force_FRD)``.
    Used by the fake VN-100 so the simulator can feed ROS-frame truth.
    """
    q_enu_flu = unit_quaternion(orientation_xyzw, "orientation", unit_tolerance)
    rate = bounded_vector3(angular_velocity, "angular velocity")
    accel = bounded_vector3(linear_acceleration, "linear acceleration")
    q_ned_frd = _ROS_TO_VN @ q_enu_flu
    return _canonical(q_ned_frd), rate * _FLIP_YZ, accel * _FLIP_YZ
