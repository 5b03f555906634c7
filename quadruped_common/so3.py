"""Rotation maths on SO(3) used by the model, the controller and the drivers.

Conventions:

- Rotations are 3x3 numpy arrays R with R^T R = I, det R = +1; ``R`` maps body-frame vectors to the
  world frame (paper: R in eq. (rot), (error)).
- Quaternions are ``(x, y, z, w)``, scalar last, as in ROS ``geometry_msgs/Quaternion``.
- Roll, pitch, yaw are the ROS / REP-103 fixed-axis angles: R = Rz(yaw) Ry(pitch) Rx(roll).
- ``hat(w)`` is the skew matrix with hat(w) v = w x v; ``vee`` is its inverse.

All functions are pure and keep working at the numerically awkward points (angles near 0 and pi,
gimbal lock) instead of returning NaN.
"""
from __future__ import annotations

import math
from typing import Any, Sequence, Tuple, Union

import numpy as np

from quadruped_common.jit import hypot2, hypot3, jitable

ArrayLike = Union[Sequence[float], np.ndarray]

#: Below this rotation angle (rad) the series expansions of sin(t)/t etc. are used.
_SMALL_ANGLE = 1e-4
#: Quaternions with a norm below this are rejected as meaningless.
_MIN_QUAT_NORM = 1e-9


TWO_PI = 2.0 * math.pi


def wrap_angle(angle: Union[float, np.ndarray]) -> Union[float, np.ndarray]:
    """Angle(s) in radians wrapped into [-pi, pi): the project's one wrapping convention.

    A float gives a float (the kinematics' hot path, no numpy); anything else an array.
    """
    if isinstance(angle, float):
        return (angle + math.pi) % TWO_PI - math.pi
    return (np.asarray(angle, dtype=float) + math.pi) % TWO_PI - math.pi


def _vec3(w: ArrayLike, name: str = "vector") -> np.ndarray:
    v = np.asarray(w, dtype=float).reshape(-1)
    if v.shape != (3,):
        raise ValueError("%s must have 3 elements, got shape %s" % (name, np.shape(w)))
    return v


def _mat3(R: ArrayLike, name: str = "matrix") -> np.ndarray:
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3):
        raise ValueError("%s must be 3x3, got shape %s" % (name, M.shape))
    return M


def hat(w: ArrayLike) -> np.ndarray:
    """Skew-symmetric matrix [w]_x with hat(w) @ v == cross(w, v)."""
    x, y, z = _vec3(w, "hat argument")
    return np.array([[0.0, -z, y],
                     [z, 0.0, -x],
                     [-y, x, 0.0]])


def vee(S: ArrayLike) -> np.ndarray:
    """Inverse of :func:`hat`: the vector of the skew-symmetric part of ``S``.

    For a non-skew matrix the antisymmetric part 0.5 (S - S^T) is used, which is what the attitude
    error of eq. (error) needs.
    """
    M = _mat3(S, "vee argument")
    return np.array([0.5 * (M[2, 1] - M[1, 2]),
                     0.5 * (M[0, 2] - M[2, 0]),
                     0.5 * (M[1, 0] - M[0, 1])])


# --------------------------------------------------------------------------------------------------
# Quaternions (x, y, z, w)
# --------------------------------------------------------------------------------------------------

def _quat(q: ArrayLike) -> np.ndarray:
    v = np.asarray(q, dtype=float).reshape(-1)
    if v.shape != (4,):
        raise ValueError("quaternion must have 4 elements (x, y, z, w), got shape %s" % (np.shape(q),))
    if not np.all(np.isfinite(v)):
        raise ValueError("quaternion has non-finite elements: %s" % (v,))
    return v


def quat_normalize(q: ArrayLike) -> np.ndarray:
    """Unit quaternion in the direction of ``q``; ValueError for non-finite or near-zero input."""
    v = _quat(q)
    n = float(np.linalg.norm(v))
    if n < _MIN_QUAT_NORM:
        raise ValueError("quaternion norm %g is too small to define a rotation" % n)
    return v / n


def quat_to_rot(q: ArrayLike) -> np.ndarray:
    """Rotation matrix of quaternion (x, y, z, w); the quaternion is normalised first."""
    x, y, z, w = quat_normalize(q)
    return np.array(_rotation_entries(x, y, z, w)).reshape(3, 3)


