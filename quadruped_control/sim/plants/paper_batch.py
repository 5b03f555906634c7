"""The paper's floating-base model, eq. (trans), (rot), and its SO(3) Runge-Kutta step, vectorised over trials.

:class:`PaperPlantBatch` advances N rigid-body states (p, v, R, omega) over one step with each trial's
joints held (midpoint and finite-difference rate, as :class:`~quadruped_control.sim.simulation.PlantSimulator`
holds them): the array form of :meth:`~quadruped_control.sim.plants.paper.FloatingBaseModel._rk4_held`,
the same classic RK4 in the Munthe-Kaas chart R = R0 exp(hat(xi)) and the same final Newton-Schulz polish
(:func:`~quadruped_control.sim.plants.rigid_body.chart_step_end`). Forces, per stage and trial:

- paw drag, eq. (drag), (force_leg), (torque_leg): the readable
  :func:`~quadruped_control.model.hydrodynamics.paw_drag_force_unchecked` on the body-axes foot velocities
  u_i = R^T v + omega x r_i + J_P,i q_dot_i (eq. (fb_jac); drag is rotation invariant);
- body drag, eq. (quad), (visc): :func:`~quadruped_control.model.hydrodynamics.body_drag_f`, which takes
  arrays as it takes floats;
- paw buoyancy, eq. (buoy_force), (buoy_torque), and the optional centre-of-buoyancy moment: U R^T z_hat
  with U = B_net hat(sum_i r_i) + U_cb (:func:`~quadruped_control.model.hydrodynamics.torso_buoyancy_torque_matrix`).

A trial whose kinematics fail (a five-bar that cannot close) or whose state stops being finite is
marked in ``failed`` with the step, and its state is frozen; the per-trial engine raises
:class:`~quadruped_control.sim.simulation.SimulationError` there.
"""
from __future__ import annotations

from typing import Tuple

import numpy as np

from quadruped_common.so3 import cross_rows
from quadruped_control.model import hydrodynamics
from quadruped_control.model.hydrodynamics import body_drag_f, paw_drag_force_unchecked, torso_buoyancy_torque_matrix
from quadruped_control.model.kinematics_batch import LegGeometry, leg_kinematics_batch
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.rigid_body import SMALL_ANGLE

__all__ = ["PaperPlantBatch", "chart_rate_batch", "chart_step_end_batch", "exp_rotation_batch"]


def exp_rotation_batch(xi: np.ndarray) -> np.ndarray:
    """exp(hat(xi)) (..., 3, 3) of rotation vectors (..., 3): :func:`~.rigid_body.exp_rotation` on arrays."""
    x, y, z = xi[..., 0], xi[..., 1], xi[..., 2]
    t2 = x * x + y * y + z * z
    small = t2 < SMALL_ANGLE * SMALL_ANGLE
    t = np.sqrt(np.where(small, 1.0, t2))
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(t) / t)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(t)) / np.where(small, 1.0, t2))
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    return np.stack((1.0 - b * (y * y + z * z), bxy - a * z, bxz + a * y,
                     bxy + a * z, 1.0 - b * (x * x + z * z), byz - a * x,
                     bxz - a * y, byz + a * x, 1.0 - b * (x * x + y * y)), axis=-1).reshape(xi.shape[:-1] + (3, 3))


