"""The attitude controller for N trials at once: the robot's own control law in a loop over trials.

:class:`BatchController` is :class:`~quadruped_control.control.controller.AttitudeController` with the
paper's stroke scheme for N trials, each with its own gains, torque limit, stroke timing, force-direction
option and setpoint; the robot (kinematics, inertia, drag constant, paw buoyancy) and the leg pairs are
shared. One :meth:`BatchController.step` runs :func:`controller_batch_step`, a loop over the trials
(compiled by numba when it is installed, :mod:`quadruped_common.jit`) that calls the robot's own float
functions per trial:

1. eq. (error), (pid) with both anti-windup discretisations, (sat):
   :func:`~quadruped_control.control.controller.control_law_f`, the function the robot's controller runs;
2. the paper's power/recovery stroke cycle (:class:`~quadruped_control.control.strokes.paper.StrokeCycle`)
   with the allocation of eq. (foot_speed), (foot_vel) latched at each power start
   (:func:`~quadruped_control.control.allocation.foot_velocity_command_f`), eq. (foot_integration), the
   cubic retrace (:func:`~quadruped_control.control.strokes.base.cubic_time_profile`) and the leg IK
   (:func:`~quadruped_control.model.kinematics.ik_row`, the core of the robot's ``joint_angles_floats``).

The stroke cycle's phase logic is written here once more, on per-trial state arrays instead of the
robot's objects (pairs, recorded paths); the tests step both side by side and require every state to be
equal. What the compiled loop leaves out, because no simulated trial of the paper's scheme reaches it: the
hold (safe state, scheme switches; a trial whose measurement the float controller would refuse is
reported as ``refused``, frozen and stops being trusted) and timing changes during a trial.

:class:`ControllerObjects` runs everything else: the robot's own
:class:`~quadruped_control.control.controller.AttitudeController` objects, one per trial, stepped one
after another with the same interface. The batch uses it for the coordinated stroke scheme (its
workspace search and planned paths live on objects, and a second copy of them on arrays would be a
second controller) and for trials with the controller switched off; only the plant, the servos and the
recording are batched then.

Each power stroke is recorded per trial and leg as the robot's
:class:`~quadruped_control.control.strokes.base.StrokePath` records it (the points reached, their IK
solutions and cumulative lengths, on arrays of ``path_capacity`` points), and the recovery retraces it
with :func:`~quadruped_control.control.strokes.base.arc_length_point`, the arithmetic
``StrokePath.at_arc_length`` runs: the batch computes the robot's foot targets to the same bits, the
fallback to the nearest recorded point included (counted in ``ik_fallbacks``).
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np

from quadruped_common.jit import hypot3, jitable, kernel
from quadruped_common.robot import LEGS
from quadruped_control.control.allocation import foot_velocity_command_f
from quadruped_control.control.controller import AttitudeController, control_law_f
from quadruped_control.control.controller_config import ControllerConfig
from quadruped_control.control.strokes.base import TIME_EPS, arc_length_point, arc_length_segment, cubic_time_profile
from quadruped_control.model.kinematics import _geometry, ik_row, joint_angles_floats
from quadruped_control.model.params import RobotParams

__all__ = ["BatchController", "ControllerObjects", "controller_batch_step"]


@jitable
def _clamped_ik(x, y, z, frame, g):
    """ik_row of the target (x, y, z), the angles clamped exactly into the servo ranges as
    :meth:`StrokeCycle.ik` clamps them: (reached, theta1, theta2, theta3)."""
    ok, t1, t2, t3 = ik_row(x, y, z, frame, g)
    t1 = g[7] if g[7] > t1 else t1
    t2 = g[9] if g[9] > t2 else t2
    t3 = g[11] if g[11] > t3 else t3
    return ok, (g[8] if g[8] < t1 else t1), (g[10] if g[10] < t2 else t2), (g[12] if g[12] < t3 else t3)


@jitable
def _start_power(i, pair, legs, frames, k_drag, t_pow_max, normalize, tau_sat, omega, positions, joints, velocities,
                 path_points, path_joints, path_length, path_count, power, phase_time, t_pow):
    """:meth:`StrokeCycle._start_power`: latch eq. (foot_vel) with each leg's share tau_sat / 4 and start
    each leg's recorded stroke at its current point."""
    power[i, pair] = True
    phase_time[i, pair] = 0.0
    t_pow[i, pair] = t_pow_max[i]
    tau = (0.25 * tau_sat[i, 0], 0.25 * tau_sat[i, 1], 0.25 * tau_sat[i, 2])
    w = (omega[i, 0], omega[i, 1], omega[i, 2])
    for slot in range(2):
        leg = legs[pair, slot]
        start = (positions[i, leg, 0], positions[i, leg, 1], positions[i, leg, 2])
        vx, vy, vz = foot_velocity_command_f(tau, start, w, k_drag, normalize[i])
        if not (math.isfinite(vx) and math.isfinite(vy) and math.isfinite(vz)):
            vx = vy = vz = 0.0  # defensive, as the float path: a non-finite command means no stroke
        velocities[i, leg, 0], velocities[i, leg, 1], velocities[i, leg, 2] = vx, vy, vz
        for k in range(3):
            path_points[i, leg, 0, k] = positions[i, leg, k]
            path_joints[i, leg, 0, k] = joints[i, leg, k]
        path_length[i, leg, 0] = 0.0
        path_count[i, leg] = 1


