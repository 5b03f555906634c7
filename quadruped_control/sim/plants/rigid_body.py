"""What every plant shares: the floating base's state, its input checks and the SO(3) chart machinery
of the Runge-Kutta integrator (used by :mod:`.paper` and :mod:`.tank`).

- :class:`RigidBodyState`: position p^W, velocity v_B^W, rotation R_B^W and rate omega_B^B.
- :func:`joint_array`, :func:`check_dt`, :func:`vector3`: the checks of the plants' public inputs.
- The chart: within a step R = R_0 exp(hat(xi)) and the rotation vector xi obeys
  d xi/dt = J_r(xi)^-1 omega (:func:`exp_rotation`, :func:`chart_rate`, both at once in
  :func:`chart_point`); :func:`chart_step_end` maps the chart state at the end of a step back to a
  :class:`RigidBodyState` (one Newton-Schulz polish of R, finiteness check).
- :class:`StepContext`: the leg inputs of one step as floats (the plants' stages read it).

The Runge-Kutta stages work on plain Python floats: for 3-vectors and 3x3 matrices, CPython float
arithmetic is several times faster than numpy's per-call overhead. Matrices are row-major 9-tuples
(:data:`Mat3`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence, Tuple, Union

import numpy as np

from quadruped_common.jit import jitable
from quadruped_common.robot import LEGS
from quadruped_control.model.hydrodynamics import paw_buoyancy_f

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]
Mat3 = Tuple[float, float, float, float, float, float, float, float, float]
Vec3 = Tuple[float, float, float]

NUM_LEGS = len(LEGS)

#: Below this rotation-vector norm (rad) the SO(3) chart coefficients are their Taylor series through
#: t^6 (:func:`chart_coefficients`): the first omitted term is below 1e-20 there, so the series are
#: exact to rounding, and they avoid the cancellation of 1/t^2 - (1 + cos t) / (2 t sin t) at small t.
#: The integrator's stage coordinates are about omega dt / 2 (0.005 rad at 1 rad/s), so its stages run
#: without a sine or cosine.
SERIES_ANGLE = 0.02

__all__ = [
    "DynamicsError",
    "Mat3",
    "NUM_LEGS",
    "RigidBodyState",
    "SERIES_ANGLE",
    "StateDerivative",
    "StepContext",
    "as_mat3",
    "chart_coefficients",
    "chart_point",
    "chart_rate",
    "chart_step_end",
    "check_dt",
    "inverse_jacobian_rate",
    "diverged",
    "exp_rotation",
    "joint_array",
    "matmul",
    "polish",
    "vector3",
]


class DynamicsError(RuntimeError):
    """The integration produced a non-finite state (diverged); the input state is left untouched."""


# --------------------------------------------------------------------------------------------------
# State and input checks
# --------------------------------------------------------------------------------------------------

def vector3(value: ArrayLike, name: str) -> np.ndarray:
    """``value`` as a float array of shape (3,); ValueError for another shape or a NaN/inf element."""
    arr = np.array(value, dtype=float)
    if arr.shape != (3,):
        raise ValueError("%s must have 3 elements, got shape %s" % (name, arr.shape))
    if not math.isfinite(float(arr.sum())):  # NaN or inf anywhere makes the sum non-finite
        raise ValueError("%s has non-finite elements: %s" % (name, arr))
    return arr


@dataclass
class RigidBodyState:
    """State of the floating base.

    ``position`` p^W (m) and ``velocity`` v_B^W (m/s) of the centre of mass in the world frame,
    ``rotation`` R_B^W (body -> world), ``omega`` omega_B^B (rad/s) in the body frame (as in eq. (ee_vel)).
    """

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))

    #: Largest |R^T R - I| accepted by :meth:`validate`.
    ROTATION_TOL = 1e-6

    def copy(self) -> "RigidBodyState":
        """Deep copy (independent arrays)."""
        return RigidBodyState(self.position.copy(), self.velocity.copy(), self.rotation.copy(), self.omega.copy())

    def validate(self) -> "RigidBodyState":
        """Check shapes, finiteness and R in SO(3); returns a copy with float arrays, ValueError otherwise."""
        rotation = np.array(self.rotation, dtype=float)
        if rotation.shape != (3, 3) or not math.isfinite(float(rotation.sum())):
            raise ValueError("rotation must be a finite 3x3 matrix, got %r" % (self.rotation,))
        error = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
        # For an orthogonal matrix det = +-1 = R_0 . (R_1 x R_2) (rows); -1 is a reflection.
        (a, b, c), (d, e, f), (g, h, i) = rotation.tolist()
        det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
        if error > self.ROTATION_TOL or det <= 0.0:
            raise ValueError("rotation is not in SO(3) (|R^T R - I| = %.3g, det = %.6g)" % (error, det))
        return RigidBodyState(vector3(self.position, "position"), vector3(self.velocity, "velocity"),
                              rotation, vector3(self.omega, "omega"))

    def to_vector(self) -> np.ndarray:
        """Flat (18,) vector [p, v, R row-major, omega] (for logging and comparisons)."""
        return np.concatenate((self.position, self.velocity, self.rotation.reshape(9), self.omega))

    @classmethod
    def from_vector(cls, vector: ArrayLike) -> "RigidBodyState":
        """Inverse of :meth:`to_vector`; validates the result."""
        vec = np.asarray(vector, dtype=float)
        if vec.shape != (18,):
            raise ValueError("state vector must have 18 elements, got shape %s" % (vec.shape,))
        return cls(vec[0:3].copy(), vec[3:6].copy(), vec[6:15].reshape(3, 3).copy(), vec[15:18].copy()).validate()


@dataclass
class StateDerivative:
    """Time derivative of a :class:`RigidBodyState`: (p_dot, v_dot, R_dot = R hat(omega), omega_dot)."""

    position_dot: np.ndarray
    velocity_dot: np.ndarray
    rotation_dot: np.ndarray
    omega_dot: np.ndarray


def joint_array(value: ArrayLike, name: str) -> np.ndarray:
    """Joint angles or rates as a finite (4, 3) float array (legs 1..4 x (theta1, theta2, theta3)); a
    (12,) vector is reshaped. ValueError for another shape or a NaN/inf element."""
    arr = np.array(value, dtype=float)
    if arr.shape == (3 * NUM_LEGS,):
        arr = arr.reshape(NUM_LEGS, 3)
    if arr.shape != (NUM_LEGS, 3):
        raise ValueError("%s must have shape (4, 3) or (12,) (legs 1..4 x (theta1, theta2, theta3)), got %s"
                         % (name, arr.shape))
    if not np.all(np.isfinite(arr)):
        raise ValueError("%s has non-finite elements: %s" % (name, arr.tolist()))
    return arr


def check_dt(dt: float) -> float:
    """``dt`` as a float; ValueError unless it is a positive finite number of seconds."""
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError("dt must be a positive finite number of seconds, got %r" % (dt,))
    return dt


# --------------------------------------------------------------------------------------------------
# The SO(3) chart of the integrator
# --------------------------------------------------------------------------------------------------

@jitable
def chart_coefficients(t2: float) -> Tuple[float, float, float]:
    """(sin t / t, (1 - cos t) / t^2, 1/t^2 - (1 + cos t) / (2 t sin t)) for t^2 = |xi|^2 = ``t2``: the
    coefficients of Rodrigues' formula (:func:`exp_rotation`) and of the inverse right Jacobian
    (:func:`chart_rate`); their Taylor series below :data:`SERIES_ANGLE`."""
    if t2 < SERIES_ANGLE * SERIES_ANGLE:
        return (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0)),
                0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0)),
                1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 / 1209600.0)))
    t = math.sqrt(t2)
    sin_t, cos_t = math.sin(t), math.cos(t)
    return sin_t / t, (1.0 - cos_t) / t2, 1.0 / t2 - (1.0 + cos_t) / (2.0 * t * sin_t)


@jitable
def rodrigues(x: float, y: float, z: float, a: float, b: float) -> Mat3:
    """exp(hat(xi)) = I + a hat(xi) + b hat(xi)^2 with the coefficients a, b of :func:`chart_coefficients`."""
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    return (1.0 - b * (y * y + z * z), bxy - a * z, bxz + a * y,
            bxy + a * z, 1.0 - b * (x * x + z * z), byz - a * x,
            bxz - a * y, byz + a * x, 1.0 - b * (x * x + y * y))


@jitable
def exp_rotation(x: float, y: float, z: float) -> Mat3:
    """exp(hat(xi)) by Rodrigues' formula (the maths of so3.exp_so3, on floats and without input checks)."""
    a, b, _ = chart_coefficients(x * x + y * y + z * z)
    return rodrigues(x, y, z, a, b)