def chart_rate_batch(xi: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """d xi / dt = J_r(xi)^-1 omega (..., 3): :func:`~.rigid_body.chart_rate` on arrays."""
    t2 = np.sum(xi * xi, axis=-1)
    small = t2 < SMALL_ANGLE * SMALL_ANGLE
    t = np.sqrt(np.where(small, 1.0, t2))
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(small, 1.0 / 12.0 + t2 / 720.0,
                     1.0 / np.where(small, 1.0, t2) - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    a = cross_rows(xi, omega)
    return omega + 0.5 * a + c[..., None] * cross_rows(xi, a)


def chart_step_end_batch(start: Tuple[np.ndarray, ...], end: Tuple[np.ndarray, ...], ok: np.ndarray,
                         failed: np.ndarray) -> Tuple[np.ndarray, ...]:
    """The end of a Runge-Kutta step in the chart of every trial: :func:`~.rigid_body.chart_step_end` on
    arrays. ``start`` (p, v, R, omega) at the step's start, ``end`` (p, v, xi, omega) at its end with
    R = R0 exp(hat(xi)), polished once by Newton-Schulz, R (3 I - R^T R) / 2. A trial whose kinematics
    failed (``ok`` False) or whose new state is not finite is marked in ``failed`` (in place) and keeps
    its start state. Returns (p, v, R, omega)."""
    p, v, R, w = start
    p1, v1, xi, w1 = end
    R1 = R @ exp_rotation_batch(xi)
    R1 = R1 @ (1.5 * np.eye(3) - 0.5 * np.einsum("nji,njk->nik", R1, R1))
    good = ok & np.isfinite(p1).all(axis=1) & np.isfinite(v1).all(axis=1) & np.isfinite(w1).all(axis=1) \
        & np.isfinite(R1).all(axis=(1, 2))
    failed |= ~good
    keep = ~good
    if keep.any():
        p1, v1, R1, w1 = p1.copy(), v1.copy(), R1.copy(), w1.copy()
        p1[keep], v1[keep], R1[keep], w1[keep] = p[keep], v[keep], R[keep], w[keep]
    return p1, v1, R1, w1


class PaperPlantBatch:
    """N copies of the paper's plant (module docstring); one robot, optional centre-of-buoyancy offset."""

    name = "paper"

    def __init__(self, robot: RobotParams, n: int, restoring_matrix: np.ndarray = None) -> None:
        self.robot = robot
        self.n = int(n)
        self.geometry = LegGeometry.from_params(robot)
        self.mass = float(robot.mass)
        self._inverse_mass = 1.0 / self.mass
        self.drag_constant = float(robot.drag_constant)
        self.inertia = np.asarray(robot.inertia, dtype=float)
        self.inertia_inverse = np.linalg.inv(self.inertia)
        self.net_paw_buoyancy = float(robot.paw_net_buoyancy)
        self.drag = hydrodynamics.body_drag_coefficients(robot).flat
        self.restoring = np.zeros((3, 3)) if restoring_matrix is None else np.asarray(restoring_matrix, dtype=float)
        self.failed = np.zeros(self.n, dtype=bool)

    @staticmethod
    def restoring_matrix(robot: RobotParams, offset) -> np.ndarray:
        """U_cb of :class:`~quadruped_control.sim.plants.paper.FloatingBaseModel`'s ``restoring_offset``."""
        return torso_buoyancy_torque_matrix(float(robot.mass) * robot.gravity, offset)

    def _stage(self, feet: np.ndarray, rates: np.ndarray, up_torque: np.ndarray, lift: float, R0: np.ndarray,
               v: np.ndarray, xi: np.ndarray, w: np.ndarray):
        """(dv/dt, dxi/dt, domega/dt) of every trial: :meth:`FloatingBaseModel._stage` on arrays."""
        R = R0 @ exp_rotation_batch(xi)
        b = np.einsum("nji,nj->ni", R, v)  # R^T v
        u = b[:, None, :] + cross_rows(w[:, None, :], feet) + rates
        force_legs = paw_drag_force_unchecked(u, self.drag_constant)  # body axes
        f = force_legs.sum(axis=1)
        tau = cross_rows(feet, force_legs).sum(axis=1)
        drag = body_drag_f(self.drag, b[:, 0], b[:, 1], b[:, 2], w[:, 0], w[:, 1], w[:, 2])
        f = f + np.stack(drag[:3], axis=1)
        tau = tau + np.stack(drag[3:], axis=1) + np.einsum("nij,nj->ni", up_torque, R[:, 2, :])
        tau = tau - cross_rows(w, w @ self.inertia.T)                       # eq. (rot)
        accel = np.einsum("nij,nj->ni", R, f)
        accel[:, 2] += lift
        return accel * self._inverse_mass, chart_rate_batch(xi, w), tau @ self.inertia_inverse.T   # eq. (trans)

    def step(self, p: np.ndarray, v: np.ndarray, R: np.ndarray, w: np.ndarray, q: np.ndarray, q_dot: np.ndarray,
             dt: float):
        """(p, v, R, omega) after ``dt`` s with joints q, q_dot (N, 4, 3) held: classic RK4 in the chart."""
        feet, rates, ok = leg_kinematics_batch(q, q_dot, self.geometry)
        # paw buoyancy matrix U = B_net hat(sum_i r_i) (+ the centre-of-buoyancy moment)
        s = self.net_paw_buoyancy * feet.sum(axis=1)
        zero = np.zeros(self.n)
        up = np.stack((zero, -s[:, 2], s[:, 1], s[:, 2], zero, -s[:, 0], -s[:, 1], s[:, 0], zero),
                      axis=1).reshape(self.n, 3, 3) + self.restoring
        lift = 4.0 * self.net_paw_buoyancy
        h = 0.5 * dt
        stage = self._stage
        # The caller silences floating-point warnings: a diverging trial is flagged below.
        zeros = np.zeros((self.n, 3))
        a1, x1, b1 = stage(feet, rates, up, lift, R, v, zeros, w)
        v2 = v + h * a1
        a2, x2, b2 = stage(feet, rates, up, lift, R, v2, h * x1, w + h * b1)
        v3 = v + h * a2
        a3, x3, b3 = stage(feet, rates, up, lift, R, v3, h * x2, w + h * b2)
        v4 = v + dt * a3
        a4, x4, b4 = stage(feet, rates, up, lift, R, v4, dt * x3, w + dt * b3)
        s6 = dt / 6.0
        p1 = p + s6 * (v + 2.0 * (v2 + v3) + v4)
        v1 = v + s6 * (a1 + 2.0 * (a2 + a3) + a4)
        xi = s6 * (x1 + 2.0 * (x2 + x3) + x4)
        w1 = w + s6 * (b1 + 2.0 * (b2 + b3) + b4)
        return chart_step_end_batch((p, v, R, w), (p1, v1, xi, w1), ok, self.failed)