@jitable
def _record(i, leg, x, y, z, t1, t2, t3, path_points, path_joints, path_length, path_count) -> bool:
    """:meth:`StrokePath.append`: the next point of the stroke (not stored when it equals the last);
    False if the path is full (the capacity covers t_pow_max, see :class:`BatchController`)."""
    n = path_count[i, leg]
    step = hypot3(x - path_points[i, leg, n - 1, 0], y - path_points[i, leg, n - 1, 1], z - path_points[i, leg, n - 1, 2])
    if step == 0.0:
        return True
    if n >= path_points.shape[2]:
        return False
    path_points[i, leg, n, 0], path_points[i, leg, n, 1], path_points[i, leg, n, 2] = x, y, z
    path_joints[i, leg, n, 0], path_joints[i, leg, n, 1], path_joints[i, leg, n, 2] = t1, t2, t3
    path_length[i, leg, n] = path_length[i, leg, n - 1] + step
    path_count[i, leg] = n + 1
    return True


@jitable
def _power_step(i, pair, legs, h, frames, g, t_rec, positions, joints, velocities, path_points, path_joints,
                path_length, path_count, power, phase_time, t_move, t_total, t_pow, refused):
    """:meth:`StrokeCycle._power_step`: eq. (foot_integration), IK and the recorded stroke; the phase ends
    at the workspace boundary or after t_pow (then :meth:`StrokeCycle._start_recovery`)."""
    phase_time[i, pair] += h
    boundary = False
    for slot in range(2):
        leg = legs[pair, slot]
        x, y, z = positions[i, leg, 0], positions[i, leg, 1], positions[i, leg, 2]
        tx, ty, tz = x + velocities[i, leg, 0] * h, y + velocities[i, leg, 1] * h, z + velocities[i, leg, 2] * h
        if tx == x and ty == y and tz == z:
            continue
        ok, t1, t2, t3 = _clamped_ik(tx, ty, tz, frames[leg], g)
        if not ok:
            boundary = True  # workspace boundary: keep the last reachable point
            continue
        positions[i, leg, 0], positions[i, leg, 1], positions[i, leg, 2] = tx, ty, tz
        joints[i, leg, 0], joints[i, leg, 1], joints[i, leg, 2] = t1, t2, t3
        if not _record(i, leg, tx, ty, tz, t1, t2, t3, path_points, path_joints, path_length, path_count):
            refused[i] = True  # a stroke longer than its record: no longer the robot's; not trusted
    if boundary or phase_time[i, pair] >= t_pow[i, pair] - TIME_EPS:
        power[i, pair] = False
        phase_time[i, pair] = 0.0
        t_move[i, pair] = t_rec[i]
        t_total[i, pair] = t_rec[i]
        for slot in range(2):
            leg = legs[pair, slot]
            for k in range(3):
                velocities[i, leg, k] = 0.0