@jitable
def matmul(A: Sequence[float], B: Sequence[float]) -> Mat3:
    """A B for row-major 3x3 matrices (9 floats each)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


def as_mat3(M: ArrayLike) -> Mat3:
    """A 3x3 matrix as a row-major 9-tuple of floats."""
    return tuple(np.asarray(M, dtype=float).reshape(9).tolist())  # type: ignore[return-value]


@jitable
def inverse_jacobian_rate(x: float, y: float, z: float, wx: float, wy: float, wz: float, c: float) -> Vec3:
    """J_r^-1(xi) omega = omega + 1/2 xi x omega + c xi x (xi x omega), with c of :func:`chart_coefficients`."""
    ax, ay, az = y * wz - z * wy, z * wx - x * wz, x * wy - y * wx        # xi x omega
    bx, by, bz = y * az - z * ay, z * ax - x * az, x * ay - y * ax        # xi x (xi x omega)
    return wx + 0.5 * ax + c * bx, wy + 0.5 * ay + c * by, wz + 0.5 * az + c * bz


@jitable
def chart_rate(x: float, y: float, z: float, wx: float, wy: float, wz: float) -> Vec3:
    """d xi / dt = J_r(xi)^-1 omega for R = R_0 exp(hat(xi)) with R^T dR/dt = hat(omega).

    J_r^-1(xi) = I + 1/2 hat(xi) + c(t) hat(xi)^2, c(t) = 1/t^2 - (1 + cos t) / (2 t sin t), t = |xi|.
    """
    return inverse_jacobian_rate(x, y, z, wx, wy, wz, chart_coefficients(x * x + y * y + z * z)[2])


@jitable
def chart_point(R0: Mat3, x: float, y: float, z: float, wx: float, wy: float, wz: float) -> Tuple[Mat3, Vec3]:
    """(R, d xi/dt) at chart coordinate xi = (x, y, z) around R0: R = R0 exp(hat(xi)) and the rate
    :func:`chart_rate` of the body rate omega, the coefficients computed once for both. At xi = 0 (the
    first Runge-Kutta stage) exp(hat(xi)) = I and J_r^-1 = I, so (R0, omega) is returned without the
    products (the same values)."""
    if x == 0.0 and y == 0.0 and z == 0.0:
        return R0, (wx, wy, wz)
    a, b, c = chart_coefficients(x * x + y * y + z * z)
    return matmul(R0, rodrigues(x, y, z, a, b)), inverse_jacobian_rate(x, y, z, wx, wy, wz, c)


@jitable
def polish(R: Mat3) -> Mat3:
    """One Newton-Schulz step towards SO(3), R (3 I - R^T R) / 2: removes the O(eps) drift that products
    of rotations accumulate."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = R
    n0 = 1.5 - 0.5 * (a0 * a0 + a3 * a3 + a6 * a6)
    n4 = 1.5 - 0.5 * (a1 * a1 + a4 * a4 + a7 * a7)
    n8 = 1.5 - 0.5 * (a2 * a2 + a5 * a5 + a8 * a8)
    n1 = -0.5 * (a0 * a1 + a3 * a4 + a6 * a7)
    n2 = -0.5 * (a0 * a2 + a3 * a5 + a6 * a8)
    n5 = -0.5 * (a1 * a2 + a4 * a5 + a7 * a8)
    return matmul(R, (n0, n1, n2, n1, n4, n5, n2, n5, n8))


