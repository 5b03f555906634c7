"""The paper's power/recovery stroke cycle (section "Attitude Controller Design"), written once.

The robot's :class:`~quadruped_control.control.strokes.paper.StrokeCycle` (one trial) and the batched
simulator's controller (:mod:`quadruped_control.sim.batch_controller`, a compiled loop over N trials) both
run the functions of this module on a :class:`CycleState`: arrays whose first index is the trial ``i``.
They are :func:`~quadruped_common.jit.jitable`: plain Python for the robot, inlined into the batch's
kernel. One step of a pair is three calls, the inverse kinematics between them being the caller's:

1. ``targets = power_targets(...)`` or ``recovery_targets(...)``: where each foot of the pair goes;
2. the caller solves the IK of each target that moves (:class:`LegSolution`; the robot with its own,
   possibly injected, IK, which raises UnreachableError; the batch with
   :func:`~quadruped_control.model.kinematics.ik_row`, which reports it);
3. ``power_step(...)`` or ``recovery_step(...)`` takes the solutions and advances the phase; a recovery
   that is over returns True and the caller starts the power phase with :func:`start_power`, handing it
   the velocity command of eq. (foot_vel) for each leg at its start point.

The cycle:

- Start-up (:func:`wait_at_start`): the first pair waits t_rec / 2 at its start point (a recovery with
  nothing to retrace), the second pair starts a power phase at once.
- Power phase: v^cmd latched at the start (:func:`start_power`, eq. (foot_vel)); each step
  r(t + h) = r(t) + v^cmd h, eq. (foot_integration) (:func:`power_targets`), mapped by the IK and recorded
  (:func:`record_point`). It ends when a foot's target is unreachable (a workspace boundary: that foot
  keeps its last reachable point) or after t_pow^max (:func:`start_recovery`).
- Recovery phase: each foot retraces its recorded stroke, by arc length from the end, with the cubic time
  profile s(u) = 3 u^2 - 2 u^3, u = t / t_rec; where the chord between two recorded points is
  unreachable, the foot takes the nearest recorded point (counted in ``ik_fallbacks``). It ends exactly
  at the stroke's start after t_total (t_rec, or t_rec / 2 at start-up).

A recorded stroke holds at most ``capacity`` points (the path arrays' third dimension): a point that
does not fit sets ``overflowed[i]`` (the batch sizes its arrays for t_pow^max and refuses such a trial;
the robot enlarges its arrays before a power step, :func:`path_nearly_full`, so its strokes have no
limit).
"""
from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from quadruped_common.jit import hypot3, jitable
from quadruped_common.vec3 import ZERO, Vec3, add, scale
from quadruped_control.control.strokes.base import TIME_EPS, arc_length_point, arc_length_segment, cubic_time_profile

__all__ = ["CycleState", "LegSolution", "LegTarget", "PairSolutions", "PairTargets", "RecoveryClock", "RecoveryTargets",
           "new_cycle_state", "path_nearly_full", "power_step", "power_targets", "record_point",
           "recovery_clock", "recovery_step", "recovery_targets", "start_power", "start_recovery", "wait_at_start"]


class CycleState(NamedTuple):
    """The stroke cycle of N trials (first index ``i``), 4 legs (0-based ``leg``), 2 pairs."""

    positions: Any      #: (N, 4, 3) commanded foot positions r_e,i^B, m
    joints: Any         #: (N, 4, 3) their joint targets, rad
    velocities: Any     #: (N, 4, 3) latched v_i^cmd (zero outside power phases), m/s
    path_points: Any    #: (N, 4, capacity, 3) each foot's recorded stroke, point 0 its start
    path_joints: Any    #: (N, 4, capacity, 3) the IK solutions of the recorded points
    path_length: Any    #: (N, 4, capacity) cumulative arc length along the stroke, m
    path_count: Any     #: (N, 4) recorded points (int64)
    power: Any          #: (N, 2) the pair is in its power phase (bool)
    phase_time: Any     #: (N, 2) time since the phase started, s
    t_move: Any         #: (N, 2) duration of the cubic retrace (recovery), s
    t_total: Any        #: (N, 2) duration of the recovery phase (>= t_move), s
    t_pow: Any          #: (N, 2) t_pow^max latched at the power start, s
    ik_fallbacks: Any   #: (N,) recovery points replaced by the nearest recorded one (int64)
    overflowed: Any     #: (N,) a stroke had more points than its record holds (bool)


