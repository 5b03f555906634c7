"""Torque allocation and foot velocity commands (paper section "Torque Allocation and Foot Velocity").

The saturated body torque tau_sat of eq. (sat) is split equally among the four legs,
tau_i^B = tau_sat / 4. Each leg produces its share as the torque r_i x F_i of its paw drag
(eq. (torque_leg)), so the drag force must be perpendicular to both r_i = r_e,i^B and tau_i:

    f_i = tau_hat_i x r_hat_i                                 (force direction, as written in the paper)
    v_i = sqrt(|tau_i^B| / (k |r_e,i^B|))                      eq. (foot_speed)
    v_i^cmd = -f_i v_i - omega_B^B x r_e,i^B                   eq. (foot_vel)

where k = 1/2 rho C_D A (eq. (force_leg)). eq. (foot_speed) follows from eq. (torque_leg) with the
foot velocity orthogonal to r_i: |tau_i| = k |v|^2 |r_i|.

Why the minus sign: the paw drag opposes the foot's velocity through the water, F = -k |v| v
(eq. (force_leg)). With v = -f v_i the drag is +k |v| v_i f, and r_i x f = |r_i| r_hat x (tau_hat x r_hat)
points along tau_i. The term -omega x r cancels the foot velocity that the body rotation itself
causes (eq. (ee_vel): v_e^W = R (omega x r + J q_dot) for a body at rest in translation), so the foot
moves through the water with -f v_i whatever omega is.

Decision (configurable): f_i as written is NOT a unit vector unless tau_i is orthogonal to r_i; its norm
is sin(angle(tau_i, r_i)). As written, leg i then delivers sin(a) * (component of tau_i perpendicular to
r_i), i.e. magnitude sin^2(a) |tau_i|. With ``normalize=True`` f_i is divided by its norm and the leg
delivers the component of tau_i perpendicular to r_i scaled to the full magnitude |tau_i|. A leg cannot
produce torque about its own r_i (drag acts at the foot), so in both variants the delivered torque is
along the perpendicular component of tau_i. Degenerate cases (zero torque, foot at the body origin,
foot on the torque axis) give a zero force direction and zero speed, never NaN.

:func:`estimate_body_torque` evaluates eq. (torque_leg) from measured joint motion (telemetry, and
the way the paper estimated tau_max) with the paw drag law of :mod:`quadruped_control.model.hydrodynamics`.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.jit import hypot3, jitable

from quadruped_control.model.hydrodynamics import paw_drag_wrench_f
from quadruped_control.model.kinematics import leg_kinematics
from quadruped_control.model.params import RobotParams

ArrayLike = Union[Sequence[float], np.ndarray]
Vec3 = Tuple[float, float, float]

__all__ = [
    "MIN_ARM",
    "MIN_SIN",
    "MIN_TORQUE",
    "allocate",
    "estimate_body_torque",
    "foot_speed",
    "foot_velocity_command",
    "force_direction",
    "leg_torques",
]

#: Torques below this norm (N m) are treated as zero: no stroke.
MIN_TORQUE = 1e-12
#: Foot positions closer than this to the body origin (m) cannot produce torque.
MIN_ARM = 1e-9
#: |tau_hat x r_hat| below this: the foot lies on the torque axis and cannot produce that torque.
MIN_SIN = 1e-9


def _floats3(value: ArrayLike, name: str) -> Vec3:
    values = value.tolist() if isinstance(value, np.ndarray) else list(value)
    if len(values) != 3:
        raise ValueError("%s must have 3 elements, got %d" % (name, len(values)))
    x, y, z = float(values[0]), float(values[1]), float(values[2])
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise ValueError("%s has non-finite elements: %r" % (name, (x, y, z)))
    return x, y, z


@jitable
def _norm(x: float, y: float, z: float) -> float:
    return hypot3(x, y, z)


def _check_drag_constant(drag_constant: float) -> float:
    k = float(drag_constant)
    if not (math.isfinite(k) and k > 0.0):
        raise ValueError("drag constant k must be a positive finite number, got %r" % (drag_constant,))
    return k


# --------------------------------------------------------------------------------------------------
# Float kernels (no validation; used by the controller's hot path and by the public wrappers)
# --------------------------------------------------------------------------------------------------

@jitable
def force_direction_f(tx: float, ty: float, tz: float, rx: float, ry: float, rz: float,
                      normalize: bool) -> Vec3:
    """f = tau_hat x r_hat (optionally normalised) on floats; zero in the degenerate cases."""
    nt = _norm(tx, ty, tz)
    nr = _norm(rx, ry, rz)
    if nt < MIN_TORQUE or nr < MIN_ARM:
        return 0.0, 0.0, 0.0
    tx, ty, tz = tx / nt, ty / nt, tz / nt
    rx, ry, rz = rx / nr, ry / nr, rz / nr
    fx, fy, fz = ty * rz - tz * ry, tz * rx - tx * rz, tx * ry - ty * rx
    sin_angle = _norm(fx, fy, fz)
    if sin_angle < MIN_SIN:
        return 0.0, 0.0, 0.0
    if normalize:
        return fx / sin_angle, fy / sin_angle, fz / sin_angle
    return fx, fy, fz


@jitable
def foot_speed_f(torque_norm: float, arm: float, drag_constant: float) -> float:
    """eq. (foot_speed) on floats: sqrt(|tau_i| / (k |r_i|)); 0 for zero torque or zero arm."""
    if torque_norm < MIN_TORQUE or arm < MIN_ARM:
        return 0.0
    return math.sqrt(torque_norm / (drag_constant * arm))


@jitable
def foot_velocity_command_f(tau: Vec3, r: Vec3, omega: Vec3, drag_constant: float, normalize: bool) -> Vec3:
    """eq. (foot_vel) on floats: -f v - omega x r (leg torque ``tau`` already divided among the legs)."""
    tx, ty, tz = tau
    rx, ry, rz = r
    wx, wy, wz = omega
    fx, fy, fz = force_direction_f(tx, ty, tz, rx, ry, rz, normalize)
    if fx == 0.0 and fy == 0.0 and fz == 0.0:
        speed = 0.0
    else:
        speed = foot_speed_f(_norm(tx, ty, tz), _norm(rx, ry, rz), drag_constant)
    return (-fx * speed - (wy * rz - wz * ry),
            -fy * speed - (wz * rx - wx * rz),
            -fz * speed - (wx * ry - wy * rx))


# --------------------------------------------------------------------------------------------------
# Public API (validated, numpy in and out)
# --------------------------------------------------------------------------------------------------

def leg_torques(tau_sat: ArrayLike, n_legs: int = 4) -> np.ndarray:
    """Equal split of the saturated torque, tau_i^B = tau_sat / n_legs (paper: n = 4). Shape (n_legs, 3)."""
    if isinstance(n_legs, bool) or not isinstance(n_legs, int) or n_legs < 1:
        raise ValueError("n_legs must be a positive integer, got %r" % (n_legs,))
    tau = np.array(_floats3(tau_sat, "tau_sat"))
    return np.tile(tau / n_legs, (n_legs, 1))


def force_direction(tau_i: ArrayLike, r_i: ArrayLike, normalize: bool = False) -> np.ndarray:
    """Drag-force direction f_i = tau_hat_i x r_hat_i (section "Torque Allocation and Foot Velocity").

    As written (``normalize=False``) |f_i| = sin(angle(tau_i, r_i)) <= 1; ``normalize=True`` returns the
    unit vector. Zero vector if tau_i ~ 0, r_i ~ 0 or tau_i parallel to r_i (no torque is possible).
    """
    tx, ty, tz = _floats3(tau_i, "tau_i")
    rx, ry, rz = _floats3(r_i, "r_i")
    return np.array(force_direction_f(tx, ty, tz, rx, ry, rz, bool(normalize)))


def foot_speed(tau_i: ArrayLike, r_i: ArrayLike, drag_constant: float) -> float:
    """Required paw speed v_i = sqrt(|tau_i^B| / (k |r_e,i^B|)), eq. (foot_speed), m/s.

    From eq. (torque_leg) with the foot velocity orthogonal to r_i: |tau_i| = k v_i^2 |r_i|.
    ``drag_constant`` is k = 1/2 rho C_D A (``RobotParams.drag_constant``). 0 for zero torque or a foot
    at the body origin.
    """
    tau = _floats3(tau_i, "tau_i")
    r = _floats3(r_i, "r_i")
    return foot_speed_f(_norm(*tau), _norm(*r), _check_drag_constant(drag_constant))


def foot_velocity_command(tau_i: ArrayLike, r_i: ArrayLike, omega: ArrayLike, drag_constant: float,
                          normalize: bool = False) -> np.ndarray:
    """Foot velocity command in the body frame, v_i^cmd = -f_i v_i - omega_B^B x r_e,i^B, eq. (foot_vel).

    ``tau_i``: this leg's torque share tau_i^B (N m); ``r_i``: foot position r_e,i^B (m); ``omega``:
    body angular velocity omega_B^B (rad/s); ``drag_constant``: k. The first term makes the paw drag
    produce tau_i (see the module docstring for the exact torque delivered), the second cancels the foot
    velocity caused by the body rotation. Never NaN for finite input.
    """
    tau = _floats3(tau_i, "tau_i")
    r = _floats3(r_i, "r_i")
    w = _floats3(omega, "omega")
    return np.array(foot_velocity_command_f(tau, r, w, _check_drag_constant(drag_constant), bool(normalize)))


def allocate(tau_sat: ArrayLike, feet: ArrayLike, omega: ArrayLike, drag_constant: float,
             normalize: bool = False) -> np.ndarray:
    """Foot velocity commands (4, 3) for all legs: equal split of ``tau_sat`` then eq. (foot_vel) per leg.

    ``feet``: foot positions r_e,i^B, shape (4, 3), rows legs 1..4.
    """
    feet_arr = np.asarray(feet, dtype=float)
    if feet_arr.ndim != 2 or feet_arr.shape[1] != 3:
        raise ValueError("feet must have shape (N, 3), got %s" % (feet_arr.shape,))
    shares = leg_torques(tau_sat, feet_arr.shape[0])
    w = _floats3(omega, "omega")
    k = _check_drag_constant(drag_constant)
    out = np.empty_like(feet_arr)
    for row in range(feet_arr.shape[0]):
        out[row] = foot_velocity_command_f(tuple(shares[row].tolist()), _floats3(feet_arr[row], "foot position"),
                                           w, k, bool(normalize))
    return out


def estimate_body_torque(q: ArrayLike, q_dot: ArrayLike, R: ArrayLike, omega: ArrayLike, robot: RobotParams,
                         v_body_world: Optional[ArrayLike] = None) -> np.ndarray:
    """Body-frame torque of the paw drag, eq. (torque_leg) summed over the four legs, N m.

    The foot velocities follow eq. (ee_vel), (fb_jac): v_e,i^W = v_B^W + R (omega x r_i + J_P,i^B q_dot_i).
    ``q``, ``q_dot``: measured joint angles and velocities (4, 3) (legs 1..4; theta1, theta2, theta3);
    ``R``: R_B^W; ``omega``: omega_B^B; ``v_body_world``: v_B^W (default zero: the robot hangs from a rope
    and the paper estimated tau_max from IMU rates and joint velocities only). Telemetry: this is how the
    paper estimated tau_max (section "Control Law").
    """
    q_arr = np.asarray(q, dtype=float).reshape(-1)
    q_dot_arr = np.asarray(q_dot, dtype=float).reshape(-1)
    if q_arr.shape != (12,) or q_dot_arr.shape != (12,):
        raise ValueError("q and q_dot must have 12 elements (4 legs x 3 joints), got %s and %s"
                         % (np.shape(q), np.shape(q_dot)))
    if not (np.all(np.isfinite(q_arr)) and np.all(np.isfinite(q_dot_arr))):
        raise ValueError("q and q_dot must be finite")
    rot = np.asarray(R, dtype=float)
    if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
        raise ValueError("R must be a finite 3x3 rotation matrix")
    wx, wy, wz = _floats3(omega, "omega")
    if v_body_world is None:
        bx = by = bz = 0.0
    else:  # R^T v_B^W: the body velocity in body axes
        vx, vy, vz = _floats3(v_body_world, "v_body_world")
        (r0, r1, r2), (r3, r4, r5), (r6, r7, r8) = rot.tolist()
        bx, by, bz = r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz
    # Foot positions r_i and joint-induced velocities J_P,i^B q_dot_i of all legs in one float pass
    # (kinematics.leg_kinematics), then the paw drag torques summed in body axes (the drag is rotation
    # invariant): hydrodynamics.paw_drag_wrench_f, the float twin of hydrodynamics.leg_wrench.
    feet = leg_kinematics(q_arr.reshape(4, 3).tolist(), q_dot_arr.reshape(4, 3).tolist(), robot)
    _, _, _, tx, ty, tz = paw_drag_wrench_f(feet, robot.drag_constant, bx, by, bz, wx, wy, wz)
    return np.array([tx, ty, tz])