def diverged(dt: float, start: RigidBodyState, reason: str) -> DynamicsError:
    """The error of a step of ``dt`` s from ``start`` that blew up (``reason``)."""
    return DynamicsError("integration diverged (%s) in a step of %g s from %s" % (reason, dt, start))


def chart_step_end(R0: Mat3, position_velocity: Tuple[float, ...], xi: Vec3, omega: Vec3, dt: float,
                   start: RigidBodyState) -> RigidBodyState:
    """The state at the end of a Runge-Kutta step in the chart around R0: p, v (``position_velocity``,
    6 floats), R = R0 exp(hat(xi)) and omega. One Newton-Schulz polish, R (3 I - R^T R) / 2, removes the
    O(eps) drift that products of rotations accumulate. Raises :class:`DynamicsError` (naming ``dt`` and
    the ``start`` state) if a value is not finite. The fields are views of disjoint parts of one array."""
    isfinite = math.isfinite
    values = position_velocity + xi + omega
    if not isfinite(sum(values)) and not all(map(isfinite, values)):
        raise diverged(dt, start, "non-finite state")
    R1 = polish(matmul(R0, exp_rotation(xi[0], xi[1], xi[2])))
    data = np.array(position_velocity + R1 + omega)
    return RigidBodyState(data[0:3], data[3:6], data[6:15].reshape(3, 3), data[15:18])


# --------------------------------------------------------------------------------------------------
# Inputs of one step
# --------------------------------------------------------------------------------------------------

class StepContext:
    """The leg inputs of one integration step as floats, constant while q, q_dot are held.

    ``feet``: per leg the row (r_e,i^B, J_P,i^B q_dot_i) (6 floats); ``lift``: the paw buoyancy force
    F_buoyancy^W . z_hat; ``up_torque``: the matrix U (row-major) with U R^T z_hat = the paw buoyancy
    torque (:func:`~quadruped_control.model.hydrodynamics.paw_buoyancy_f`) plus the plant's ``restoring``
    torque matrix (zero unless a centre-of-buoyancy offset is configured).
    """

    __slots__ = ("feet", "lift", "up_torque")

    def __init__(self, rows: Sequence[Tuple[float, ...]], net_paw_buoyancy: float, restoring: Mat3) -> None:
        """``rows``: the legs' rows, as :func:`~quadruped_control.model.kinematics.leg_kinematics_rows`
        returns them."""
        feet = self.feet = list(rows)
        self.lift, (u0, u1, u2, u3, u4, u5, u6, u7, u8) = paw_buoyancy_f(feet, net_paw_buoyancy)
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = restoring
        self.up_torque = (r0 + u0, r1 + u1, r2 + u2, r3 + u3, r4 + u4, r5 + u5, r6 + u6, r7 + u7, r8 + u8)

    @classmethod
    def from_rows(cls, rows: Sequence[Sequence[float]], net_paw_buoyancy: float, restoring: Mat3) -> "StepContext":
        """The context of per-leg rows (r_e,i^B, J_P,i^B q_dot_i) (same values as the flat constructor)."""
        return cls([tuple(row) for row in rows], net_paw_buoyancy, restoring)
