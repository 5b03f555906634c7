"""The test-tank plant of :mod:`quadruped_control.sim.plants.tank`, vectorised over trials.

:class:`TankPlantBatch` is :class:`~quadruped_control.sim.plants.tank.TankModel` for N trials, each with
its own :class:`~quadruped_control.sim.plants.tank.TankParams` (the identification's parameter sets):
eq. (tank) with the paper's forces, the rope, the torso's weight and buoyancy, the torso's and the
paws' added mass and the candidate effects (appendage damping, rope torsion), integrated with the same
classic RK4 in the SO(3) chart as the per-trial plant (``FloatingBaseModel._rk4`` with the tank's
``_chart_derivative``). Every per-trial constant (drag constant, body-drag coefficients, torso
buoyancy and weight, the M_RB + M_A mass matrix, paw added mass) is read from a
:class:`~quadruped_control.sim.plants.tank.TankModel` built for that trial, so the batch and the
per-trial plant share their set-up; the equations of :meth:`TankModel.generalized_forces` are written
here on arrays (the tests compare the two trial by trial). The 6x6 mass matrix is solved with
numpy.linalg.solve instead of the per-trial Schur complement (the same solution to rounding).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from quadruped_common.so3 import cross_rows
from quadruped_control.model.hydrodynamics import body_drag_f, paw_drag_force_unchecked
from quadruped_control.model.kinematics_batch import LegGeometry, leg_kinematics_batch
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.paper_batch import chart_rate_batch, chart_step_end_batch, exp_rotation_batch
from quadruped_control.sim.plants.tank import TankModel, TankParams

__all__ = ["TankPlantBatch"]


def _hat(s: np.ndarray) -> np.ndarray:
    """hat(s) (N, 3, 3) of vectors (N, 3)."""
    zero = np.zeros(s.shape[0])
    return np.stack((zero, -s[:, 2], s[:, 1], s[:, 2], zero, -s[:, 0], -s[:, 1], s[:, 0], zero),
                    axis=1).reshape(-1, 3, 3)


def _apply(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """M x row by row: (N, 3, 3) times (N, 3)."""
    return np.einsum("nij,nj->ni", M, x)


class TankPlantBatch:
    """N tank plants (module docstring); ``tanks``: one TankParams per trial."""

    name = "tank"

    def __init__(self, robot: RobotParams, tanks: Sequence[TankParams]) -> None:
        models = [TankModel(robot, tank) for tank in tanks]
        n = len(models)
        self.n = n
        self.robot = robot
        self.models = models
        self.geometry = LegGeometry.from_params(robot)
        self.net_paw_buoyancy = float(robot.paw_net_buoyancy)
        self.drag_constant = np.array([m.drag_constant for m in models])[:, None, None]
        drag = np.array([m._drag for m in models])  # noqa: SLF001 (the model's float coefficients)
        self.body_drag = tuple(drag[:, i] for i in range(8))
        self.restoring = np.array([m._restoring_matrix for m in models])  # noqa: SLF001
        self.extra_lift = np.array([(m.torso_buoyancy - m.torso_weight) if m.tank.hydrostatics else 0.0
                                    for m in models])
        self.suspension = np.array([m.tank.suspension for m in models])
        self.hook = np.array([m.tank.hook for m in models], dtype=float)
        self.rope_length = np.array([m.tank.rope_length for m in models])
        self.rope_stiffness = np.array([m.tank.rope_stiffness for m in models])
        self.rope_damping = np.array([m.tank.rope_damping for m in models])
        self.torsion_stiffness = np.where(self.suspension, [m.tank.rope_torsion_stiffness for m in models], 0.0)
        self.torsion_damping = np.where(self.suspension, [m.tank.rope_torsion_damping for m in models], 0.0)
        self.appendage_linear = np.array([m.tank.appendage_damping_linear for m in models], dtype=float)
        self.appendage_quadratic = np.array([m.tank.appendage_damping_quadratic for m in models], dtype=float)
        self.body_mass = np.array([m.body_mass_matrix for m in models])
        self.paw_added_mass = np.array([m.paw_added_mass for m in models])
        self.anchor = np.zeros((n, 3))
        self.untwisted = np.tile(np.eye(3), (n, 1, 1))
        self.failed = np.zeros(n, dtype=bool)

    def attach(self, position: np.ndarray, rotation: np.ndarray) -> None:
        """:meth:`TankModel.attach` of every trial: anchor above the hook, rope untwisted at this attitude."""
        for i, model in enumerate(self.models):
            hook = position[i] + rotation[i] @ model.hook
            stretch = model.static_rope_tension() / model.tank.rope_stiffness
            self.anchor[i] = hook + np.array([0.0, 0.0, model.tank.rope_length + stretch])
        self.untwisted = np.array(rotation, dtype=float)

    def _forces(self, feet, rates, sums, p, v, R, w):
        """:meth:`TankModel.generalized_forces` of every trial: (force, torque) (N, 3) each, body axes."""
        b = np.einsum("nji,nj->ni", R, v)  # R^T v
        up = R[:, 2, :]  # R^T z_hat
        u = b[:, None, :] + cross_rows(w[:, None, :], feet) + rates
        force_legs = paw_drag_force_unchecked(u, self.drag_constant)  # eq. (drag), body axes
        f = force_legs.sum(axis=1)
        tau = cross_rows(feet, force_legs).sum(axis=1)
        drag = body_drag_f(self.body_drag, b[:, 0], b[:, 1], b[:, 2], w[:, 0], w[:, 1], w[:, 2])
        f = f + np.stack(drag[:3], axis=1)
        sr, sc, S, P, rc = sums
        up_torque = self.net_paw_buoyancy * _hat(sr) + self.restoring  # paw buoyancy + torso moment: U
        tau = tau + np.stack(drag[3:], axis=1) + _apply(up_torque, up)
        lift = 4.0 * self.net_paw_buoyancy + self.extra_lift
        f = f + lift[:, None] * up
        # the rope: tension only, from the hook to the anchor
        if self.suspension.any():
            h = self.hook
            hook_world = p + _apply(R, h)
            hook_velocity = v + _apply(R, cross_rows(w, h))
            d = self.anchor - hook_world
            distance = np.sqrt(np.sum(d * d, axis=1))
            taut = self.suspension & (distance > self.rope_length)
            unit = d / np.where(taut, distance, 1.0)[:, None]
            rate = -np.sum(unit * hook_velocity, axis=1)
            tension = self.rope_stiffness * (distance - self.rope_length) + self.rope_damping * rate
            tension = np.where(taut & (tension > 0.0), tension, 0.0)
            Fb = np.einsum("nji,nj->ni", R, tension[:, None] * unit)  # R^T F
            f = f + Fb
            tau = tau + cross_rows(h, Fb)
            twisting = (self.torsion_stiffness > 0.0) | (self.torsion_damping > 0.0)
            if twisting.any():
                Q = np.einsum("nij,nkj->nik", R, self.untwisted)  # R R0^T
                twist = 2.0 * np.arctan2(Q[:, 1, 0] - Q[:, 0, 1], 1.0 + np.trace(Q, axis1=1, axis2=2))
                torque = -(self.torsion_stiffness * twist + self.torsion_damping * np.sum(up * w, axis=1))
                tau = tau + np.where(twisting, torque, 0.0)[:, None] * up
        tau = tau - (self.appendage_linear + self.appendage_quadratic * np.abs(w)) * w
        # Kirchhoff terms of M_RB + M_A: [omega x p; v x p + omega x h], [p; h] = M nu
        ph = np.einsum("nij,nj->ni", self.body_mass, np.concatenate((b, w), axis=1))
        f = f - cross_rows(w, ph[:, :3])
        tau = tau - cross_rows(b, ph[:, :3]) - cross_rows(w, ph[:, 3:])
        ma = self.paw_added_mass[:, None]
        wv = cross_rows(w, b)
        f = f - ma * (4.0 * wv + cross_rows(w, cross_rows(w, sr)) + 2.0 * cross_rows(w, sc))
        tau = tau - ma * (cross_rows(sr, wv) + cross_rows(_apply(S, w), w) + 2.0 * (w * rc[:, None] - _apply(P, w)))
        return b, f, tau

    def _derivative(self, feet, rates, sums, mass, R0, p, v, xi, w):
        R = R0 @ exp_rotation_batch(xi)
        b, f, tau = self._forces(feet, rates, sums, p, v, R, w)
        nu_dot = np.linalg.solve(mass, np.concatenate((f, tau), axis=1)[..., None])[..., 0]
        a = nu_dot[:, :3] + cross_rows(w, b)
        return v, _apply(R, a), chart_rate_batch(xi, w), nu_dot[:, 3:]

    def step(self, p: np.ndarray, v: np.ndarray, R: np.ndarray, w: np.ndarray, q: np.ndarray, q_dot: np.ndarray,
             dt: float):
        """(p, v, R, omega) after ``dt`` s with joints q, q_dot (N, 4, 3) held: the tank's RK4 in the chart."""
        feet, rates, ok = leg_kinematics_batch(q, q_dot, self.geometry)
        sr, sc = feet.sum(axis=1), rates.sum(axis=1)
        S = np.einsum("nli,nlj->nij", feet, feet)
        P = np.einsum("nli,nlj->nij", rates, feet)
        rc = np.sum(feet * rates, axis=(1, 2))
        sums = (sr, sc, S, P, rc)
        # M = M_RB + M_A + m_a [[4 I, -hat(sr)], [hat(sr), tr(S) I - S]] (the paws' point added masses)
        ma = self.paw_added_mass[:, None, None]
        mass = self.body_mass.copy()
        H = _hat(sr)
        mass[:, :3, :3] += ma * 4.0 * np.eye(3)
        mass[:, :3, 3:] -= ma * H
        mass[:, 3:, :3] += ma * H
        mass[:, 3:, 3:] += ma * (np.trace(S, axis1=1, axis2=2)[:, None, None] * np.eye(3) - S)
        h = 0.5 * dt
        d = self._derivative
        zeros = np.zeros((self.n, 3))
        k1 = d(feet, rates, sums, mass, R, p, v, zeros, w)
        k2 = d(feet, rates, sums, mass, R, p + h * k1[0], v + h * k1[1], h * k1[2], w + h * k1[3])
        k3 = d(feet, rates, sums, mass, R, p + h * k2[0], v + h * k2[1], h * k2[2], w + h * k2[3])
        k4 = d(feet, rates, sums, mass, R, p + dt * k3[0], v + dt * k3[1], dt * k3[2], w + dt * k3[3])
        s6 = dt / 6.0
        new = [y + s6 * (a + 2.0 * (b_ + c) + e) for y, a, b_, c, e in zip((p, v, zeros, w), k1, k2, k3, k4)]
        return chart_step_end_batch((p, v, R, w), tuple(new), ok, self.failed)
