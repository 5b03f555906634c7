"""Hydrodynamic forces on the underwater quadruped (paper section "Mathematical Modeling").

- Paw drag and its transmission to the body, eq. (drag), (virtual_work), (force_leg), (torque_leg):
  :func:`paw_drag_force`, :func:`leg_wrench`; fast path :func:`paw_drag_wrench_f`.
- Net paw buoyancy and its torque on the body, eq. (buoy_force), (buoy_torque): :func:`paw_buoyancy`;
  fast path :func:`paw_buoyancy_f`. Beyond the paper, the torso's buoyancy moment about an offset
  centre of buoyancy: :func:`torso_buoyancy_torque_matrix`.
- MuJoCo's inertia-box body drag, eq. (inertia_box), (quad), (visc): :func:`inertia_box`,
  :func:`body_drag` (force and torque both in the body frame; eq. (drag_total) rotates the force to
  the world frame, which :mod:`quadruped_control.sim.plants.paper` does), computed by
  :func:`body_drag_f`.

Frames: superscript W is the ENU world frame, B the body frame (forward-left-up), R = R_B^W maps body
vectors to world vectors. All functions are pure; the per-leg functions accept one leg (shape (3,))
or a stack of legs (shape (N, 3)) and return the same leading shape.

Every force law is written here once, and the plants (:mod:`quadruped_control.sim.plants`) and the
torque estimate of :func:`quadruped_control.control.allocation.estimate_body_torque` use it. The
readable functions take and return numpy arrays in the frames the paper writes them in and check
their input. The functions ending in ``_f`` are their fast paths: plain floats in body axes, no
checks, for the integrator (four Runge-Kutta stages per 10 ms step, where numpy's per-call overhead
on 3-vectors would cost several times the arithmetic) and the controller's telemetry; the tests
compare each with its readable twin. The coefficients that depend only on the parameters are
gathered in :class:`BodyDragCoefficients` so the integrator computes them once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, NamedTuple, Sequence, Tuple, Union

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_common.jit import jitable
from quadruped_common.so3 import hat
from quadruped_common.vec3 import Mat3
from quadruped_control.model.params import RobotParams

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: Six floats of one leg: foot position r_e,i^B, then the joint-induced foot velocity J_P,i^B q_dot_i (body).
FootRow = Sequence[float]
Wrench6 = Tuple[float, float, float, float, float, float]

__all__ = [
    "BodyDragCoefficients",
    "BodyDragFloats",
    "body_drag",
    "body_drag_coefficients",
    "body_drag_f",
    "inertia_box",
    "leg_wrench",
    "paw_buoyancy",
    "paw_buoyancy_f",
    "paw_drag_force",
    "paw_drag_f",
    "paw_drag_force_unchecked",
    "paw_drag_wrench_f",
    "paw_velocity_f",
    "torso_buoyancy_torque_matrix",
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
    return paw_drag_force_unchecked(_finite_vectors(v_foot_world, "foot velocity"), params.drag_constant)


def paw_drag_force_unchecked(v: np.ndarray, drag_constant: float) -> np.ndarray:
    """eq. (drag) for foot velocities ``v`` of any shape (..., 3), without the finiteness check of
    :func:`paw_drag_force` (the batched plant, where one diverging trial must not stop the others)."""
    speed = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    return -drag_constant * speed * v


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


@jitable
def paw_velocity_f(px: float, py: float, pz: float, cx: float, cy: float, cz: float, bx: float, by: float,
                   bz: float, wx: float, wy: float, wz: float) -> Tuple[float, float, float]:
    """The paw's velocity through the water in body axes, u_i = R^T v_e,i^W = b + omega x r_i + c_i
    (eq. (fb_jac)), for the foot r_i = (px, py, pz), its joint-induced velocity c_i = (cx, cy, cz), the
    body velocity b = R^T v_B^W and rate omega_B^B."""
    return bx + wy * pz - wz * py + cx, by + wz * px - wx * pz + cy, bz + wx * py - wy * px + cz


@jitable
def paw_drag_f(px: float, py: float, pz: float, cx: float, cy: float, cz: float, drag_constant: float, bx: float,
               by: float, bz: float, wx: float, wy: float, wz: float) -> Tuple[float, float, float]:
    """eq. (drag), (force_leg) on floats, body axes: R^T F_i^W = -k |u_i| u_i for the paw's velocity
    u_i of :func:`paw_velocity_f` (foot r_i = (px, py, pz), joint-induced velocity c_i, body velocity b,
    rate omega); the drag is rotation invariant. The one implementation of the paw drag on floats."""
    ux, uy, uz = paw_velocity_f(px, py, pz, cx, cy, cz, bx, by, bz, wx, wy, wz)
    s = -drag_constant * math.sqrt(ux * ux + uy * uy + uz * uz)
    return s * ux, s * uy, s * uz


@jitable
def paw_drag_wrench_f(feet: Iterable[FootRow], drag_constant: float, bx: float, by: float, bz: float,
                      wx: float, wy: float, wz: float) -> Wrench6:
    """Fast path of :func:`leg_wrench` summed over the legs, on floats: eq. (drag), (force_leg),
    (torque_leg) in body axes, (sum_i R^T F_i^W, sum_i tau_i^B).

    ``feet``: one row (r_x, r_y, r_z, c_x, c_y, c_z) per leg, the foot position r_e,i^B and the
    joint-induced foot velocity c_i = J_P,i^B q_dot_i; (bx, by, bz) = R^T v_B^W, the body velocity in body
    axes; (wx, wy, wz) = omega_B^B. The foot velocity in body axes is u_i = R^T v_e,i^W =
    b + omega x r_i + c_i (eq. (fb_jac)); the drag is rotation invariant, so R^T F_i^W = -k |u_i| u_i
    and tau_i^B = r_i x (R^T F_i^W). No input checks (the integrator's stages and the controller's
    torque estimate call it on values they built).
    """
    fx = fy = fz = tx = ty = tz = 0.0
    for px, py, pz, cx, cy, cz in feet:
        gx, gy, gz = paw_drag_f(px, py, pz, cx, cy, cz, drag_constant, bx, by, bz, wx, wy, wz)
        fx += gx
        fy += gy
        fz += gz
        tx += py * gz - pz * gy                                # eq. (torque_leg)
        ty += pz * gx - px * gz
        tz += px * gy - py * gx
    return fx, fy, fz, tx, ty, tz


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


@jitable
def paw_buoyancy_f(feet: Sequence[FootRow], net_paw_buoyancy: float) -> Tuple[float, Mat3]:
    """Fast path of :func:`paw_buoyancy`, eq. (buoy_force), (buoy_torque), on floats, for legs held over
    an integration step: (F_z, U) with F_buoyancy^W = (0, 0, F_z) and tau_buoyancy^B = U (R^T z_hat).

    ``feet``: rows whose first three floats are r_e,i^B (the rows of :func:`paw_drag_wrench_f`);
    ``net_paw_buoyancy``: B_net = g rho V_s - m_s g of one paw, N. U = B_net hat(sum_i r_i) (a
    :class:`~quadruped_common.vec3.Mat3`): the torque (sum_i r_i) x (R^T B_net z_hat) is linear in
    R^T z_hat, so the integrator forms U once per step and the stages only multiply it by the third row
    of R.
    """
    sx = sy = sz = 0.0
    for foot in feet:
        sx += foot[0]
        sy += foot[1]
        sz += foot[2]
    sx *= net_paw_buoyancy
    sy *= net_paw_buoyancy
    sz *= net_paw_buoyancy
    return len(feet) * net_paw_buoyancy, Mat3(0.0, -sz, sy, sz, 0.0, -sx, -sy, sx, 0.0)


def torso_buoyancy_torque_matrix(buoyancy: float, center_of_buoyancy: ArrayLike) -> np.ndarray:
    """U_cb = B hat(r_cb): the torso buoyancy B (N) acting at the centre of buoyancy r_cb^B (m, body frame,
    relative to the centre of mass) gives the moment r_cb x (R^T [0, 0, B]) = U_cb (R^T z_hat) about the
    centre of mass (N m, body frame).

    Not in the paper, whose centre of buoyancy is at the centre of mass (section "Body Dynamics"): the
    restoring torque of the paper plant's optional centre-of-buoyancy offset and of the tank plant's
    hydrostatics. A matrix because R^T z_hat (the third row of R) is what changes from step to step.
    """
    return float(buoyancy) * hat(_finite_vectors(center_of_buoyancy, "center_of_buoyancy").reshape(3))


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


class BodyDragFloats(NamedTuple):
    """:class:`BodyDragCoefficients` as floats, in the order :func:`body_drag_f` takes them: the quadratic
    force (q_x, q_y, q_z) and torque (p_x, p_y, p_z) coefficients, then the viscous c_f and c_g."""

    q_x: float
    q_y: float
    q_z: float
    p_x: float
    p_y: float
    p_z: float
    c_f: float
    c_g: float


@dataclass(frozen=True)
class BodyDragCoefficients:
    """Coefficients of the inertia-box drag, eq. (quad) and (visc), per body axis (x, y, z).

    f_i = -quad_force[i] |v_i| v_i - visc_force v_i,  g_i = -quad_torque[i] |w_i| w_i - visc_torque w_i.
    """

    quad_force: np.ndarray   # 2 rho r_j r_k, kg/m
    quad_torque: np.ndarray  # 1/2 rho r_i (r_j^4 + r_k^4), kg m^2
    visc_force: float        # 6 pi beta r_eq, kg/s
    visc_torque: float       # 8 pi beta r_eq^3, kg m^2 / s

    @property
    def flat(self) -> BodyDragFloats:
        """The eight coefficients as floats, in the order :func:`body_drag_f` takes them."""
        return BodyDragFloats(*self.quad_force.tolist(), *self.quad_torque.tolist(), self.visc_force,
                              self.visc_torque)


@jitable
def body_drag_f(coefficients: Sequence[float], bx: float, by: float, bz: float, wx: float, wy: float,
                wz: float) -> Wrench6:
    """The inertia-box body drag (f_D + f_V, g_D + g_V), eq. (quad) + (visc), on floats, body frame:
    the one implementation, behind :func:`body_drag` and the integrator's stages.

    ``coefficients``: :attr:`BodyDragCoefficients.flat` (q_x, q_y, q_z, p_x, p_y, p_z, c_f, c_g);
    (bx, by, bz) = v_B^B, (wx, wy, wz) = omega_B^B, floats or arrays of the same shape. No input checks.
    """
    qf0, qf1, qf2, qg0, qg1, qg2, cf, cg = coefficients
    # Plain arithmetic and abs(): the same code runs on floats (the plants' stages) and on arrays of
    # one value per trial (the batched plant, :mod:`quadruped_control.sim.plants.paper_batch`).
    return (-(qf0 * abs(bx) + cf) * bx,
            -(qf1 * abs(by) + cf) * by,
            -(qf2 * abs(bz) + cf) * bz,
            -(qg0 * abs(wx) + cg) * wx,
            -(qg1 * abs(wy) + cg) * wy,
            -(qg2 * abs(wz) + cg) * wz)


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
    wrench = body_drag_f(body_drag_coefficients(params).flat, *(v.tolist() + w.tolist()))
    return np.array(wrench[:3]), np.array(wrench[3:])
