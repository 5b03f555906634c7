"""The attitude controller vectorised over trials: many closed-loop trials share one step of numpy.

:class:`BatchController` is :class:`~quadruped_control.control.controller.AttitudeController` for N
trials at once, each with its own gains, torque limit, stroke timing, force-direction option and
setpoint, the robot (kinematics, inertia, drag constant, paw buoyancy) and the leg pairs shared. One
:meth:`BatchController.step` is the controller's step on arrays with a leading trial axis:

1. eq. (error): E = R_d^T R, e_R = vee(1/2 (E - E^T)), and the geodesic angle of E;
2. eq. (pid) with the feedforward omega x (I omega) - tau_buoyancy^B at the commanded feet, the
   integral z = int(e_R + K_aw Delta_sat) in the controller's two discretisations (forward in the
   anti-windup excess while g = h K_aw K_i <= 1, backward Euler beyond, then the clip to
   ``integral_limit``: see the controller's module docstring), eq. (sat);
3. the paper's power/recovery stroke cycle (:class:`~quadruped_control.control.strokes.paper.StrokeCycle`)
   with the allocation of eq. (foot_speed), (foot_vel) latched at each power start
   (:func:`~quadruped_control.control.allocation.foot_velocity_commands_batch`), eq. (foot_integration)
   and the leg IK (:func:`~quadruped_control.model.kinematics_batch.joint_angles_batch`).

The robot runs the float path (:class:`~quadruped_control.control.controller.AttitudeController`,
unrolled on Python floats for its 100 Hz deadline); this is its array form, for the batched simulator
(:mod:`quadruped_control.sim.batch`), and the tests step both side by side and compare every state
to 1e-9. What the batch leaves out, because no simulated trial reaches it: the hold (safe state, scheme
switches; a trial whose measurement the float controller would refuse is reported as ``refused`` and
stops being trusted), the coordinated stroke scheme, and timing changes during a trial.

The paper's power strokes are straight lines (a constant velocity from the stroke's start), so the
recorded stroke of :class:`~quadruped_control.control.strokes.base.StrokePath` is the segment from its
start to its end and its arc-length retrace is the linear interpolation along that segment: the same
points to rounding. Where the float path falls back to the nearest recorded point (the chord between
two reachable points left the workspace: not seen in any study), the batch keeps the foot where it is
and counts the event in ``ik_fallbacks``.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from quadruped_common.so3 import cross_rows
from quadruped_common.robot import LEGS
from quadruped_control.control.allocation import foot_velocity_commands_batch
from quadruped_control.control.controller_config import ControllerConfig
from quadruped_control.control.strokes.base import TIME_EPS
from quadruped_control.model.kinematics_batch import LegGeometry, joint_angles_batch
from quadruped_control.model.params import RobotParams

__all__ = ["BatchController", "cubic_time_profile_batch"]


def cubic_time_profile_batch(u: np.ndarray) -> np.ndarray:
    """:func:`~quadruped_control.control.strokes.base.cubic_time_profile` on arrays: 3 u^2 - 2 u^3 on [0, 1]."""
    return np.where(u <= 0.0, 0.0, np.where(u >= 1.0, 1.0, u * u * (3.0 - 2.0 * u)))


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
        self.k_p = np.array([c.gains.k_p for c in configs], dtype=float)
        self.k_i = np.array([c.gains.k_i for c in configs], dtype=float)
        self.k_d = np.array([c.gains.k_d for c in configs], dtype=float)
        self.k_aw = np.array([c.gains.k_aw for c in configs], dtype=float)
        self.tau_max = _per_trial(configs, "tau_max")
        self.integral_limit = _per_trial(configs, "integral_limit")
        self.t_rec = _per_trial(configs, "t_rec")
        self.t_pow_max = _per_trial(configs, "t_pow_max")
        self.normalize = np.array([bool(c.normalize_force_direction) for c in configs])
        self.R_d = np.array(setpoints, dtype=float).reshape(n, 3, 3)
        self.inertia = np.asarray(robot.inertia, dtype=float)
        self.k_drag = float(robot.drag_constant)
        self.net_buoyancy = float(robot.paw_net_buoyancy)
        self.geometry = LegGeometry.from_params(robot)
        # legs of each pair (pair index per leg), in config order
        self.pairs = first.pairs
        self.pair_of_leg = np.zeros(4, dtype=int)
        for index, pair in enumerate(self.pairs):
            for leg in pair:
                self.pair_of_leg[leg - 1] = index
        nominal = np.array([robot.nominal_foot_body(leg) for leg in LEGS], dtype=float)
        nominal_joints, ok = joint_angles_batch(nominal, self.geometry)
        if not ok.all():
            raise ValueError("a nominal foot position is unreachable")
        self.nominal = nominal
        self.nominal_joints = np.clip(nominal_joints, self.geometry.low, self.geometry.high)
        self.reset()

    # ---- state -------------------------------------------------------------------------------

    def reset(self) -> None:
        """Integral cleared, feet at the nominal pose, cycle at its start (first pair: half recovery)."""
        n = self.n
        self.integral = np.zeros((n, 3))
        self.delta_sat = np.zeros((n, 3))
        self.tau_sat = np.zeros((n, 3))
        self.omega = np.zeros((n, 3))
        self.t_prev: Optional[float] = None
        self.positions = np.tile(self.nominal, (n, 1, 1))
        self.joints = np.tile(self.nominal_joints, (n, 1, 1))
        self.velocities = np.zeros((n, 4, 3))
        self.path_start = self.positions.copy()
        self.path_start_joints = self.joints.copy()
        self.path_end = self.positions.copy()
        self.power = np.zeros((n, 2), dtype=bool)
        self.phase_time = np.zeros((n, 2))
        self.t_move = np.zeros((n, 2))
        self.t_total = np.zeros((n, 2))
        self.t_total[:, 0] = 0.5 * self.t_rec
        self.t_pow = np.zeros((n, 2))
        #: trials whose measurement the float controller would have refused (it would hold)
        self.refused = np.zeros(n, dtype=bool)
        self.ik_fallbacks = np.zeros(n, dtype=int)

    # ---- step --------------------------------------------------------------------------------

    def _elapsed(self, t: float) -> float:
        h = self.dt if self.t_prev is None else min(max(t - self.t_prev, 0.0), self.max_step)
        self.t_prev = t
        return h

    def step(self, t: float, R: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """One control step of every trial at time ``t`` with measured R (N, 3, 3) and omega (N, 3);
        returns the joint targets (N, 4, 3). Fills ``e_R``, ``geodesic``, ``tau_cmd``, ``saturated``."""
        h = self._elapsed(float(t))
        self.refused |= ~(np.isfinite(omega).all(axis=1) & (np.abs(omega) <= self.max_angular_rate).all(axis=1))
        # eq. (error): E = R_d^T R
        E = np.einsum("nji,njk->nik", self.R_d, R)
        e = 0.5 * np.stack((E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]), axis=1)
        self.e_R = e
        self.geodesic = np.arctan2(np.sqrt(np.sum(e * e, axis=1)), 0.5 * (np.trace(E, axis1=1, axis2=2) - 1.0))
        w = omega
        # feedforward omega x (I omega) - tau_buoyancy^B, eq. (pid), (buoy_torque)
        feedforward = np.zeros((self.n, 3))
        if self.gyroscopic:
            feedforward = feedforward + cross_rows(w, w @ self.inertia.T)
        if self.buoyancy:
            feedforward = feedforward - cross_rows(self.positions.sum(axis=1), self.net_buoyancy * R[:, 2, :])
        k_p, k_i, k_d, k_aw = self.k_p[:, None], self.k_i[:, None], self.k_d[:, None], self.k_aw[:, None]
        tau_max = self.tau_max
        z = self.integral
        g = h * self.k_aw * self.k_i
        forward = z + h * (e + k_aw * self.delta_sat)
        predictor = z + h * e
        u = -k_p * e - k_i * predictor - k_d * w + feedforward
        norm_u = np.sqrt(np.sum(u * u, axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            excess = np.where(norm_u > tau_max, h * self.k_aw * (norm_u - tau_max) / ((1.0 + g) * norm_u), 0.0)
        backward = predictor + excess[:, None] * u
        z = np.where((g <= 1.0)[:, None], forward, backward)
        norm_z = np.sqrt(np.sum(z * z, axis=1))
        over = norm_z > self.integral_limit
        z = np.where(over[:, None], z * (self.integral_limit / np.where(over, norm_z, 1.0))[:, None], z)
        self.integral = z
        c = -k_p * e - k_i * z - k_d * w + feedforward
        norm_c = np.sqrt(np.sum(c * c, axis=1))
        saturated = norm_c > tau_max
        tau_sat = np.where(saturated[:, None], c * (tau_max / np.where(saturated, norm_c, 1.0))[:, None], c)  # eq. (sat)
        self.tau_cmd = c
        self.saturated = saturated
        self.delta_sat = c - tau_sat
        self.tau_sat = tau_sat
        self.omega = w
        self._advance_strokes(h)
        return self.joints

    # ---- the paper's stroke cycle ------------------------------------------------------------

    def _ik(self, points: np.ndarray, legs: Sequence[int]):
        angles, ok = joint_angles_batch(points, self.geometry, legs)
        return np.clip(angles, self.geometry.low, self.geometry.high), ok

    def _advance_strokes(self, h: float) -> None:
        """:meth:`StrokeCycle.advance` of every trial: pair 0 then pair 1, each its power or recovery step."""
        for pair in (0, 1):
            legs = [leg - 1 for leg in self.pairs[pair]]
            power = self.power[:, pair].copy()  # the phase at the step's start: a power step may end it
            if h > 0.0:
                self._power_step(pair, legs, power, h)
            self._recovery_step(pair, legs, ~power, h)

    def _power_step(self, pair: int, legs: Sequence[int], active: np.ndarray, h: float) -> None:
        if not active.any():
            return
        self.phase_time[:, pair] = np.where(active, self.phase_time[:, pair] + h, self.phase_time[:, pair])
        position = self.positions[:, legs]
        target = position + self.velocities[:, legs] * h  # eq. (foot_integration)
        moving = active[:, None] & (target != position).any(axis=2)
        joints, ok = self._ik(target, legs)
        move = moving & ok
        boundary = (moving & ~ok).any(axis=1)
        self.positions[:, legs] = np.where(move[..., None], target, position)
        self.joints[:, legs] = np.where(move[..., None], joints, self.joints[:, legs])
        end = active & (boundary | (self.phase_time[:, pair] >= self.t_pow[:, pair] - TIME_EPS))
        if end.any():
            self._start_recovery(pair, legs, end)

    def _start_recovery(self, pair: int, legs: Sequence[int], which: np.ndarray) -> None:
        self.power[:, pair] &= ~which
        self.phase_time[:, pair] = np.where(which, 0.0, self.phase_time[:, pair])
        self.t_move[:, pair] = np.where(which, self.t_rec, self.t_move[:, pair])
        self.t_total[:, pair] = np.where(which, self.t_rec, self.t_total[:, pair])
        mask = which[:, None, None]
        self.velocities[:, legs] = np.where(mask, 0.0, self.velocities[:, legs])
        self.path_end[:, legs] = np.where(mask, self.positions[:, legs], self.path_end[:, legs])

    def _recovery_step(self, pair: int, legs: Sequence[int], active: np.ndarray, h: float) -> None:
        if not active.any():
            return
        time = np.where(active, self.phase_time[:, pair] + h, self.phase_time[:, pair])
        self.phase_time[:, pair] = time
        t_move = self.t_move[:, pair]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(t_move > 0.0, cubic_time_profile_batch(time / np.where(t_move > 0.0, t_move, 1.0)), 1.0)
        done = active & (time >= self.t_total[:, pair] - TIME_EPS)
        at_start = (done | (s >= 1.0))[:, None] & active[:, None]
        start, start_joints = self.path_start[:, legs], self.path_start_joints[:, legs]
        end = self.path_end[:, legs]
        # StrokePath.at_arc_length(length (1 - s)) on the straight stroke: start + (1 - s) (end - start)
        point = start + (1.0 - s)[:, None, None] * (end - start)
        position = self.positions[:, legs]
        moving = active[:, None] & ~at_start & (point != position).any(axis=2)
        joints, ok = self._ik(point, legs)
        move = moving & ok
        self.ik_fallbacks += (moving & ~ok).sum(axis=1)
        new_position = np.where(move[..., None], point, position)
        new_joints = np.where(move[..., None], joints, self.joints[:, legs])
        self.positions[:, legs] = np.where(at_start[..., None], start, new_position)
        self.joints[:, legs] = np.where(at_start[..., None], start_joints, new_joints)
        if done.any():
            self._start_power(pair, legs, done)

    def _start_power(self, pair: int, legs: Sequence[int], which: np.ndarray) -> None:
        self.power[:, pair] |= which
        self.phase_time[:, pair] = np.where(which, 0.0, self.phase_time[:, pair])
        self.t_pow[:, pair] = np.where(which, self.t_pow_max, self.t_pow[:, pair])
        start = self.positions[:, legs]
        # eq. (foot_vel) with the leg's share tau_sat / 4, from the torque and rate of this step
        velocity = foot_velocity_commands_batch(0.25 * self.tau_sat[:, None, :], start, self.omega[:, None, :],
                                                self.k_drag, self.normalize[:, None])
        velocity = np.where(np.isfinite(velocity).all(axis=2, keepdims=True), velocity, 0.0)
        mask = which[:, None, None]
        self.velocities[:, legs] = np.where(mask, velocity, self.velocities[:, legs])
        self.path_start[:, legs] = np.where(mask, start, self.path_start[:, legs])
        self.path_start_joints[:, legs] = np.where(mask, self.joints[:, legs], self.path_start_joints[:, legs])
        self.path_end[:, legs] = np.where(mask, start, self.path_end[:, legs])
