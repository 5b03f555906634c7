"""The robot's attitude controller for N trials at once (the batched simulator's controller).

:class:`BatchController`: the paper's stroke scheme for N trials, each with its own gains, torque limit,
stroke timing, force-direction option and setpoint (robot and leg pairs shared), stepped by
:func:`controller_batch_step`, a loop over the trials (compiled when numba is installed,
:mod:`quadruped_common.jit`) that runs the robot's own float functions per trial: the control law
:func:`~quadruped_control.control.controller.control_law_f`, the allocation
:func:`~quadruped_control.control.allocation.foot_velocity_command_f`, the stroke cycle itself
(:mod:`quadruped_control.control.strokes.cycle`, the functions the robot's
:class:`~quadruped_control.control.strokes.paper.StrokeCycle` runs on its one trial) and the leg IK
:func:`~quadruped_control.model.kinematics.ik_row`, which reports an unreachable target to the cycle (it
ends the power phase, or the recovery takes the nearest recorded point) where the robot's IK raises. The
tests require every state to equal the robot's. Here the recorded strokes hold ``path_capacity`` points
(t_pow_max covered); a trial whose stroke outgrows them is marked ``refused``. Not covered (no simulated
trial of the paper's scheme reaches it): the robot's hold and restart and timing changes during a trial;
a measurement the robot would refuse marks the trial ``refused``.

:class:`ControllerObjects`: the robot's own :class:`~quadruped_control.control.controller.AttitudeController`
objects, one per trial, with the same interface (the coordinated scheme, controllers switched off).

How the batch and the robot's controller share one law: docs/controller.md.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np

from quadruped_common.jit import jitable, kernel
from quadruped_common.robot import LEGS
from quadruped_common.vec3 import ZERO, Mat3, Vec3, add, mat3, scale, sub
from quadruped_control.control.allocation import foot_velocity_command_f
from quadruped_control.control.controller import AttitudeController, Feedforward, LawGains, control_law_f
from quadruped_control.control.controller_config import ControllerConfig
from quadruped_control.control.strokes.cycle import (LegSolution, LegTarget, PairSolutions,
                                                     new_cycle_state, power_step, power_targets, recovery_step,
                                                     recovery_targets, start_power, wait_at_start)
from quadruped_control.model.kinematics import IkConstants, _geometry, ik_row, joint_angles_floats
from quadruped_control.model.params import RobotParams

__all__ = ["BatchController", "ControllerObjects", "controller_batch_step"]


@jitable
def _vec3_at(a, i) -> Vec3:
    """Row ``i`` of an (N, 3) array as a Vec3."""
    return (a[i, 0], a[i, 1], a[i, 2])


@jitable
def _set_vec3(a, i, v: Vec3) -> None:
    """Row ``i`` of an (N, 3) array := v."""
    a[i, 0], a[i, 1], a[i, 2] = v[0], v[1], v[2]


@jitable
def _rotation_at(R, i) -> Mat3:
    """Trial ``i`` of an (N, 3, 3) array of rotations as a Mat3."""
    return Mat3(R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2], R[i, 2, 0], R[i, 2, 1],
                R[i, 2, 2])


@jitable
def _clamped_ik(x, y, z, frame, ik: IkConstants):
    """ik_row of the target (x, y, z), the angles clamped exactly into the servo ranges as
    :meth:`StrokeCycle.ik` clamps them: (reached, theta1, theta2, theta3)."""
    ok, t1, t2, t3 = ik_row(x, y, z, frame, ik)
    t1 = ik.theta1_min if ik.theta1_min > t1 else t1
    t2 = ik.theta2_min if ik.theta2_min > t2 else t2
    t3 = ik.theta3_min if ik.theta3_min > t3 else t3
    return (ok, (ik.theta1_max if ik.theta1_max < t1 else t1), (ik.theta2_max if ik.theta2_max < t2 else t2),
            (ik.theta3_max if ik.theta3_max < t3 else t3))


@jitable
def _solve_leg(target: LegTarget, frame, ik: IkConstants) -> LegSolution:
    """The batch's IK of one foot's target (:func:`_clamped_ik`), for a target that moves."""
    if not target.moves:
        return LegSolution(False, 0.0, 0.0, 0.0)
    ok, t1, t2, t3 = _clamped_ik(target.x, target.y, target.z, frame, ik)
    return LegSolution(ok, t1, t2, t3)


@jitable
def _solve(targets, pair, legs, frames, ik: IkConstants) -> PairSolutions:
    """The IK of the pair's targets (a power step's :class:`~quadruped_control.control.strokes.cycle.PairTargets`
    or a recovery step's :class:`~quadruped_control.control.strokes.cycle.RecoveryTargets`; an unreachable
    target is reported, not raised: the shared cycle ends the power phase or takes the nearest recorded
    point)."""
    return PairSolutions(_solve_leg(targets.first, frames[legs[pair, 0]], ik),
                         _solve_leg(targets.second, frames[legs[pair, 1]], ik))


@jitable
def _velocity_command(st, i, leg, tau: Vec3, w: Vec3, k_drag, normalize) -> Vec3:
    """eq. (foot_speed), (foot_vel) at the foot's current point with the leg's share tau = tau_sat / 4."""
    start = (st.positions[i, leg, 0], st.positions[i, leg, 1], st.positions[i, leg, 2])
    return foot_velocity_command_f(tau, start, w, k_drag, normalize)


@kernel
def controller_batch_step(h, R, omega_measured, R_d, gains, limits, t_rec, t_pow_max, normalize, feedforward,
                          k_drag, max_angular_rate, legs, frames, ik, integral, delta_sat, tau_sat, omega, e_R,
                          geodesic, tau_cmd, saturated, st, refused):
    """One control step of every trial not yet ``refused``, in place on the state arrays (N leading).

    ``R`` (N, 3, 3), ``omega_measured`` (N, 3): the measurement; ``R_d`` (N, 9) the setpoints; ``gains``
    (N, 4) K_p, K_i, K_d, K_aw; ``limits`` (N, 2) tau_max, integral_limit; ``feedforward``: the
    :class:`~quadruped_control.control.controller.Feedforward` shared by the trials; ``legs`` (2, 2) the
    pairs' legs (0-based); ``frames`` (4, 6) and ``ik`` the :func:`~quadruped_control.model.kinematics.ik_row`
    geometry."""
    for i in range(R.shape[0]):
        if refused[i]:
            continue
        w = _vec3_at(omega_measured, i)
        if not (abs(w[0]) <= max_angular_rate and abs(w[1]) <= max_angular_rate and abs(w[2]) <= max_angular_rate):
            refused[i] = True  # the float controller raises (the robot would hold): not trusted from here
            continue
        feet_sum = ZERO
        if feedforward.buoyancy:
            for leg in range(4):
                feet_sum = add(feet_sum, (st.positions[i, leg, 0], st.positions[i, leg, 1], st.positions[i, leg, 2]))
        law = control_law_f(mat3(R_d[i]), _rotation_at(R, i), w, _vec3_at(integral, i), _vec3_at(delta_sat, i), h,
                            LawGains(gains[i, 0], gains[i, 1], gains[i, 2], gains[i, 3], limits[i, 0], limits[i, 1]),
                            feedforward, feet_sum)
        _set_vec3(e_R, i, law.e_R)
        geodesic[i] = law.geodesic
        _set_vec3(integral, i, law.z)
        _set_vec3(tau_cmd, i, law.tau_cmd)
        _set_vec3(tau_sat, i, law.tau_sat)
        saturated[i] = law.saturated
        _set_vec3(delta_sat, i, sub(law.tau_cmd, law.tau_sat))
        _set_vec3(omega, i, w)
        # the stroke cycle (quadruped_control.control.strokes.cycle), as StrokeCycle.advance runs it:
        # pair 0 then pair 1, each its power or its recovery step, the IK between targets and step
        for pair in range(2):
            if st.power[i, pair]:
                if h > 0.0:
                    targets = power_targets(st, i, pair, legs, h)
                    power_step(st, i, pair, legs, h, t_rec[i], targets, _solve(targets, pair, legs, frames, ik))
            else:
                targets = recovery_targets(st, i, pair, legs, h)
                if recovery_step(st, i, pair, legs, targets, _solve(targets, pair, legs, frames, ik)):
                    tau = scale(0.25, law.tau_sat)
                    start_power(st, i, pair, legs, t_pow_max[i],
                                _velocity_command(st, i, legs[pair, 0], tau, w, k_drag, normalize[i]),
                                _velocity_command(st, i, legs[pair, 1], tau, w, k_drag, normalize[i]))
        if st.overflowed[i]:
            refused[i] = True  # a stroke longer than its record: no longer the robot's; not trusted


def _per_trial(configs: Sequence[ControllerConfig], name: str) -> np.ndarray:
    return np.array([float(getattr(c, name)) for c in configs])


class BatchController:
    """N attitude controllers with the paper's stroke scheme, stepped together (module docstring).

    ``robot``: shared robot model; ``configs``: one :class:`ControllerConfig` per trial (gains, tau_max,
    integral_limit, t_rec, t_pow_max, normalize_force_direction may differ; dt, pairs, the feedforward
    switches, max_step_factor and the stroke scheme must agree and the scheme must be 'paper');
    ``setpoints``: R_d per trial (N, 3, 3).
    """

    def __init__(self, robot: RobotParams, configs: Sequence[ControllerConfig], setpoints: np.ndarray) -> None:
        if not configs:
            raise ValueError("a batch needs at least one trial")
        first = configs[0]
        for config in configs:
            for shared in ("dt", "pairs", "gyroscopic_feedforward", "buoyancy_feedforward", "max_step_factor",
                           "max_angular_rate", "stroke_scheme"):
                if getattr(config, shared) != getattr(first, shared):
                    raise ValueError("the trials of a batch must share %s (%r != %r)"
                                     % (shared, getattr(config, shared), getattr(first, shared)))
        if first.stroke_scheme != "paper":
            raise ValueError("the batched controller runs the 'paper' stroke scheme, not %r" % first.stroke_scheme)
        n = len(configs)
        self.n = n
        self.robot = robot
        self.dt = float(first.dt)
        self.max_step = float(first.max_step)
        self.max_angular_rate = float(first.max_angular_rate)
        self.gyroscopic = bool(first.gyroscopic_feedforward)
        self.buoyancy = bool(first.buoyancy_feedforward)
        self.gains = np.array([[c.gains.k_p, c.gains.k_i, c.gains.k_d, c.gains.k_aw] for c in configs], dtype=float)
        self.limits = np.stack((_per_trial(configs, "tau_max"), _per_trial(configs, "integral_limit")), axis=1)
        self.t_rec = _per_trial(configs, "t_rec")
        self.t_pow_max = _per_trial(configs, "t_pow_max")
        self.normalize = np.array([bool(c.normalize_force_direction) for c in configs])
        self.R_d = np.array(setpoints, dtype=float).reshape(n, 3, 3)
        self._R_d_rows = np.ascontiguousarray(self.R_d.reshape(n, 9))
        inertia = Mat3(*np.asarray(robot.inertia, dtype=float).ravel().tolist())
        self.feedforward = Feedforward(self.gyroscopic, inertia, self.buoyancy, float(robot.paw_net_buoyancy))
        self.k_drag = float(robot.drag_constant)
        geometry = _geometry(robot)
        self.frames = np.array(geometry.frame_rows, dtype=float)
        self.ik_constants = geometry.ik
        self.pairs = first.pairs
        self.legs = np.array([[leg - 1 for leg in pair] for pair in self.pairs], dtype=np.int64)
        nominal = np.array([robot.nominal_foot_body(leg) for leg in LEGS], dtype=float)
        low = np.array([geometry.ik.theta1_min, geometry.ik.theta2_min, geometry.ik.theta3_min])
        high = np.array([geometry.ik.theta1_max, geometry.ik.theta2_max, geometry.ik.theta3_max])
        try:
            angles = [joint_angles_floats(*nominal[k].tolist(), leg, robot) for k, leg in enumerate(LEGS)]
        except ValueError as exc:
            raise ValueError("a nominal foot position is unreachable: %s" % exc) from None
        self.nominal = nominal
        self.nominal_joints = np.clip(np.array(angles, dtype=float), low, high)
        #: points a recorded stroke can hold: the start and one per power step of the longest t_pow_max
        #: (the control period can only be shorter than dt by rounding, max_step caps a longer one)
        self.path_capacity = int(math.ceil(float(np.max(self.t_pow_max)) / self.dt)) + 3
        self.reset()

    # ---- state -------------------------------------------------------------------------------

    def reset(self) -> None:
        """Integral cleared, feet at the nominal pose, cycle at its start (first pair: half recovery)."""
        n = self.n
        self.integral = np.zeros((n, 3))
        self.delta_sat = np.zeros((n, 3))
        self.tau_sat = np.zeros((n, 3))
        self.omega = np.zeros((n, 3))
        self.e_R = np.zeros((n, 3))
        self.geodesic = np.zeros(n)
        self.tau_cmd = np.zeros((n, 3))
        self.saturated = np.zeros(n, dtype=bool)
        self.t_prev: Optional[float] = None
        # The stroke cycle's state (quadruped_control.control.strokes.cycle): feet at the nominal pose,
        # strokes of one point; first pair: half a recovery, second: power at its first step.
        self.cycle = new_cycle_state(n, self.path_capacity, self.nominal, self.nominal_joints)
        for i in range(n):
            wait_at_start(self.cycle, i, 0, self.legs, 0.5 * float(self.t_rec[i]))
            wait_at_start(self.cycle, i, 1, self.legs, 0.0)
        self.positions, self.joints = self.cycle.positions, self.cycle.joints
        self.power, self.ik_fallbacks = self.cycle.power, self.cycle.ik_fallbacks
        #: trials whose measurement the float controller would have refused (it would hold), or whose
        #: stroke outgrew its record
        self.refused = np.zeros(n, dtype=bool)

    # ---- step --------------------------------------------------------------------------------

    def _elapsed(self, t: float) -> float:
        h = self.dt if self.t_prev is None else min(max(t - self.t_prev, 0.0), self.max_step)
        self.t_prev = t
        return h

    def step(self, t: float, R: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """One control step of every trial at time ``t`` with measured R (N, 3, 3) and omega (N, 3);
        returns the joint targets (N, 4, 3), the controller's own array (updated in place by the next
        step). Fills ``e_R``, ``geodesic``, ``tau_cmd``, ``saturated``."""
        h = self._elapsed(float(t))
        controller_batch_step(h, np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(omega, dtype=float),
                              self._R_d_rows, self.gains, self.limits, self.t_rec, self.t_pow_max, self.normalize,
                              self.feedforward, self.k_drag, self.max_angular_rate, self.legs, self.frames,
                              self.ik_constants, self.integral, self.delta_sat, self.tau_sat, self.omega, self.e_R,
                              self.geodesic, self.tau_cmd, self.saturated, self.cycle, self.refused)
        return self.joints


class ControllerObjects:
    """N of the robot's own :class:`AttitudeController` objects, one per trial, with the interface of
    :class:`BatchController` (module docstring): any stroke scheme, and ``enabled`` False for a trial
    whose controller stays in its hold state (passive dynamics). A measurement the controller refuses
    makes it hold for that step, as the per-trial engine does (counted in ``holds``); so, unlike the
    compiled loop's, these trials are never ``refused``: they stay what the per-trial engine computes.

    ``configs`` must share dt, max_step_factor and max_angular_rate (one clock for the batch)."""

    def __init__(self, robot: RobotParams, configs: Sequence[ControllerConfig], setpoints: np.ndarray,
                 enabled: Optional[Sequence[bool]] = None) -> None:
        if not configs:
            raise ValueError("a batch needs at least one trial")
        first = configs[0]
        for config in configs:
            for shared in ("dt", "max_step_factor", "max_angular_rate"):
                if getattr(config, shared) != getattr(first, shared):
                    raise ValueError("the trials of a batch must share %s (%r != %r)"
                                     % (shared, getattr(config, shared), getattr(first, shared)))
        n = len(configs)
        self.n = n
        self.robot = robot
        self.dt = float(first.dt)
        self.enabled = np.ones(n, dtype=bool) if enabled is None else np.array(enabled, dtype=bool).reshape(n)
        self.R_d = np.array(setpoints, dtype=float).reshape(n, 3, 3)
        self.controllers = [AttitudeController(robot, config) for config in configs]
        for controller, R_d in zip(self.controllers, self.R_d):
            controller.set_setpoint(R_d)
        self.joints = np.array([controller.stroke.nominal_joints for controller in self.controllers], dtype=float)
        self.tau_sat = np.zeros((n, 3))
        self.power = np.zeros((n, 2), dtype=bool)
        self.refused = np.zeros(n, dtype=bool)
        self.holds = np.zeros(n, dtype=np.int64)
        self.ik_fallbacks = np.zeros(n, dtype=np.int64)

    def step(self, t: float, R: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """One step of every controller at ``t`` with R (N, 3, 3), omega (N, 3); returns the joint
        targets (N, 4, 3), updated in place by the next step; fills ``tau_sat`` and ``power``."""
        for i, controller in enumerate(self.controllers):
            if not self.enabled[i]:
                output = controller.hold(t, "controller off")
            else:
                try:
                    output = controller.step(t, R[i], omega[i])
                except ValueError as exc:
                    self.holds[i] += 1
                    output = controller.hold(t, "bad measurement: %s" % exc)
            self.joints[i] = output.joint_targets
            self.tau_sat[i] = output.state.tau_sat
            phases = output.state.pair_phase
            self.power[i, 0], self.power[i, 1] = phases[0] == "power", phases[1] == "power"
        return self.joints