def new_cycle_state(n: int, capacity: int, nominal: Any, nominal_joints: Any) -> CycleState:
    """N trials with every foot at ``nominal`` (4 x 3) with ``nominal_joints``, strokes of one point, every
    pair in a recovery of zero duration (call :func:`wait_at_start` to schedule the start-up)."""
    positions = np.tile(np.asarray(nominal, dtype=float), (n, 1, 1))
    joints = np.tile(np.asarray(nominal_joints, dtype=float), (n, 1, 1))
    path_points = np.zeros((n, 4, capacity, 3))
    path_joints = np.zeros((n, 4, capacity, 3))
    path_points[:, :, 0, :] = positions
    path_joints[:, :, 0, :] = joints
    return CycleState(positions, joints, np.zeros((n, 4, 3)), path_points, path_joints, np.zeros((n, 4, capacity)),
                      np.ones((n, 4), dtype=np.int64), np.zeros((n, 2), dtype=bool), np.zeros((n, 2)),
                      np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(n, dtype=np.int64),
                      np.zeros(n, dtype=bool))


class LegTarget(NamedTuple):
    """Where one foot goes this step: ``moves`` False when it stays or its point is known (no IK needed);
    (x, y, z) the target; ``nearest`` the recorded point nearest to it (recovery)."""

    moves: bool
    x: float
    y: float
    z: float
    nearest: int


class PairTargets(NamedTuple):
    """The :class:`LegTarget` of the pair's first and second leg."""

    first: LegTarget
    second: LegTarget


class LegSolution(NamedTuple):
    """The caller's IK of a :class:`LegTarget`: ``reached`` and the joint angles clamped into the servo
    ranges (meaningless when not reached or when the target does not move)."""

    reached: bool
    theta1: float
    theta2: float
    theta3: float


class PairSolutions(NamedTuple):
    """The :class:`LegSolution` of the pair's first and second leg."""

    first: LegSolution
    second: LegSolution


class RecoveryClock(NamedTuple):
    """A recovery step's ``time`` since the phase started, the retrace fraction ``s`` of the cubic time
    profile and whether the phase is ``done``."""

    time: float
    s: float
    done: bool


class RecoveryTargets(NamedTuple):
    """A recovery step of a pair: its :class:`RecoveryClock` and the :class:`LegTarget` of its first and
    second leg (the clock goes on to :func:`recovery_step`, which need not compute it again)."""

    clock: RecoveryClock
    first: LegTarget
    second: LegTarget


@jitable
def _point(a, i, leg) -> Vec3:
    return (a[i, leg, 0], a[i, leg, 1], a[i, leg, 2])


@jitable
def _set_point(a, i, leg, v) -> None:
    a[i, leg, 0], a[i, leg, 1], a[i, leg, 2] = v[0], v[1], v[2]


@jitable
def _path_point(a, i, leg, k) -> Vec3:
    return (a[i, leg, k, 0], a[i, leg, k, 1], a[i, leg, k, 2])


@jitable
def _restart_path(st, i, leg) -> None:
    """The foot's recorded stroke := its current point (and joints), one point."""
    for k in range(3):
        st.path_points[i, leg, 0, k] = st.positions[i, leg, k]
        st.path_joints[i, leg, 0, k] = st.joints[i, leg, k]
    st.path_length[i, leg, 0] = 0.0
    st.path_count[i, leg] = 1


@jitable
def wait_at_start(st, i, pair, legs, t_wait) -> None:
    """Start-up: the pair rests at its current point for ``t_wait`` s (a recovery with nothing to
    retrace; t_rec / 2 for the first pair, 0 for the second), then starts its power phase."""
    st.power[i, pair] = False
    st.phase_time[i, pair] = 0.0
    st.t_move[i, pair] = 0.0
    st.t_total[i, pair] = t_wait
    for slot in range(2):
        leg = legs[pair, slot]
        _set_point(st.velocities, i, leg, ZERO)
        _restart_path(st, i, leg)