def quaternions_to_rotations(q: ArrayLike) -> np.ndarray:
    """(N, 3, 3) rotation matrices of (N, 4) quaternions (x, y, z, w), each normalised first (as
    :func:`quat_to_rot`, whose equation this is); ValueError unless finite with norms of at least 1e-9."""
    v = np.asarray(q, dtype=float)
    if v.ndim != 2 or v.shape[1] != 4:
        raise ValueError("quaternions must have shape (N, 4) (x, y, z, w), got %s" % (v.shape,))
    if not np.all(np.isfinite(v)):
        raise ValueError("quaternions have non-finite elements")
    norm = np.linalg.norm(v, axis=1)
    if v.shape[0] and norm.min() < _MIN_QUAT_NORM:
        raise ValueError("quaternion norm %g is too small to define a rotation" % norm.min())
    x, y, z, w = (v / norm[:, None]).T
    return np.stack(_rotation_entries(x, y, z, w), axis=-1).reshape(-1, 3, 3)


def _rotation_entries(x: Any, y: Any, z: Any, w: Any) -> Tuple[Any, ...]:
    """The nine entries (row-major) of the rotation of the unit quaternion (x, y, z, w): floats, or arrays of
    quaternions element by element (one equation for :func:`quat_to_rot`, per IMU sample on the robot, and
    :func:`quaternions_to_rotations`, over a recording)."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
            2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
            2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy))


def rot_to_quat(R: ArrayLike) -> np.ndarray:
    """Unit quaternion (x, y, z, w) with w >= 0 of rotation ``R`` (Shepperd's method, stable for all R)."""
    M = _mat3(R, "rotation")
    if not np.all(np.isfinite(M)):
        raise ValueError("rotation matrix has non-finite elements")
    trace = M[0, 0] + M[1, 1] + M[2, 2]
    # Pick the largest of w, x, y, z to divide by: avoids cancellation near 180 degrees.
    if trace >= max(M[0, 0], M[1, 1], M[2, 2]):
        s = 2.0 * math.sqrt(max(1.0 + trace, 0.0))
        w = 0.25 * s
        x = (M[2, 1] - M[1, 2]) / s
        y = (M[0, 2] - M[2, 0]) / s
        z = (M[1, 0] - M[0, 1]) / s
    elif M[0, 0] >= M[1, 1] and M[0, 0] >= M[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + M[0, 0] - M[1, 1] - M[2, 2], 0.0))
        x = 0.25 * s
        w = (M[2, 1] - M[1, 2]) / s
        y = (M[0, 1] + M[1, 0]) / s
        z = (M[0, 2] + M[2, 0]) / s
    elif M[1, 1] >= M[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + M[1, 1] - M[0, 0] - M[2, 2], 0.0))
        y = 0.25 * s
        w = (M[0, 2] - M[2, 0]) / s
        x = (M[0, 1] + M[1, 0]) / s
        z = (M[1, 2] + M[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 + M[2, 2] - M[0, 0] - M[1, 1], 0.0))
        z = 0.25 * s
        w = (M[1, 0] - M[0, 1]) / s
        x = (M[0, 2] + M[2, 0]) / s
        y = (M[1, 2] + M[2, 1]) / s
    q = np.array([x, y, z, w])
    q /= np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    return q


def quat_multiply(q1: ArrayLike, q2: ArrayLike) -> np.ndarray:
    """Hamilton product q1 * q2 (x, y, z, w): quat_to_rot(q1 * q2) == quat_to_rot(q1) @ quat_to_rot(q2)."""
    x1, y1, z1, w1 = _quat(q1)
    x2, y2, z2, w2 = _quat(q2)
    return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
                     w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])


def quat_conjugate(q: ArrayLike) -> np.ndarray:
    """Conjugate (x, y, z, w) -> (-x, -y, -z, w): the inverse rotation of a unit quaternion."""
    x, y, z, w = _quat(q)
    return np.array([-x, -y, -z, w])


# --------------------------------------------------------------------------------------------------
# Roll, pitch, yaw (REP-103: R = Rz(yaw) Ry(pitch) Rx(roll))
# --------------------------------------------------------------------------------------------------