@jitable
def _recovery_step(i, pair, legs, h, frames, g, positions, joints, path_points, path_joints, path_length, path_count,
                   phase_time, t_move, t_total, ik_fallbacks) -> bool:
    """:meth:`StrokeCycle._recovery_step`: the cubic retrace of the recorded stroke; True when the phase
    is over (the caller starts the power phase)."""
    time = phase_time[i, pair] + h
    phase_time[i, pair] = time
    s = cubic_time_profile(time / t_move[i, pair]) if t_move[i, pair] > 0.0 else 1.0
    done = time >= t_total[i, pair] - TIME_EPS
    for slot in range(2):
        leg = legs[pair, slot]
        if done or s >= 1.0:
            for k in range(3):
                positions[i, leg, k] = path_points[i, leg, 0, k]
                joints[i, leg, k] = path_joints[i, leg, 0, k]
            continue
        # StrokePath.at_arc_length(length (1 - s)), with s < 1 here
        last = path_count[i, leg] - 1
        a = path_length[i, leg, last] * (1.0 - s)
        if a <= 0.0 or path_length[i, leg, last] <= 0.0:
            px, py, pz, nearest = path_points[i, leg, 0, 0], path_points[i, leg, 0, 1], path_points[i, leg, 0, 2], 0
        elif a >= path_length[i, leg, last]:
            px, py, pz, nearest = (path_points[i, leg, last, 0], path_points[i, leg, last, 1],
                                   path_points[i, leg, last, 2], last)
        else:
            px, py, pz, nearest = arc_length_point(path_points[i, leg], path_length[i, leg],
                                                   arc_length_segment(path_length[i, leg], last + 1, a), a)
        if px == positions[i, leg, 0] and py == positions[i, leg, 1] and pz == positions[i, leg, 2]:
            continue
        ok, t1, t2, t3 = _clamped_ik(px, py, pz, frames[leg], g)
        if not ok:
            # the chord between two recorded (reachable) points left the workspace: the nearest one
            ik_fallbacks[i] += 1
            px, py, pz = path_points[i, leg, nearest, 0], path_points[i, leg, nearest, 1], path_points[i, leg, nearest, 2]
            t1, t2, t3 = path_joints[i, leg, nearest, 0], path_joints[i, leg, nearest, 1], path_joints[i, leg, nearest, 2]
        positions[i, leg, 0], positions[i, leg, 1], positions[i, leg, 2] = px, py, pz
        joints[i, leg, 0], joints[i, leg, 1], joints[i, leg, 2] = t1, t2, t3
    return done