@jitable
def start_power(st, i, pair, legs, t_pow_max, first: Vec3, second: Vec3) -> None:
    """Power start: latch each leg's v^cmd of eq. (foot_vel) (``first``, ``second``: the velocity commands
    at the feet's current points; a non-finite one means no stroke) and t_pow^max; each foot's recorded
    stroke starts at its current point."""
    st.power[i, pair] = True
    st.phase_time[i, pair] = 0.0
    st.t_pow[i, pair] = t_pow_max
    for slot in range(2):
        leg = legs[pair, slot]
        v_cmd = first if slot == 0 else second
        if not (math.isfinite(v_cmd[0]) and math.isfinite(v_cmd[1]) and math.isfinite(v_cmd[2])):
            v_cmd = ZERO  # defensive: a non-finite command means no stroke
        _set_point(st.velocities, i, leg, v_cmd)
        _restart_path(st, i, leg)


@jitable
def start_recovery(st, i, pair, legs, t_rec) -> None:
    """Recovery start: the pair retraces its strokes over t_rec (t_move = t_total = t_rec), no command."""
    st.power[i, pair] = False
    st.phase_time[i, pair] = 0.0
    st.t_move[i, pair] = t_rec
    st.t_total[i, pair] = t_rec
    for slot in range(2):
        _set_point(st.velocities, i, legs[pair, slot], ZERO)


@jitable
def path_nearly_full(st, i, pair, legs) -> bool:
    """True when a power step could find a stroke of the pair full (one more point than it holds)."""
    capacity = st.path_points.shape[2]
    return st.path_count[i, legs[pair, 0]] >= capacity or st.path_count[i, legs[pair, 1]] >= capacity


@jitable
def record_point(st, i, leg, r: Vec3, q: Vec3) -> None:
    """The stroke's next point r with its joints q (not stored when it equals the last one; sets
    ``overflowed`` when the record is full)."""
    n = st.path_count[i, leg]
    last = _path_point(st.path_points, i, leg, n - 1)
    step = hypot3(r[0] - last[0], r[1] - last[1], r[2] - last[2])
    if step == 0.0:
        return
    if n >= st.path_points.shape[2]:
        st.overflowed[i] = True
        return
    for k in range(3):
        st.path_points[i, leg, n, k] = r[k]
        st.path_joints[i, leg, n, k] = q[k]
    st.path_length[i, leg, n] = st.path_length[i, leg, n - 1] + step
    st.path_count[i, leg] = n + 1


@jitable
def _power_target(st, i, leg, h) -> LegTarget:
    r = _point(st.positions, i, leg)
    r_next = add(r, scale(h, _point(st.velocities, i, leg)))  # eq. (foot_integration)
    moves = not (r_next[0] == r[0] and r_next[1] == r[1] and r_next[2] == r[2])
    return LegTarget(moves, r_next[0], r_next[1], r_next[2], 0)


@jitable
def power_targets(st, i, pair, legs, h) -> PairTargets:
    """The pair's feet after ``h`` s of power, eq. (foot_integration): r(t + h) = r(t) + v^cmd h."""
    return PairTargets(_power_target(st, i, legs[pair, 0], h), _power_target(st, i, legs[pair, 1], h))


@jitable
def _power_leg(st, i, leg, target: LegTarget, solution: LegSolution) -> bool:
    """One foot's power step; True at the workspace boundary (the foot keeps its last reachable point)."""
    if not target.moves:
        return False  # zero command: no motion, the IK solution is current
    if not solution.reached:
        return True
    r = (target.x, target.y, target.z)
    q = (solution.theta1, solution.theta2, solution.theta3)
    _set_point(st.positions, i, leg, r)
    _set_point(st.joints, i, leg, q)
    record_point(st, i, leg, r, q)
    return False