def rot_x(angle: float) -> np.ndarray:
    """Elementary rotation about x by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    """Elementary rotation about y by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    """Elementary rotation about z by ``angle`` rad."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_rot(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (radians, ROS / REP-103 convention)."""
    for name, value in (("roll", roll), ("pitch", pitch), ("yaw", yaw)):
        if not math.isfinite(value):
            raise ValueError("%s must be finite, got %r" % (name, value))
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def rot_to_rpy(R: ArrayLike) -> Tuple[float, float, float]:
    """(roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll); pitch in [-pi/2, pi/2].

    At gimbal lock (|pitch| = pi/2) only roll -/+ yaw is defined; yaw is then set to 0 and the
    whole rotation about the vertical is put into roll, so rpy_to_rot(rot_to_rpy(R)) == R still holds.
    """
    M = _mat3(R, "rotation")
    return rpy_f(M[0, 0], M[0, 1], M[0, 2], M[1, 0], M[2, 0], M[2, 1], M[2, 2])


@jitable
def rpy_f(r00: float, r01: float, r02: float, r10: float, r20: float, r21: float,
          r22: float) -> Tuple[float, float, float]:
    """:func:`rot_to_rpy` on the elements of R it needs, as floats (compiled code calls it too)."""
    # cos(pitch) from the first column is accurate near gimbal lock, unlike asin(-R20).
    cp = hypot2(r00, r10)
    pitch = math.atan2(-r20, cp)
    if cp > 1e-9:
        roll = math.atan2(r21, r22)
        yaw = math.atan2(r10, r00)
    else:
        yaw = 0.0
        if r20 < 0.0:  # pitch = +pi/2: R01 = sin(roll - yaw), R02 = cos(roll - yaw)
            roll = math.atan2(r01, r02)
        else:  # pitch = -pi/2: R01 = -sin(roll + yaw), R02 = -cos(roll + yaw)
            roll = math.atan2(-r01, -r02)
    return roll, pitch, yaw


# --------------------------------------------------------------------------------------------------
# Exponential and logarithm
# --------------------------------------------------------------------------------------------------

def exp_so3(w: ArrayLike) -> np.ndarray:
    """Rotation exp(hat(w)) of rotation vector ``w`` (Rodrigues' formula, series for small angles)."""
    v = _vec3(w, "rotation vector")
    if not np.all(np.isfinite(v)):
        raise ValueError("rotation vector has non-finite elements: %s" % (v,))
    theta2 = float(v @ v)
    theta = math.sqrt(theta2)
    if theta < _SMALL_ANGLE:
        a = 1.0 - theta2 / 6.0          # sin(t)/t
        b = 0.5 - theta2 / 24.0         # (1 - cos t)/t^2
    else:
        a = math.sin(theta) / theta
        b = (1.0 - math.cos(theta)) / theta2
    W = hat(v)
    return np.eye(3) + a * W + b * (W @ W)


def log_so3(R: ArrayLike) -> np.ndarray:
    """Rotation vector w (|w| in [0, pi]) with exp_so3(w) == R; accurate near 0 and near pi."""
    M = _mat3(R, "rotation")
    if not np.all(np.isfinite(M)):
        raise ValueError("rotation matrix has non-finite elements")
    axis_sin = vee(M)                   # sin(theta) * n
    s = float(np.linalg.norm(axis_sin))
    c = 0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0)  # cos(theta)
    theta = math.atan2(s, c)
    if theta < _SMALL_ANGLE:
        # theta / sin(theta) ~ 1 + theta^2 / 6
        return axis_sin * (1.0 + theta * theta / 6.0)
    if theta < math.pi - 1e-3:
        return axis_sin * (theta / s)
    # Near pi, sin(theta) carries no information about the axis: use the symmetric part,
    # R + R^T - 2 cos(t) I = 2 (1 - cos t) n n^T, and the antisymmetric part only for the sign.
    B = 0.5 * (M + M.T) - c * np.eye(3)
    col = int(np.argmax(np.diag(B)))
    n = B[:, col] / math.sqrt(max(B[col, col], 1e-300))
    n /= np.linalg.norm(n)
    if float(n @ axis_sin) < 0.0:
        n = -n
    return n * theta


# --------------------------------------------------------------------------------------------------
# Errors and distances
# --------------------------------------------------------------------------------------------------

