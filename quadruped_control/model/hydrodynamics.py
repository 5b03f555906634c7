"""Hydrodynamic forces on the underwater quadruped (paper section "Mathematical Modeling").

- Paw drag and its transmission to the body, eq. (drag), (virtual_work), (force_leg), (torque_leg):
  :func:`paw_drag_force`, :func:`leg_wrench`.
- Net paw buoyancy and its torque on the body, eq. (buoy_force), (buoy_torque): :func:`paw_buoyancy`.
- MuJoCo's inertia-box body drag, eq. (inertia_box), (quad), (visc): :func:`inertia_box`,
  :func:`body_drag` (force and torque both in the body frame; eq. (drag_total) rotates the force to
  the world frame, which :mod:`quadruped_control.sim.plants.paper` does).

Frames: superscript W is the ENU world frame, B the body frame (forward-left-up), R = R_B^W maps body
vectors to world vectors. All functions are pure; the per-leg functions accept one leg (shape (3,))
or a stack of legs (shape (N, 3)) and return the same leading shape.

The coefficients that depend only on the parameters are gathered in :class:`BodyDragCoefficients`
so the integrator computes them once instead of at every Runge-Kutta stage.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Tuple, Union

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_control.model.params import RobotParams

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

__all__ = [
    "BodyDragCoefficients",
    "body_drag",
    "body_drag_coefficients",
    "inertia_box",
    "leg_wrench",
    "paw_buoyancy",
    "paw_drag_force",
]


def _finite_vectors(value: ArrayLike, name: str) -> np.ndarray:
    """``value`` as a float array of shape (3,) or (N, 3); ValueError for another shape or NaN/inf."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim not in (1, 2) or arr.shape[-1] != 3:
        raise ValueError("%s must have shape (3,) or (N, 3), got %s" % (name, arr.shape))
    if not np.all(np.isfinite(arr)):
        raise ValueError("%s has non-finite elements: %s" % (name, arr))
    return arr


def _rotation(R: ArrayLike) -> np.ndarray:
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3):
        raise ValueError("R must be a 3x3 rotation matrix, got shape %s" % (M.shape,))
    if not np.all(np.isfinite(M)):
        raise ValueError("R has non-finite elements")
    return M


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (..., 3) arrays (np.cross is several times slower on small arrays)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx), axis=-1)


# --------------------------------------------------------------------------------------------------
# Paw drag, eq. (drag), (force_leg), (torque_leg)
# --------------------------------------------------------------------------------------------------

def paw_drag_force(v_foot_world: ArrayLike, params: RobotParams) -> np.ndarray:
    """Drag on a spherical paw, F_D,i^W = -k |v_e,i^W| v_e,i^W with k = 1/2 rho C_D A, eq. (drag).

    ``v_foot_world``: foot velocity v_e,i^W in m/s, shape (3,) or (N, 3). Returns N, same shape.
    """
    v = _finite_vectors(v_foot_world, "foot velocity")
    speed = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    return -params.drag_constant * speed * v


def leg_wrench(v_foot_world: ArrayLike, r_foot_body: ArrayLike, R: ArrayLike,
               params: RobotParams) -> Tuple[np.ndarray, np.ndarray]:
    """Force and torque that the paw drag of a leg exerts on the body, eq. (force_leg), (torque_leg).

    The paw force maps to the floating base through (J_P,i^W)^T (eq. (virtual_work)); the joint-torque
    rows are discarded because leg dynamics are neglected. With R_W^B = R^T:

        F_i^W = -k |v_e,i^W| v_e,i^W,      tau_i^B = [r_e,i^B]_x (R^T F_i^W)

    ``v_foot_world``: v_e,i^W, m/s; ``r_foot_body``: r_e,i^B (relative to the centre of mass), m;
    both of shape (3,) or (N, 3). ``R``: R_B^W. Returns (F_i^W in N, tau_i^B in N m), same shape.
    """
    force_world = paw_drag_force(v_foot_world, params)
    r = _finite_vectors(r_foot_body, "foot position")
    if r.shape != force_world.shape:
        raise ValueError("foot position shape %s does not match foot velocity shape %s"
                         % (r.shape, force_world.shape))
    rot = _rotation(R)
    force_body = force_world @ rot  # row-wise R^T F
    return force_world, _cross(r, force_body)


# --------------------------------------------------------------------------------------------------
# Paw buoyancy, eq. (buoy_force), (buoy_torque)
# --------------------------------------------------------------------------------------------------

