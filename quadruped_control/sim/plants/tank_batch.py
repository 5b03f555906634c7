"""The test-tank plant of :mod:`quadruped_control.sim.plants.tank` for N trials.

:class:`TankPlantBatch` is :class:`~quadruped_control.sim.plants.tank.TankModel` for N trials, each with
its own :class:`~quadruped_control.sim.plants.tank_params.TankParams` (the identification's parameter sets).
It runs the per-trial plant's own functions: a loop over the trials (:func:`tank_batch_step`, compiled by
numba when it is installed, :mod:`quadruped_common.jit`) calls, per trial, the legs' kinematics, the paw buoyancy
plus the torso's buoyancy moment (:func:`~quadruped_control.sim.plants.paper_batch.held_step_inputs`), the
mass matrix of the held step (:func:`~.tank_dynamics.leg_sums`, :func:`~.tank_dynamics.mass_solver`), the
RK4 of eq. (tank) in the SO(3) chart (:func:`~.tank_dynamics.tank_rk4`) and the final polish. Every
per-trial constant is read from a :class:`~quadruped_control.sim.plants.tank.TankModel` built for that
trial (:meth:`~quadruped_control.sim.plants.tank.TankModel.constants`), so the two plants share their
set-up as well as their equations; the tests compare them trial by trial.

A trial whose kinematics fail or whose state stops being finite is marked in ``failed`` and frozen.
"""
from __future__ import annotations

from typing import Dict, Sequence

import numpy as np

from quadruped_common.jit import jitable, kernel, trial_step
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.paper_batch import held_step_inputs, leg_geometry, store_step_end
from quadruped_control.sim.plants.rigid_body import RigidBodyState
from quadruped_control.sim.plants.tank import TankModel, TurnUnresolved
from quadruped_control.sim.plants.tank_dynamics import (TANK_CONSTANT_FIELDS, body_wake_update,
                                                        disturbance_coefficients, disturbance_update,
                                                        floating_block_update,
                                                        hook_friction_update, leg_sums, mass_solver, paw_joint_loads,
                                                        paw_wake_update, tank_rk4, tether_relaxation_update,
                                                        twist_relaxation_update, whole_twist, world_to_body,
                                                        wound_friction_limit)
from quadruped_control.sim.plants.tank_params import TankParams

__all__ = ["TankPlantBatch", "tank_batch_step", "tank_trial_step"]


@jitable
def _carry_twist(rotation, reference, torsion) -> None:
    """The rope's whole twist ``torsion[2]`` (``torsion``: the six torsion constants of
    :data:`~.tank_dynamics.TankConstants`) carried from the attitude ``reference`` (9, in place) to
    ``rotation`` (9 floats), as TankModel._count_twist."""
    torsion[2] = whole_twist(rotation, reference, torsion[2])
    for k in range(9):
        reference[k] = rotation[k]