def attitude_error(R_d: ArrayLike, R: ArrayLike) -> np.ndarray:
    """e_R = vee(0.5 (R_d^T R - R^T R_d)) of eq. (error), in the body frame.

    For R = R_d exp(a hat(n)) this is sin(a) n.
    """
    Rd = _mat3(R_d, "R_d")
    M = _mat3(R, "R")
    E = Rd.T @ M
    return np.array([0.5 * (E[2, 1] - E[1, 2]),
                     0.5 * (E[0, 2] - E[2, 0]),
                     0.5 * (E[1, 0] - E[0, 1])])


def geodesic_angle(R_d: ArrayLike, R: ArrayLike) -> float:
    """Angle in [0, pi] of the rotation R_d^T R, i.e. arccos((tr(R_d^T R) - 1) / 2).

    Computed as atan2(|vee(skew part)|, (tr - 1)/2), which keeps full precision near 0 and pi where
    arccos loses it. Symmetric in its arguments.
    """
    return geodesic_f(tuple(_mat3(R_d, "R_d").ravel().tolist()), tuple(_mat3(R, "R").ravel().tolist()))


@jitable
def geodesic_f(R_d: Sequence[float], R: Sequence[float]) -> float:
    """:func:`geodesic_angle` of row-major 3x3 rotations (9 floats each; compiled code calls it too)."""
    # E = R_d^T R; |sin t| = |vee(skew part of E)| and cos t = (tr E - 1) / 2 both carry an absolute
    # error of ~eps, so atan2 is accurate to ~eps everywhere, while arccos(c) has an error of ~sqrt(eps)
    # near 0 and pi.
    dx, dy, dz, trace = geodesic_terms(R_d, R)
    return math.atan2(0.5 * hypot3(dx, dy, dz), 0.5 * (trace - 1.0))


@jitable
def geodesic_terms(R_d: Sequence[Any], R: Sequence[Any]) -> Tuple[Any, Any, Any, Any]:
    """(2 vee(skew part of E), tr E) of E = R_d^T R for row-major 3x3 matrices given as 9 elements each:
    floats (:func:`geodesic_f`) or arrays of many rotations (:func:`geodesic_angles`), the same arithmetic."""
    e01 = R_d[0] * R[1] + R_d[3] * R[4] + R_d[6] * R[7]
    e02 = R_d[0] * R[2] + R_d[3] * R[5] + R_d[6] * R[8]
    e10 = R_d[1] * R[0] + R_d[4] * R[3] + R_d[7] * R[6]
    e12 = R_d[1] * R[2] + R_d[4] * R[5] + R_d[7] * R[8]
    e20 = R_d[2] * R[0] + R_d[5] * R[3] + R_d[8] * R[6]
    e21 = R_d[2] * R[1] + R_d[5] * R[4] + R_d[8] * R[7]
    trace = 0.0
    for k in range(3):
        trace = trace + (R_d[k] * R[k] + R_d[3 + k] * R[3 + k] + R_d[6 + k] * R[6 + k])
    return e21 - e12, e02 - e20, e10 - e01, trace


def orthonormalize(R: ArrayLike) -> np.ndarray:
    """Nearest rotation matrix (Frobenius norm) to ``R`` via SVD; keeps integrated attitudes in SO(3)."""
    M = _mat3(R, "matrix")
    if not np.all(np.isfinite(M)):
        raise ValueError("matrix has non-finite elements")
    U, _, Vt = np.linalg.svd(M)
    D = np.eye(3)
    D[2, 2] = 1.0 if np.linalg.det(U @ Vt) > 0.0 else -1.0
    return U @ D @ Vt


def is_rotation(R: ArrayLike, tol: float = 1e-6) -> bool:
    """True if ``R`` is a finite 3x3 matrix with |R^T R - I| <= tol and det R > 0."""
    try:
        M = _mat3(R, "matrix")
    except ValueError:
        return False
    if not np.all(np.isfinite(M)):
        return False
    return bool(np.max(np.abs(M.T @ M - np.eye(3))) <= tol and np.linalg.det(M) > 0.0)


# --------------------------------------------------------------------------------------------------
# Batched forms for trajectories (N rotations at once); each tested against its scalar twin above
# --------------------------------------------------------------------------------------------------

def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (size 3) of arrays that broadcast together: the arithmetic of np.cross
    (same values) without its axis bookkeeping, which costs more than the products on small batches."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)