@jitable
def power_step(st, i, pair, legs, h, t_rec, targets: PairTargets, solutions: PairSolutions) -> None:
    """``h`` > 0 s of the pair's power phase to the :func:`power_targets` the IK reached; the phase ends
    (:func:`start_recovery` with ``t_rec``) at a workspace boundary or after t_pow^max."""
    st.phase_time[i, pair] += h
    first_boundary = _power_leg(st, i, legs[pair, 0], targets.first, solutions.first)
    second_boundary = _power_leg(st, i, legs[pair, 1], targets.second, solutions.second)
    if first_boundary or second_boundary or st.phase_time[i, pair] >= st.t_pow[i, pair] - TIME_EPS:
        start_recovery(st, i, pair, legs, t_rec)


@jitable
def recovery_clock(st, i, pair, h) -> RecoveryClock:
    """The pair's recovery after ``h`` more s: s = 3 u^2 - 2 u^3, u = t / t_move (1 without a motion)."""
    time = st.phase_time[i, pair] + h
    t_move = st.t_move[i, pair]
    s = cubic_time_profile(time / t_move) if t_move > 0.0 else 1.0
    return RecoveryClock(time, s, time >= st.t_total[i, pair] - TIME_EPS)


@jitable
def _recovery_target(st, i, leg, clock: RecoveryClock) -> LegTarget:
    """The point at arc length (1 - s) L of the foot's recorded stroke (linear between recorded points)."""
    if clock.done or clock.s >= 1.0:
        start = _path_point(st.path_points, i, leg, 0)
        return LegTarget(False, start[0], start[1], start[2], 0)
    last = st.path_count[i, leg] - 1
    length = st.path_length[i, leg, last]
    a = length * (1.0 - clock.s)
    if a <= 0.0 or length <= 0.0:
        x, y, z = _path_point(st.path_points, i, leg, 0)
        nearest = 0
    elif a >= length:
        x, y, z = _path_point(st.path_points, i, leg, last)
        nearest = last
    else:
        x, y, z, nearest = arc_length_point(st.path_points[i, leg], st.path_length[i, leg],
                                            arc_length_segment(st.path_length[i, leg], last + 1, a), a)
    r = _point(st.positions, i, leg)
    moves = not (x == r[0] and y == r[1] and z == r[2])
    return LegTarget(moves, x, y, z, nearest)


@jitable
def recovery_targets(st, i, pair, legs, h) -> RecoveryTargets:
    """The pair's feet after ``h`` more s of recovery (:func:`recovery_clock`) on their recorded strokes."""
    clock = recovery_clock(st, i, pair, h)
    return RecoveryTargets(clock, _recovery_target(st, i, legs[pair, 0], clock),
                           _recovery_target(st, i, legs[pair, 1], clock))


@jitable
def _recovery_leg(st, i, leg, clock: RecoveryClock, target: LegTarget, solution: LegSolution) -> None:
    if clock.done or clock.s >= 1.0:  # at the stroke's start, with its recorded joints
        _set_point(st.positions, i, leg, _path_point(st.path_points, i, leg, 0))
        _set_point(st.joints, i, leg, _path_point(st.path_joints, i, leg, 0))
        return
    if not target.moves:
        return  # not moving (e.g. at rest between strokes): the IK solution is current
    if solution.reached:
        _set_point(st.positions, i, leg, (target.x, target.y, target.z))
        _set_point(st.joints, i, leg, (solution.theta1, solution.theta2, solution.theta3))
        return
    # The chord between two recorded (reachable) points left the workspace: the nearest recorded point.
    st.ik_fallbacks[i] += 1
    _set_point(st.positions, i, leg, _path_point(st.path_points, i, leg, target.nearest))
    _set_point(st.joints, i, leg, _path_point(st.path_joints, i, leg, target.nearest))


@jitable
def recovery_step(st, i, pair, legs, targets: RecoveryTargets, solutions: PairSolutions) -> bool:
    """The pair's recovery step to its :func:`recovery_targets` (the nearest recorded point where the IK
    did not reach); True when the phase is over (the caller then calls :func:`start_power`)."""
    clock = targets.clock
    st.phase_time[i, pair] = clock.time
    _recovery_leg(st, i, legs[pair, 0], clock, targets.first, solutions.first)
    _recovery_leg(st, i, legs[pair, 1], clock, targets.second, solutions.second)
    return clock.done
