"""The paper's floating-base model, eq. (trans), (rot), and its SO(3) Runge-Kutta step, for N trials.

:class:`PaperPlantBatch` advances N rigid-body states (p, v, R, omega) over one step with each trial's
joints held (midpoint and finite-difference rate, as :class:`~quadruped_control.sim.simulation.PlantSimulator`
holds them). It runs the per-trial plant's own functions: a loop over the trials (:func:`paper_batch_step`,
compiled by numba when it is installed, :mod:`quadruped_common.jit`) calls, per trial,

- :func:`~quadruped_control.model.kinematics.leg_row` for each leg (eq. (fk_EFG) .. (ee_body), (J_leg)),
- :func:`~quadruped_control.model.hydrodynamics.paw_buoyancy_f` (eq. (buoy_force), (buoy_torque)) plus
  the optional centre-of-buoyancy moment,
- :func:`~quadruped_control.sim.plants.paper.paper_rk4_held`: the classic RK4 in the Munthe-Kaas chart
  R = R0 exp(hat(xi)) of :meth:`~quadruped_control.sim.plants.paper.FloatingBaseModel.step`, whose stages
  are :func:`~quadruped_control.sim.plants.paper.paper_stage` (paw drag, body drag, buoyancy, eq. (rot)),
- :func:`~quadruped_control.sim.plants.rigid_body.polish`: the final Newton-Schulz step.

So the batch and the per-trial plant share every equation; the tests compare them trial by trial.

A trial whose kinematics fail (a five-bar that cannot close) or whose state stops being finite is
marked in ``failed`` and its state is frozen from then on; the per-trial engine raises
:class:`~quadruped_control.sim.simulation.SimulationError` there.
"""
from __future__ import annotations

import math

import numpy as np

from quadruped_common.jit import jitable, kernel, trial_step
from quadruped_control.model import hydrodynamics
from quadruped_control.model.hydrodynamics import paw_buoyancy_f, torso_buoyancy_torque_matrix
from quadruped_control.model.kinematics import _geometry, leg_row
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.paper import paper_rk4_held
from quadruped_control.sim.plants.rigid_body import as_mat3, exp_rotation, matmul, polish

__all__ = ["PaperPlantBatch", "held_step_inputs", "leg_geometry", "leg_rows", "paper_batch_step", "paper_trial_step",
           "store_step_end"]


def leg_geometry(robot: RobotParams):
    """(frames (4, 6) array, five-bar and hip constants (a1, a2, a3, a4, c, l_y, l_z)) of
    :func:`~quadruped_control.model.kinematics.leg_row`, in the order of the legs."""
    geometry = _geometry(robot)
    return np.array(geometry.frame_rows, dtype=float), geometry.five_bar_hip


@jitable
def leg_rows(q, q_dot, i, frames, five_bar, feet) -> bool:
    """The legs' rows (r_e,i^B, J_P,i^B q_dot_i) of trial ``i`` into ``feet`` (4, 6); False if a
    five-bar cannot close or is singular."""
    a1, a2, a3, a4, c, l_y, l_z = five_bar
    ok = True
    for leg in range(4):
        good, x, y, z, vx, vy, vz = leg_row(q[i, leg, 0], q[i, leg, 1], q[i, leg, 2], q_dot[i, leg, 0],
                                            q_dot[i, leg, 1], q_dot[i, leg, 2], frames[leg], a1, a2, a3, a4, c,
                                            l_y, l_z)
        ok = ok and good
        feet[leg, 0] = x
        feet[leg, 1] = y
        feet[leg, 2] = z
        feet[leg, 3] = vx
        feet[leg, 4] = vy
        feet[leg, 5] = vz
    return ok


@jitable
def held_step_inputs(q, q_dot, i, frames, five_bar, net_paw_buoyancy, restoring, R, feet):
    """What a held step of trial ``i`` needs before its stages: (ok, lift, U, R0) with the legs' rows
    in ``feet`` (:func:`leg_rows`; ``ok`` False if a five-bar fails), the paw buoyancy force and torque
    matrix (:func:`~quadruped_control.model.hydrodynamics.paw_buoyancy_f`) plus the trial's
    centre-of-buoyancy moment ``restoring[i]``, and R0 = R[i] as a row-major 9-tuple."""
    ok = leg_rows(q, q_dot, i, frames, five_bar, feet)
    lift, U = paw_buoyancy_f(feet, net_paw_buoyancy)
    r = restoring[i]
    up = (U[0] + r[0, 0], U[1] + r[0, 1], U[2] + r[0, 2], U[3] + r[1, 0], U[4] + r[1, 1], U[5] + r[1, 2],
          U[6] + r[2, 0], U[7] + r[2, 1], U[8] + r[2, 2])
    R0 = (R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2], R[i, 2, 0], R[i, 2, 1], R[i, 2, 2])
    return ok, lift, up, R0