@trial_step
def tank_trial_step(i, frames, five_bar, net_paw_buoyancy, drag_constant, drag, extra_lift, suspension, hook, anchor,
                    rope, torsion, untwisted, linear, quadratic, body_m, paw_added_mass, paw_wake_fraction,
                    paw_wake_time_constant, paw_wake_body_share, body_wake_fraction, body_wake_time_constant, tether,
                    restoring, wake, water, p, v, R, w, q, q_dot, dt, feet, drag_feet, stall_torque, loads, block,
                    block_rest, friction, hook_friction, counts_twist, disturbed, disturbance) -> bool:
    """One held-input RK4 step of eq. (tank) for trial ``i`` in place (its paws' ``wake[i]``, the water
    turning with its body, ``water[i]``, its floating block, ``anchor[i]``, and its hook's friction,
    ``friction[i]``, too, with the body's state at the step's start, as
    :class:`~quadruped_control.sim.plants.tank.TankModel`; its tank's disturbance ``disturbance[i]``, world axes,
    held where ``disturbed[i]``, and stepped by the caller); False if it failed."""
    ok, lift, up, R0 = held_step_inputs(q, q_dot, i, frames, five_bar, net_paw_buoyancy[i], restoring, R, feet)
    if not ok:
        return False
    # the rope's whole twist carried to the step's start and end where it is read (``counts_twist``:
    # TankModel.counts_twist), as TankModel._count_twist; ``untwisted`` holds the attitude it belongs to
    if counts_twist[i]:
        _carry_twist(R0, untwisted[i], torsion[i])
    sums = leg_sums(feet)
    solver = mass_solver(body_m[i], paw_added_mass[i], sums[0], sums[2])
    constants = (drag_constant[i], drag[i], extra_lift[i], suspension[i], hook[i], anchor[i], rope[i],
                 torsion[i], untwisted[i], linear[i], quadratic[i], body_m[i], paw_added_mass[i], paw_wake_fraction[i],
                 paw_wake_time_constant[i], paw_wake_body_share[i], body_wake_fraction[i], body_wake_time_constant[i],
                 tether[i])
    rows = feet
    if paw_wake_fraction[i] > 0.0 or stall_torque[i] > 0.0:
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]  # b = R^T v at the step's start, as TankModel._body_motion
        bx, by, bz = R0[0] * vx + R0[3] * vy + R0[6] * vz, R0[1] * vx + R0[4] * vy + R0[7] * vz, \
            R0[2] * vx + R0[5] * vy + R0[8] * vz
        if paw_wake_fraction[i] > 0.0:
            paw_wake_update(feet, wake[i], paw_wake_fraction[i], paw_wake_time_constant[i], paw_wake_body_share[i], bx, by, bz,
                            w[i, 0], w[i, 1], w[i, 2], dt, drag_feet)
            rows = drag_feet
        if stall_torque[i] > 0.0:
            paw_joint_loads(q[i], frames, five_bar, rows, drag_constant[i], bx, by, bz, w[i, 0], w[i, 1], w[i, 2],
                            loads[i])
    if block[i, 0] > 0.0 and suspension[i]:
        floating_block_update(anchor[i], block_rest[i], p[i], v[i], R0, w[i], hook[i], rope[i], block[i, 0],
                              block[i, 1], block[i, 2], dt)
    turning = (0.0, 0.0, 0.0)
    if body_wake_fraction[i] > 0.0:
        turning = body_wake_update(water[i], body_wake_fraction[i], body_wake_time_constant[i], R0, w[i, 0], w[i, 1],
                                   w[i, 2], dt)
    y0 = (p[i, 0], p[i, 1], p[i, 2], v[i, 0], v[i, 1], v[i, 2], 0.0, 0.0, 0.0, w[i, 0], w[i, 1], w[i, 2])
    held = (0.0, 0.0, 0.0)
    if hook_friction[i, 0] > 0.0:
        limit = wound_friction_limit(hook_friction[i, 0], hook_friction[i, 5], torsion[i, 2])
        held = hook_friction_update(friction[i], limit, hook_friction[i, 1], hook_friction[i, 2],
                                    hook_friction[i, 3], hook_friction[i, 4], (y0[0], y0[1], y0[2]),
                                    (y0[3], y0[4], y0[5]), R0, (y0[9], y0[10], y0[11]), hook[i], anchor[i], rope[i, 0],
                                    dt)
    if disturbed[i]:  # held over the step in body axes at its start, beside the hook's friction, as TankModel
        bx, by, bz = world_to_body(R0, disturbance[i, 0], disturbance[i, 1], disturbance[i, 2])
        held = (held[0] + bx, held[1] + by, held[2] + bz)
    y = tank_rk4(constants, feet, rows, turning, held, lift, up, sums, solver, R0, y0, dt)
    if not store_step_end(y, R0, i, p, v, R, w):
        return False
    bends_tether = tether[i, 0] > 0.0 or tether[i, 1] > 0.0  # TankModel.bends_tether
    if counts_twist[i] or bends_tether:
        end = (R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2], R[i, 2, 0], R[i, 2, 1],
               R[i, 2, 2])
        if counts_twist[i]:
            _carry_twist(end, untwisted[i], torsion[i])
            if torsion[i, 3] > 0.0:  # the relaxed twist carried to the step's end, as TankModel._relax_twist
                torsion[i, 5] = twist_relaxation_update(torsion[i, 2], torsion[i, 5], torsion[i, 4], dt)
        if bends_tether:  # the tether's relaxed tilt carried to the step's end, as TankModel._relax_tether
            tether[i, 3], tether[i, 4], tether[i, 5] = tether_relaxation_update(end, tether[i], dt)
    return True