@kernel
def controller_batch_step(h, R, omega_measured, R_d, gains, limits, t_rec, t_pow_max, normalize, inertia, gyroscopic,
                          buoyancy, net_buoyancy, k_drag, max_angular_rate, legs, frames, g, integral, delta_sat,
                          tau_sat, omega, e_R, geodesic, tau_cmd, saturated, positions, joints, velocities,
                          path_points, path_joints, path_length, path_count, power, phase_time, t_move, t_total,
                          t_pow, refused, ik_fallbacks):
    """One control step of every trial not yet ``refused``, in place on the state arrays (N leading).

    ``R`` (N, 3, 3), ``omega_measured`` (N, 3): the measurement; ``R_d`` (N, 9) the setpoints; ``gains``
    (N, 4) K_p, K_i, K_d, K_aw; ``limits`` (N, 2) tau_max, integral_limit; ``legs`` (2, 2) the pairs'
    legs (0-based); ``frames`` (4, 6) and ``g`` (13 floats) the IK geometry of
    :func:`~quadruped_control.model.kinematics.ik_row` (a1 .. l_z, then the servo ranges)."""
    for i in range(R.shape[0]):
        if refused[i]:
            continue
        wx, wy, wz = omega_measured[i, 0], omega_measured[i, 1], omega_measured[i, 2]
        if not (abs(wx) <= max_angular_rate and abs(wy) <= max_angular_rate and abs(wz) <= max_angular_rate):
            refused[i] = True  # the float controller raises (the robot would hold): not trusted from here
            continue
        sx = sy = sz = 0.0
        if buoyancy:
            for leg in range(4):
                sx += positions[i, leg, 0]
                sy += positions[i, leg, 1]
                sz += positions[i, leg, 2]
        Ri = (R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2], R[i, 2, 0], R[i, 2, 1],
              R[i, 2, 2])
        law = control_law_f(R_d[i], Ri, wx, wy, wz, integral[i], delta_sat[i], h, gains[i, 0], gains[i, 1],
                            gains[i, 2], gains[i, 3], limits[i, 0], limits[i, 1], inertia, gyroscopic, buoyancy,
                            (sx, sy, sz), net_buoyancy)
        e_R[i, 0], e_R[i, 1], e_R[i, 2], geodesic[i] = law[0], law[1], law[2], law[3]
        integral[i, 0], integral[i, 1], integral[i, 2] = law[4], law[5], law[6]
        tau_cmd[i, 0], tau_cmd[i, 1], tau_cmd[i, 2] = law[7], law[8], law[9]
        tau_sat[i, 0], tau_sat[i, 1], tau_sat[i, 2] = law[10], law[11], law[12]
        saturated[i] = law[13]
        delta_sat[i, 0], delta_sat[i, 1], delta_sat[i, 2] = law[7] - law[10], law[8] - law[11], law[9] - law[12]
        omega[i, 0], omega[i, 1], omega[i, 2] = wx, wy, wz
        # StrokeCycle.advance: pair 0 then pair 1, each its power or its recovery step
        for pair in range(2):
            in_power = power[i, pair]  # the phase at the step's start: a power step may end it
            if in_power:
                if h > 0.0:
                    _power_step(i, pair, legs, h, frames, g, t_rec, positions, joints, velocities, path_points,
                                path_joints, path_length, path_count, power, phase_time, t_move, t_total, t_pow,
                                refused)
            elif _recovery_step(i, pair, legs, h, frames, g, positions, joints, path_points, path_joints, path_length,
                                path_count, phase_time, t_move, t_total, ik_fallbacks):
                _start_power(i, pair, legs, frames, k_drag, t_pow_max, normalize, tau_sat, omega, positions, joints,
                             velocities, path_points, path_joints, path_length, path_count, power, phase_time, t_pow)


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
        self.inertia = tuple(float(x) for x in np.asarray(robot.inertia, dtype=float).ravel())
        self.k_drag = float(robot.drag_constant)
        self.net_buoyancy = float(robot.paw_net_buoyancy)
        geometry = _geometry(robot)
        self.frames = np.array(geometry[1], dtype=float)
        self.ik_constants = tuple(float(x) for x in geometry[2:15])
        self.pairs = first.pairs
        self.legs = np.array([[leg - 1 for leg in pair] for pair in self.pairs], dtype=np.int64)
        nominal = np.array([robot.nominal_foot_body(leg) for leg in LEGS], dtype=float)
        low, high = np.array(geometry[9:15:2]), np.array(geometry[10:15:2])
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
        self.positions = np.tile(self.nominal, (n, 1, 1))
        self.joints = np.tile(self.nominal_joints, (n, 1, 1))
        self.velocities = np.zeros((n, 4, 3))
        # Each leg's recorded stroke (StrokePath on arrays); at the start a path of one point, the foot.
        capacity = self.path_capacity
        self.path_points = np.zeros((n, 4, capacity, 3))
        self.path_joints = np.zeros((n, 4, capacity, 3))
        self.path_length = np.zeros((n, 4, capacity))
        self.path_points[:, :, 0, :] = self.positions
        self.path_joints[:, :, 0, :] = self.joints
        self.path_count = np.ones((n, 4), dtype=np.int64)
        self.power = np.zeros((n, 2), dtype=bool)
        self.phase_time = np.zeros((n, 2))
        self.t_move = np.zeros((n, 2))
        self.t_total = np.zeros((n, 2))
        self.t_total[:, 0] = 0.5 * self.t_rec
        self.t_pow = np.zeros((n, 2))
        #: trials whose measurement the float controller would have refused (it would hold)
        self.refused = np.zeros(n, dtype=bool)
        self.ik_fallbacks = np.zeros(n, dtype=np.int64)

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
                              self.inertia, self.gyroscopic, self.buoyancy, self.net_buoyancy, self.k_drag,
                              self.max_angular_rate, self.legs, self.frames, self.ik_constants, self.integral,
                              self.delta_sat, self.tau_sat, self.omega, self.e_R, self.geodesic, self.tau_cmd,
                              self.saturated, self.positions, self.joints, self.velocities, self.path_points,
                              self.path_joints, self.path_length, self.path_count, self.power, self.phase_time,
                              self.t_move, self.t_total, self.t_pow, self.refused, self.ik_fallbacks)
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