def paw_buoyancy(r_feet_body: ArrayLike, R: ArrayLike, params: RobotParams) -> Tuple[np.ndarray, np.ndarray]:
    """Total net paw buoyancy wrench on the body, eq. (buoy_force), (buoy_torque).

    Each paw feels B_i^W = (g rho V_s - m_s g) z_hat at its foot position r_e,i^B, so

        F_buoyancy^W = sum_i B_i^W,      tau_buoyancy^B = sum_i [r_e,i^B]_x (R^T B_i^W).

    ``r_feet_body``: foot positions, shape (N, 3) (the robot has N = 4), m. ``R``: R_B^W.
    Returns (F_buoyancy^W in N, tau_buoyancy^B in N m), each of shape (3,).
    """
    r = _finite_vectors(r_feet_body, "foot positions")
    if r.ndim != 2:
        raise ValueError("foot positions must have shape (N, 3), got %s" % (r.shape,))
    rot = _rotation(R)
    net = params.paw_net_buoyancy
    up_body = rot[2, :]  # R^T z_hat: the world's up axis seen from the body
    count = r.shape[0]
    force_world = np.array([0.0, 0.0, net * count])
    # All B_i are equal, so sum_i r_i x (R^T B) = (sum_i r_i) x (R^T B).
    torque_body = _cross(r.sum(axis=0), net * up_body)
    return force_world, torque_body


# --------------------------------------------------------------------------------------------------
# Inertia-box body drag, eq. (inertia_box), (quad), (visc)
# --------------------------------------------------------------------------------------------------

def inertia_box(params: RobotParams) -> Tuple[float, float, float]:
    """Half-lengths (r_x, r_y, r_z) in m of the box with the body's mass and inertia, eq. (inertia_box).

    r_x = sqrt(3 / (2 m) (I_yy + I_zz - I_xx)) and cyclically. Uses the diagonal of ``params.inertia``
    (the body frame is the principal frame, section "Reference Frames"); raises
    :class:`~quadruped_common.config.ParameterError` for an inertia that no box has.
    """
    inertia = np.asarray(params.inertia, dtype=float)
    off_diagonal = inertia - np.diag(np.diag(inertia))
    if np.max(np.abs(off_diagonal)) > 1e-9 * np.max(np.abs(inertia)):
        raise ParameterError("the inertia-box drag model needs a diagonal inertia (principal body axes), "
                             "got %s" % (inertia.tolist(),))
    ixx, iyy, izz = (float(x) for x in np.diag(inertia))
    scale = 1.5 / params.mass
    squares = (scale * (iyy + izz - ixx), scale * (izz + ixx - iyy), scale * (ixx + iyy - izz))
    if min(squares) <= 0.0:
        raise ParameterError("principal moments %s give a degenerate inertia box (triangle inequality)"
                             % ((ixx, iyy, izz),))
    r_x, r_y, r_z = (math.sqrt(s) for s in squares)
    return r_x, r_y, r_z


@dataclass(frozen=True)
class BodyDragCoefficients:
    """Coefficients of the inertia-box drag, eq. (quad) and (visc), per body axis (x, y, z).

    f_i = -quad_force[i] |v_i| v_i - visc_force v_i,  g_i = -quad_torque[i] |w_i| w_i - visc_torque w_i.
    """

    quad_force: np.ndarray   # 2 rho r_j r_k, kg/m
    quad_torque: np.ndarray  # 1/2 rho r_i (r_j^4 + r_k^4), kg m^2
    visc_force: float        # 6 pi beta r_eq, kg/s
    visc_torque: float       # 8 pi beta r_eq^3, kg m^2 / s

    def forces(self, v_body: np.ndarray, omega_body: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(f_D + f_V, g_D + g_V) for body-frame v_B^B, omega_B^B (float arrays of shape (3,)); no checks."""
        force = -(self.quad_force * np.abs(v_body) + self.visc_force) * v_body
        torque = -(self.quad_torque * np.abs(omega_body) + self.visc_torque) * omega_body
        return force, torque


def body_drag_coefficients(params: RobotParams) -> BodyDragCoefficients:
    """:class:`BodyDragCoefficients` of the robot's inertia box (eq. (inertia_box)) in its fluid."""
    r = np.array(inertia_box(params))
    rho, beta = params.rho, params.beta
    r_j = r[[1, 2, 0]]  # (i, j, k) cyclic permutations of (x, y, z)
    r_k = r[[2, 0, 1]]
    r_eq = float(r.sum()) / 3.0  # Stokes sphere of eq. (visc)
    return BodyDragCoefficients(
        quad_force=2.0 * rho * r_j * r_k,
        quad_torque=0.5 * rho * r * (r_j ** 4 + r_k ** 4),
        visc_force=6.0 * math.pi * beta * r_eq,
        visc_torque=8.0 * math.pi * beta * r_eq ** 3,
    )


def body_drag(v_body: ArrayLike, omega_body: ArrayLike, params: RobotParams) -> Tuple[np.ndarray, np.ndarray]:
    """Inertia-box body drag (f_D + f_V, g_D + g_V), BOTH in the body frame, eq. (quad) + (visc).

    ``v_body``: linear velocity of the centre of mass in the body frame, v_B^B = R^T v_B^W, m/s.
    ``omega_body``: angular velocity omega_B^B, rad/s. Returns (force in N, torque in N m).
    This is MuJoCo's inertia-box fluid model (no wind) exactly; the tests compare the two.
    """
    v = _finite_vectors(v_body, "body velocity")
    w = _finite_vectors(omega_body, "body angular velocity")
    if v.shape != (3,) or w.shape != (3,):
        raise ValueError("body velocity and angular velocity must have shape (3,), got %s and %s"
                         % (v.shape, w.shape))
    return body_drag_coefficients(params).forces(v, w)