@kernel
def tank_batch_step(frames, five_bar, net_paw_buoyancy, drag_constant, drag, extra_lift, suspension, hook, anchor,
                    rope, torsion, untwisted, linear, quadratic, body_m, paw_added_mass, paw_wake_fraction,
                    paw_wake_time_constant, paw_wake_body_share, body_wake_fraction, body_wake_time_constant, tether,
                    restoring, wake, water, p, v, R, w, q, q_dot, dt, failed, stall_torque, loads, block, block_rest,
                    friction, hook_friction, counts_twist, disturbed, disturbance):
    """One held-input RK4 step of eq. (tank) for every trial not yet ``failed``, in place on p, v, w
    (N, 3), R (N, 3, 3), the paws' ``wake`` (N, 4, 3), the water turning with each body, ``water``
    (N, 3), and each rope's upper end, ``anchor`` (N, 6). The constants are the fields of
    :data:`~.tank_dynamics.TankConstants`, one row (or value) per trial, ``restoring`` (N, 3, 3) each
    trial's torso buoyancy moment matrix, ``net_paw_buoyancy`` (N,) each trial's paws' buoyancy, ``block``
    (N, 3) each floating block's mass, drag and tie stiffness (mass 0: a fixed anchor), ``block_rest``
    (N, 3) where it rests, ``friction`` (N, 3) each hook's friction torque (advanced in place) and
    ``hook_friction`` (N, 6) its Coulomb torque tau_c (0: off), presliding angle, static over sliding
    friction, Stribeck rate, roll over pitch friction and the tether's capstan coefficient; ``counts_twist``
    (N,) whether the trial carries the rope's twist (TankModel.counts_twist); ``tether`` (N, 6) the tether's
    stiffnesses, relaxation time and relaxed tilt (advanced in place where either stiffness is above 0);
    ``disturbed`` (N,) whether the trial's tank is not still and ``disturbance`` (N, 3) its torque, world axes,
    held over this step (TankModel.disturbance; the caller steps it)."""
    feet = np.empty((4, 6))
    drag_feet = np.empty((4, 6))
    for i in range(p.shape[0]):
        if not failed[i] and not tank_trial_step(i, frames, five_bar, net_paw_buoyancy, drag_constant, drag,
                                                 extra_lift, suspension, hook, anchor, rope, torsion, untwisted,
                                                 linear, quadratic, body_m, paw_added_mass, paw_wake_fraction,
                                                 paw_wake_time_constant, paw_wake_body_share, body_wake_fraction,
                                                 body_wake_time_constant, tether, restoring, wake, water, p, v, R,
                                                 w, q, q_dot, dt, feet, drag_feet, stall_torque, loads, block,
                                                 block_rest, friction, hook_friction, counts_twist, disturbed,
                                                 disturbance):
            failed[i] = True