@jitable
def store_step_end(y, R0, i, p, v, R, w) -> bool:
    """Write the chart state ``y`` = (p, v, xi, omega) at a step's end into row ``i`` of the state arrays,
    with R = polish(R0 exp(hat(xi))) (:func:`~quadruped_control.sim.plants.rigid_body.chart_step_end`);
    False, and nothing written, if a value is not finite."""
    R1 = polish(matmul(R0, exp_rotation(y[6], y[7], y[8])))
    total = 0.0
    for value in y:
        total += value
    for value in R1:
        total += value
    if not math.isfinite(total):
        return False
    for k in range(3):
        p[i, k] = y[k]
        v[i, k] = y[3 + k]
        w[i, k] = y[9 + k]
        for j in range(3):
            R[i, k, j] = R1[3 * k + j]
    return True


@trial_step
def paper_trial_step(i, frames, five_bar, drag_constant, drag, inertia, inertia_inverse, inverse_mass,
                     net_paw_buoyancy, restoring, p, v, R, w, q, q_dot, dt, feet) -> bool:
    """One held-input RK4 step of trial ``i`` in place; False if it failed (module docstring)."""
    ok, lift, up, R0 = held_step_inputs(q, q_dot, i, frames, five_bar, net_paw_buoyancy, restoring, R, feet)
    if not ok:
        return False
    y = paper_rk4_held(feet, drag_constant, drag, up, lift, inertia, inertia_inverse, inverse_mass, R0,
                       p[i, 0], p[i, 1], p[i, 2], v[i, 0], v[i, 1], v[i, 2], w[i, 0], w[i, 1], w[i, 2], dt)
    return store_step_end(y, R0, i, p, v, R, w)


@kernel
def paper_batch_step(frames, five_bar, drag_constant, drag, inertia, inertia_inverse, inverse_mass,
                     net_paw_buoyancy, restoring, p, v, R, w, q, q_dot, dt, failed):
    """One held-input RK4 step of every trial not yet ``failed``, in place on p, v, w (N, 3) and R (N, 3, 3)
    (module docstring). ``restoring`` (N, 3, 3): each trial's centre-of-buoyancy moment matrix."""
    feet = np.empty((4, 6))
    for i in range(p.shape[0]):
        if not failed[i] and not paper_trial_step(i, frames, five_bar, drag_constant, drag, inertia, inertia_inverse,
                                                  inverse_mass, net_paw_buoyancy, restoring, p, v, R, w, q, q_dot,
                                                  dt, feet):
            failed[i] = True


class PaperPlantBatch:
    """N copies of the paper's plant (module docstring); one robot, optional centre-of-buoyancy offset."""

    name = "paper"

    def __init__(self, robot: RobotParams, n: int, restoring_matrix: np.ndarray = None) -> None:
        self.robot = robot
        self.n = int(n)
        self.frames, self.five_bar = leg_geometry(robot)
        self.drag_constant = float(robot.drag_constant)
        inertia = np.asarray(robot.inertia, dtype=float)
        self.inertia = as_mat3(inertia)
        self.inertia_inverse = as_mat3(np.linalg.inv(inertia))
        self.inverse_mass = 1.0 / float(robot.mass)
        self.net_paw_buoyancy = float(robot.paw_net_buoyancy)
        self.drag = hydrodynamics.body_drag_coefficients(robot).flat
        self.restoring = np.zeros((self.n, 3, 3)) if restoring_matrix is None \
            else np.ascontiguousarray(np.broadcast_to(np.asarray(restoring_matrix, dtype=float), (self.n, 3, 3)))
        self.failed = np.zeros(self.n, dtype=bool)

    @staticmethod
    def restoring_matrix(robot: RobotParams, offset) -> np.ndarray:
        """U_cb of :class:`~quadruped_control.sim.plants.paper.FloatingBaseModel`'s ``restoring_offset``."""
        return torso_buoyancy_torque_matrix(float(robot.mass) * robot.gravity, offset)

    def step(self, p: np.ndarray, v: np.ndarray, R: np.ndarray, w: np.ndarray, q: np.ndarray, q_dot: np.ndarray,
             dt: float):
        """(p, v, R, omega) after ``dt`` s with joints q, q_dot (N, 4, 3) held: classic RK4 in the chart.
        The arrays passed in are advanced in place (and returned)."""
        paper_batch_step(self.frames, self.five_bar, self.drag_constant, self.drag, self.inertia,
                         self.inertia_inverse, self.inverse_mass, self.net_paw_buoyancy, self.restoring,
                         p, v, R, w, np.ascontiguousarray(q), np.ascontiguousarray(q_dot), float(dt), self.failed)
        return p, v, R, w