def atan2_elementwise(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``math.atan2`` of each pair: the C library's atan2, as scalar and compiled code compute it.

    Not ``np.arctan2``: on CPUs with AVX-512, numpy computes it with its own SIMD routine, which differs
    from the C library's in the last bit for about a third of all arguments, so the recorded angles of the
    per-trial simulator would not be those of the batched one (:func:`rpy_f`, :func:`geodesic_f`)."""
    y = np.asarray(y, dtype=float)
    x = np.broadcast_to(np.asarray(x, dtype=float), y.shape)
    return np.fromiter(map(math.atan2, y.ravel().tolist(), x.ravel().tolist()), dtype=float,
                       count=y.size).reshape(y.shape)


def rotations_to_rpy(R: np.ndarray) -> np.ndarray:
    """(N, 3) roll, pitch, yaw (rad, R = Rz(yaw) Ry(pitch) Rx(roll)) of (N, 3, 3) rotations, as :func:`rot_to_rpy`."""
    cp = np.sqrt(R[:, 0, 0] * R[:, 0, 0] + R[:, 1, 0] * R[:, 1, 0])  # hypot2 of rpy_f, the same bits
    pitch = atan2_elementwise(-R[:, 2, 0], cp)
    regular = cp > 1e-9
    roll = np.where(regular, atan2_elementwise(R[:, 2, 1], R[:, 2, 2]), 0.0)
    yaw = np.where(regular, atan2_elementwise(R[:, 1, 0], R[:, 0, 0]), 0.0)
    if not np.all(regular):  # gimbal lock: all rotation about the vertical into roll (:func:`rot_to_rpy`)
        up = ~regular & (R[:, 2, 0] < 0.0)
        down = ~regular & ~(R[:, 2, 0] < 0.0)
        roll = np.where(up, atan2_elementwise(R[:, 0, 1], R[:, 0, 2]), roll)
        roll = np.where(down, atan2_elementwise(-R[:, 0, 1], -R[:, 0, 2]), roll)
    return np.column_stack((roll, pitch, yaw))


def rotations_to_quaternions(R: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (x, y, z, w), w >= 0, of (N, 3, 3) rotations (Shepperd, branch per row)."""
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    trace = m00 + m11 + m22
    candidates = np.column_stack((1.0 + trace, 1.0 + m00 - m11 - m22, 1.0 + m11 - m00 - m22, 1.0 + m22 - m00 - m11))
    branch = np.argmax(candidates, axis=1)
    s = 2.0 * np.sqrt(np.maximum(candidates[np.arange(R.shape[0]), branch], 1e-300))
    d21, d02, d10 = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    s01, s02, s12 = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    q = np.empty((R.shape[0], 4))
    b = branch == 0
    q[b] = np.column_stack((d21[b] / s[b], d02[b] / s[b], d10[b] / s[b], 0.25 * s[b]))
    b = branch == 1
    q[b] = np.column_stack((0.25 * s[b], s01[b] / s[b], s02[b] / s[b], d21[b] / s[b]))
    b = branch == 2
    q[b] = np.column_stack((s01[b] / s[b], 0.25 * s[b], s12[b] / s[b], d02[b] / s[b]))
    b = branch == 3
    q[b] = np.column_stack((s02[b] / s[b], s12[b] / s[b], 0.25 * s[b], d10[b] / s[b]))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0.0] *= -1.0
    return q


def geodesic_angles(R_d: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(N,) angle of R_d^T R_k (rad, [0, pi]) as :func:`geodesic_angle`, for (N, 3, 3) rotations R and one
    setpoint R_d (3, 3) or one per rotation (N, 3, 3)."""
    # geodesic_terms on columns of elements (no einsum, whose SIMD sums round differently on some CPUs)
    # and the C library's atan2: the per-trial and the batched simulator record the same bits.
    D = np.broadcast_to(np.asarray(R_d, dtype=float), np.shape(R))
    dx, dy, dz, trace = geodesic_terms([D[:, k // 3, k % 3] for k in range(9)], [R[:, k // 3, k % 3] for k in range(9)])
    s = 0.5 * np.sqrt(dx * dx + dy * dy + dz * dz)  # hypot3, elementwise
    return atan2_elementwise(s, 0.5 * (trace - 1.0))