class TankPlantBatch:
    """N tank plants (module docstring); ``tanks``: one TankParams per trial."""

    name = "tank"

    def __init__(self, robot: RobotParams, tanks: Sequence[TankParams]) -> None:
        self.models = [TankModel(robot, tank) for tank in tanks]
        self.n = len(self.models)
        self.robot = robot
        self.frames, self.five_bar = leg_geometry(robot)
        #: Each trial's paws' net buoyancy (N,): TankModel.net_paw_buoyancy (robot.yaml's plus the offset).
        self.net_paw_buoyancy = np.array([m.net_paw_buoyancy for m in self.models], dtype=float)
        self.restoring = np.array([m._restoring_matrix for m in self.models], dtype=float)  # noqa: SLF001
        self.failed = np.zeros(self.n, dtype=bool)
        #: Why a trial marked in ``failed`` failed, where the plant knows better than "a non-finite state": a
        #: wound tether past the turn its set can be stepped at (:class:`~.tank.TurnUnresolved`), by trial.
        self.failure_reasons: Dict[int, str] = {}
        #: Each trial's paws' wake velocity (N, 4, 3), body axes: TankModel.wake for N trials.
        self.wake = np.zeros((self.n, 4, 3))
        #: The rate of the water turning with each trial's body (N, 3), world axes: TankModel.body_wake for N
        #: trials.
        self.water = np.zeros((self.n, 3))
        #: Each trial's servos' stall torque (N,; 0: no loaded servos) and joint loads (N, 4, 3): TankModel's
        #: servo_stall_torque and joint_loads for N trials, read by the batch's servo step.
        self.stall_torque = np.array([float(tank.servo_stall_torque) for tank in tanks])
        self.loads = np.zeros((self.n, 4, 3))
        #: Each trial's floating block (N, 3): mass, drag and tie stiffness (TankParams' block_*; mass 0: the
        #: anchor is fixed); where it rests (N, 3, world), set by attach. Its position and velocity are the
        #: constants' "anchor" rows (N, 6), advanced in place.
        self.block = np.array([[tank.block_mass, tank.block_drag, tank.block_tie_stiffness] for tank in tanks],
                              dtype=float).reshape(self.n, 3)
        self.block_rest = np.zeros((self.n, 3))
        #: Each trial's hook friction (N, 6): tau_c (TankModel.hook_friction_limit; 0: off), the presliding
        #: angle, the static over sliding friction, the Stribeck rate, the roll over pitch friction and the
        #: tether's capstan coefficient; its torque (N, 3, body axes): TankModel.hook_friction for N trials.
        self.hook_friction = np.array([[m.hook_friction_limit(), tank.hook_friction_angle,
                                        tank.hook_friction_static_ratio, tank.hook_friction_stribeck_rate,
                                        tank.hook_friction_roll_ratio, tank.hook_friction_wrap]
                                       for m, tank in zip(self.models, tanks)], dtype=float).reshape(self.n, 6)
        self.friction = np.zeros((self.n, 3))
        self._checked_step = min(model._checked_step for model in self.models) if self.models else 0.0  # noqa: SLF001
        #: Each trial's TankModel.counts_twist (N,); the wound tethers' trials (N,) and the turn each has had
        #: checked (N, rad; TankModel.check_turn)
        self.counts_twist = np.array([m.counts_twist for m in self.models], dtype=bool)
        self._wound = np.array([m._wound for m in self.models], dtype=bool)  # noqa: SLF001
        self._checked_turns = np.array([m.checked_turn for m in self.models], dtype=float)
        self._any_wound = bool(self._wound.any())
        #: Each trial's tank not still (N,; TankParams.disturbed), its disturbance torque (N, 3, world axes:
        #: TankModel.disturbance for N trials) and the standard normal draws it steps on, a block per trial
        #: (TankModel.disturbance_noise_block) taken a row per step, as the per-trial plant takes them.
        self.disturbed = np.array([tank.disturbed for tank in tanks], dtype=bool)
        self._disturbed = np.flatnonzero(self.disturbed)
        self.disturbance = np.zeros((self.n, 3))
        self._disturbance_draws = np.zeros((len(self._disturbed), 0, 3))
        self._disturbance_row = 0
        self._disturbance_coefficients: Dict[float, np.ndarray] = {}
        self._load_constants()

    def _load_constants(self) -> None:
        """The per-trial fields of TankConstants as arrays (one row per trial)."""
        columns = list(zip(*(m.constants() for m in self.models)))
        self.constants = {name: np.array(column, dtype=bool if name == "suspension" else float)
                          for name, column in zip(TANK_CONSTANT_FIELDS, columns)}

    def attach(self, position: np.ndarray, rotation: np.ndarray) -> None:
        """:meth:`TankModel.attach` of every trial: anchor above the hook, rope untwisted at this attitude, every
        trial a new one (a trial that failed before runs again)."""
        for i, model in enumerate(self.models):
            model.attach(RigidBodyState(np.array(position[i], dtype=float), np.zeros(3),
                                        np.array(rotation[i], dtype=float), np.zeros(3)))
        self.failed[:] = False
        self.failure_reasons = {}
        self.wake[:] = 0.0
        self.water[:] = 0.0
        self.friction[:] = 0.0
        self.loads[:] = 0.0
        self._load_constants()
        self.block_rest = np.array([m.block_rest for m in self.models], dtype=float).reshape(self.n, 3)
        self.disturbance = np.array([m.disturbance for m in self.models], dtype=float).reshape(self.n, 3)
        if len(self._disturbed):  # the rest of the block each one's start was drawn from (attach took its first row)
            self._take_disturbance_draws()

    def _take_disturbance_draws(self) -> None:
        """Each disturbed trial's next draws (TankModel.take_disturbance_noise), one row per step from here."""
        self._disturbance_draws = np.array([self.models[i].take_disturbance_noise() for i in self._disturbed],
                                           dtype=float).reshape(len(self._disturbed), -1, 3)
        self._disturbance_row = 0

    def _step_disturbance(self, dt: float) -> None:
        """Each disturbed trial's disturbance one step of ``dt`` on (TankModel._step_disturbance for N trials)."""
        if self._disturbance_row >= self._disturbance_draws.shape[1]:
            self._take_disturbance_draws()
        coefficients = self._disturbance_coefficients.get(dt)
        if coefficients is None:
            coefficients = np.array([disturbance_coefficients(self.models[i].tank.disturbance_torque_std,
                                                              self.models[i].tank.disturbance_correlation_time, dt)
                                     for i in self._disturbed], dtype=float).reshape(-1, 2)
            self._disturbance_coefficients[dt] = coefficients
        noise = self._disturbance_draws[:, self._disturbance_row]
        self._disturbance_row += 1
        self.disturbance[self._disturbed] = disturbance_update(self.disturbance[self._disturbed],
                                                               coefficients[:, 0:1], coefficients[:, 1:2], noise)

    def step(self, p: np.ndarray, v: np.ndarray, R: np.ndarray, w: np.ndarray, q: np.ndarray, q_dot: np.ndarray,
             dt: float):
        """(p, v, R, omega) after ``dt`` s with joints q, q_dot (N, 4, 3) held: the tank's RK4 in the chart.
        The arrays passed in are advanced in place (and returned). ParameterError if a trial's parameters
        cannot take a step of ``dt`` (:meth:`TankModel.check_step_stability`); a trial whose wound tether has
        turned past what its parameters can be stepped at (:meth:`TankModel.check_turn`) is marked in
        ``failed`` instead, with the refusal in ``failure_reasons``, and the others run on."""
        if dt > self._checked_step:  # once per new step length, not per step: a loop over N models
            for model in self.models:
                model.check_step(dt)
            self._checked_step = dt
        c = self.constants
        tank_batch_step(self.frames, self.five_bar, self.net_paw_buoyancy, c["drag_constant"], c["drag"],
                        c["extra_lift"], c["suspension"], c["hook"], c["anchor"], c["rope"], c["torsion"],
                        c["untwisted"], c["linear"], c["quadratic"], c["body_m"], c["paw_added_mass"],
                        c["paw_wake_fraction"], c["paw_wake_time_constant"], c["paw_wake_body_share"], c["body_wake_fraction"],
                        c["body_wake_time_constant"], c["tether"], self.restoring, self.wake, self.water, p, v, R, w,
                        np.ascontiguousarray(q), np.ascontiguousarray(q_dot), float(dt), self.failed, self.stall_torque,
                        self.loads, self.block, self.block_rest, self.friction, self.hook_friction,
                        self.counts_twist, self.disturbed, self.disturbance)
        if len(self._disturbed):
            self._step_disturbance(float(dt))
        if self._any_wound:  # TankModel.check_turn where a wound tether has turned past its checked turn
            turns = np.abs(c["torsion"][:, 2])
            for i in np.flatnonzero(self._wound & ~self.failed & (turns > self._checked_turns)):
                try:
                    self.models[i].check_turn(float(turns[i]))
                except TurnUnresolved as exc:  # frozen from here, like a trial that diverged
                    self.failed[i] = True
                    self.failure_reasons[int(i)] = str(exc)
                    continue
                self._checked_turns[i] = self.models[i].checked_turn
        return p, v, R, w
