"""The coordinated stroke scheme ``coordinated`` (beyond the paper; its section "Discussion" names the limits
this scheme addresses: simultaneous recoveries leave torque gaps, and retracting to a fixed point near the
workspace centre leaves the power stroke about half of the range).

Rules (the reasoning, with figures, is in docs/stroke_schemes.md):

- **Alternation with hand-over.** One pair strokes at a time. When the pair in power ends its stroke, the
  other pair starts its power stroke in the same control step if it is ready (back at its start point);
  otherwise it starts the moment its recovery ends. The pairs are tied to each other's events, not to
  clocks, so they keep their order and cannot drift into simultaneous strokes. While nothing is demanded
  the pair in power stands still (zero velocity) and the other waits: no stroke, no reverse drag.
- **Allocation.** Only the legs in power make torque, so the pair in power gets the whole saturated
  torque: tau_i = tau_sat / 2 per leg, with eq. (foot_speed) and (foot_vel) (the controller's velocity
  callback with share 1/2; the paper's scheme uses tau_sat / 4 although only two legs stroke at a time).
- **Power strokes use the whole workspace.** The velocity command is latched at the stroke start (the
  servos need a steady target, as in the paper) and latched again from the current point every t_pow^max,
  so a long stroke follows the controller; the stroke runs, eq. (foot_integration), until the next point
  leaves the workspace with margin (:mod:`quadruped_control.control.strokes.workspace`: 5 degrees inside every
  servo range, one grid cell inside the reach of the five-bar). A step whose joint change exceeds what
  the servos can turn in one period (``speed_fraction`` of the no-load speed) is shortened along the same
  line, so the feet never outrun the servos.
- **Recovery to where the next stroke has range.** A recovery ends at the start of the longest straight
  stroke inside the workspace along the direction the allocation gives that leg *now*
  (:meth:`Workspace.best_start`), not at the nominal point. The path is the straight segment to it (or
  via the nominal point, or, failing both, the reverse of the power stroke, always reachable), sampled
  every ``path_sample`` m through the IK and followed with the cubic time profile of the paper
  (:func:`~quadruped_control.control.strokes.paper.cubic_time_profile`). A ready pair whose start point has lost
  its range because the demanded direction changed moves to the new best start.
- **Recovery time from physics.** The drag of a returning paw opposes the stroke, F = k v^2 (eq.
  (force_leg)): over one cycle a leg with stroke length L, power time T_p and recovery time T_r gives the
  impulse k |r| L^2 (1/T_p - 1/T_r) over T_p + T_r; the mean torque (1/T_p - 1/T_r) / (T_p + T_r) is largest
  at T_r = (1 + sqrt 2) T_p (``recovery_ratio``). The recovery lasts that long (at most t_rec), but never
  less than the servos need: 1.5 x (largest joint travel along the path) / (``speed_fraction`` x no-load
  speed), the factor 1.5 being the peak-to-mean speed of the cubic profile.
  Note the trade-off this exposes: a recovery that always fits inside the other pair's stroke
  (T_r <= T_p) returns at least as fast as the stroke went out and cancels its impulse; with two pairs, an
  uninterrupted power phase and a positive net torque exclude each other for straight strokes. The scheme
  chooses the net torque; ``recovery_ratio`` = 1 gives the uninterrupted alternative.
- **Hold.** No new strokes; every foot goes straight (or back along its stroke) to the nominal pose over
  max(t_rec, the servo time), with the cubic profile, then stays. Leaving the hold, the pairs start again
  from where the feet are.

Every joint target comes from a successful IK, clamped into the servo ranges; nothing here returns NaN.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

from quadruped_common.robot import LEGS, MIRROR_DIAG
from quadruped_common.schema import Param
from quadruped_control.control.strokes.base import (PHASE_HOLD, PHASE_POWER, PHASE_RECOVERY, TIME_EPS, PairState,
                                                    StrokePath, StrokeScheme, Vec3, VelocityCommand, cubic_time_profile)
from quadruped_control.control.strokes.workspace import Workspace, leg_workspace
from quadruped_control.model.kinematics import UnreachableError, joint_angles_floats
from quadruped_control.model.params import RobotParams

__all__ = ["COORDINATED_PARAMS", "CoordinatedParams", "CoordinatedStrokes", "DRAG_OPTIMAL_RECOVERY_RATIO"]

#: T_rec / T_pow maximising the mean torque of one leg's cycle, (1/T_p - 1/T_r) / (T_p + T_r): 1 + sqrt(2).
DRAG_OPTIMAL_RECOVERY_RATIO = 1.0 + math.sqrt(2.0)
#: Peak speed of the cubic time profile relative to its mean (s'(1/2) = 3/2).
CUBIC_PEAK_TO_MEAN = 1.5
#: Share of tau_sat per leg while one pair strokes.
PAIR_SHARE = 0.5
_READY = "ready"  # internal: back at the start point, waiting for the hand-over (reported as recovery)

#: The ``stroke.coordinated`` keys of config/controller.yaml, declared once for the file (they are part of
#: :data:`~quadruped_control.control.controller_config.CONTROLLER_SCHEMA`) and for :class:`CoordinatedParams`.
COORDINATED_PARAMS: Tuple[Param, ...] = (
    Param("stroke.coordinated.joint_margin_deg", "deg", "workspace margin inside every servo range", 0.0, 30.0,
          default=5.0, source="choice"),
    Param("stroke.coordinated.speed_fraction", "", "fraction of the servo no-load speed the planned foot paths may "
          "use", 0.05, 1.0, default=0.8, source="choice"),
    Param("stroke.coordinated.recovery_ratio", "", "T_rec / T_pow: 1 + sqrt(2) maximises a leg's mean torque with "
          "drag ~ v^2", 0.1, 100.0, default=DRAG_OPTIMAL_RECOVERY_RATIO, source="choice"),
    Param("stroke.coordinated.path_sample", "m", "spacing of the IK samples along a recovery path", 0.002, 0.1,
          default=0.02, source="choice"),
    Param("stroke.coordinated.replan_fraction", "", "a waiting pair re-plans when its stroke has less than this "
          "fraction of the best range", 0.0, 1.0, default=0.6, source="choice"),
    Param("stroke.coordinated.workspace_radius", "m", "strokes stay within this distance of the nominal foot point",
          0.01, 0.3, default=0.035, source="choice"),
)
#: field of CoordinatedParams -> its declaration
_COORDINATED = {param.key.rsplit(".", 1)[1]: param for param in COORDINATED_PARAMS}


@dataclass(frozen=True)
class CoordinatedParams:
    """Parameters of the coordinated scheme (``stroke.coordinated`` in config/controller.yaml).

    ``joint_margin_deg``: servo-range margin of the workspace (deg); ``speed_fraction``: fraction of the
    servo no-load speed the planned foot paths may use; ``recovery_ratio``: T_rec / T_pow (default the
    drag-optimal 1 + sqrt 2); ``path_sample``: spacing of the IK samples along a recovery path (m);
    ``replan_fraction``: a ready pair moves to a new start when its stroke along the current direction is
    shorter than this fraction of the longest one.
    """

    joint_margin_deg: float = _COORDINATED["joint_margin_deg"].default
    speed_fraction: float = _COORDINATED["speed_fraction"].default
    recovery_ratio: float = _COORDINATED["recovery_ratio"].default
    path_sample: float = _COORDINATED["path_sample"].default
    replan_fraction: float = _COORDINATED["replan_fraction"].default
    workspace_radius: float = _COORDINATED["workspace_radius"].default

    def __post_init__(self) -> None:
        for name, param in _COORDINATED.items():  # each value through its declaration (ParameterError otherwise)
            object.__setattr__(self, name, param.read(getattr(self, name), param.key))


class _Pair(PairState):
    """State of one leg pair of the coordinated scheme (``paths``: recovery / hold paths, from the current
    point to the target)."""

    __slots__ = ("duration", "segment", "strokes", "t_pow_last")

    def __init__(self, legs: Tuple[int, int]) -> None:
        super().__init__(legs, _READY)
        self.duration = 0.0        # recovery: duration of the cubic motion along ``paths``
        self.segment = 0.0         # power: time since the velocity was last latched
        self.strokes: List[StrokePath] = []  # power: the recorded stroke of each leg
        self.t_pow_last = 0.0      # duration of the last finished power stroke


class CoordinatedStrokes(StrokeScheme):
    """The coordinated stroke scheme (see the module docstring).

    ``robot``: kinematics, nominal feet, servo speed; ``pairs``: the two leg pairs (the first strokes
    first); ``t_rec``: longest recovery (s); ``t_pow_max``: re-latch period of the velocity command (s);
    ``params``: :class:`CoordinatedParams`. Raises ParameterError if a nominal foot position is unreachable.
    """

    name = "coordinated"

    def __init__(self, robot: RobotParams, pairs: Sequence[Sequence[int]] = ((1, 3), (2, 4)),
                 t_rec: float = 1.5, t_pow_max: float = 0.5, params: Optional[CoordinatedParams] = None) -> None:
        self.params = params if params is not None else CoordinatedParams()
        super().__init__(robot, pairs, t_rec, t_pow_max)
        margin = math.radians(self.params.joint_margin_deg)
        self._margin_bounds = tuple((lo + margin, hi - margin) for lo, hi in self._bounds)
        self._max_joint_step_rate = self.params.speed_fraction * float(robot.servo_no_load_speed)
        self.workspace: Workspace = leg_workspace(robot, joint_margin=margin, radius=self.params.workspace_radius)
        self._frames = {leg: (MIRROR_DIAG[leg], tuple(robot.leg_origins[leg].tolist())) for leg in LEGS}
        self._last_power = 1
        self._start(_Pair)

    # ---- configuration -----------------------------------------------------------------------

    def ik(self, point: Vec3, leg: int) -> Vec3:
        """IK of ``point`` for ``leg``, clamped exactly into the servo ranges; raises UnreachableError."""
        t1, t2, t3 = joint_angles_floats(point[0], point[1], point[2], leg, self.robot)
        (l1, h1), (l2, h2), (l3, h3) = self._bounds
        return (min(max(t1, l1), h1), min(max(t2, l2), h2), min(max(t3, l3), h3))

    def set_timing(self, t_rec: Optional[float] = None, t_pow_max: Optional[float] = None) -> None:
        """New longest recovery and re-latch period (s); they apply from the next recovery / latch."""
        self.t_rec, self.t_pow_max = self._checked_timing(t_rec, t_pow_max, self.t_rec, self.t_pow_max)

    # ---- frames and workspace ----------------------------------------------------------------

    def _to_leg(self, point: Vec3, leg: int) -> Vec3:
        (mx, my, mz), (ox, oy, oz) = self._frames[leg]
        return mx * (point[0] - ox), my * (point[1] - oy), mz * (point[2] - oz)

    def _to_body(self, point: Vec3, leg: int) -> Vec3:
        (mx, my, mz), (ox, oy, oz) = self._frames[leg]
        return ox + mx * point[0], oy + my * point[1], oz + mz * point[2]

    def _inside(self, point: Vec3, leg: int) -> Optional[Vec3]:
        """Joint angles of ``point`` if it is inside the workspace with margin, else None."""
        x, y, z = self._to_leg(point, leg)
        if not self.workspace.inside(x, y, z):
            return None
        try:
            angles = self.ik(point, leg)
        except UnreachableError:
            return None
        for a, (lo, hi) in zip(angles, self._margin_bounds):
            if not lo <= a <= hi:
                return None
        return angles

    def _direction(self, leg: int, velocity_command: Optional[VelocityCommand]) -> Vec3:
        """Leg-frame direction of the power stroke the allocation asks of ``leg`` at its current point."""
        if velocity_command is None:
            return 0.0, 0.0, 0.0
        vx, vy, vz = velocity_command(leg, self.positions[leg - 1], PAIR_SHARE)
        if not math.isfinite(vx + vy + vz):
            return 0.0, 0.0, 0.0
        (mx, my, mz), _ = self._frames[leg]
        return mx * vx, my * vy, mz * vz

    # ---- state -------------------------------------------------------------------------------

    def reset(self) -> None:
        """All feet at the nominal pose; the first pair strokes first."""
        self.positions = list(self.nominal)
        self.joints = list(self.nominal_joints)
        self.holding = False
        self.hold_time = 0.0
        for pair in self._pairs:
            self._make_ready(pair)
            pair.t_pow_last = 0.0
        self._last_power = 1

    def _make_ready(self, pair: _Pair) -> None:
        pair.phase = _READY
        pair.time = 0.0
        pair.segment = 0.0
        pair.paths = []
        pair.velocities = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]

    @property
    def pair_phase(self) -> Tuple[str, str]:
        if self.holding:
            return PHASE_HOLD, PHASE_HOLD
        return tuple(PHASE_POWER if p.phase == PHASE_POWER else PHASE_RECOVERY  # type: ignore[return-value]
                     for p in self._pairs)

    # ---- stepping ----------------------------------------------------------------------------

    def advance(self, dt: float, velocity_command: VelocityCommand) -> None:
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError("dt must be a finite non-negative time step, got %r" % (dt,))
        if self.holding:
            self.holding = False
            self.hold_time = 0.0
            for pair in self._pairs:  # start again from where the feet are
                self._make_ready(pair)
            self._last_power = 1
        for pair in self._pairs:
            if pair.phase == PHASE_POWER:
                self._power_step(pair, dt, velocity_command)
        for pair in self._pairs:
            if pair.phase == PHASE_RECOVERY:
                self._move_step(pair, dt)
                if pair.time >= pair.duration - TIME_EPS:
                    self._make_ready(pair)
        if not any(pair.phase == PHASE_POWER for pair in self._pairs):
            # Hand-over: the pair that did not stroke last goes first.
            order = (1 - self._last_power, self._last_power)
            for index in order:
                if self._pairs[index].phase == _READY:
                    self._start_power(index, velocity_command)
                    break

    def _enter_hold(self) -> None:
        """Every foot moves straight back to its nominal point (cubic profile)."""
        for pair in self._pairs:
            self._plan(pair, [self.nominal[leg - 1] for leg in pair.legs], hold=True)
            pair.phase = PHASE_HOLD

    def _hold_step(self, dt: float) -> None:
        for pair in self._pairs:
            self._move_step(pair, dt)

    # ---- power -------------------------------------------------------------------------------

    def _latch(self, pair: _Pair, velocity_command: VelocityCommand) -> None:
        velocities = []
        for leg in pair.legs:
            vx, vy, vz = velocity_command(leg, self.positions[leg - 1], PAIR_SHARE)
            vel = (float(vx), float(vy), float(vz))
            if not math.isfinite(vel[0] + vel[1] + vel[2]):
                vel = (0.0, 0.0, 0.0)  # defensive: a non-finite command means no stroke
            velocities.append(vel)
        pair.velocities = velocities
        pair.segment = 0.0

    def _start_power(self, index: int, velocity_command: VelocityCommand) -> None:
        pair = self._pairs[index]
        pair.phase = PHASE_POWER
        pair.time = 0.0
        pair.strokes = [StrokePath(self.positions[leg - 1], self.joints[leg - 1]) for leg in pair.legs]
        self._latch(pair, velocity_command)
        self._last_power = index
        self._replan_waiting(self._pairs[1 - index], velocity_command)

    def _replan_waiting(self, pair: _Pair, velocity_command: VelocityCommand) -> None:
        """A ready pair whose start point has lost its range moves to the best start for the current demand."""
        if pair.phase != _READY:
            return
        for leg in pair.legs:
            direction = self._direction(leg, velocity_command)
            _, best = self.workspace.best_start(*direction)
            if best <= 0.0:
                continue
            here = self.workspace.chord_from(*self._to_leg(self.positions[leg - 1], leg), *direction)
            if here < self.params.replan_fraction * best:
                self._start_recovery(pair, velocity_command)
                return

    def _power_step(self, pair: _Pair, dt: float, velocity_command: VelocityCommand) -> None:
        if dt <= 0.0:
            return
        pair.time += dt
        pair.segment += dt
        if pair.segment >= self.t_pow_max - TIME_EPS:
            self._latch(pair, velocity_command)
            self._replan_waiting(self._pairs[1 - self._pairs.index(pair)], velocity_command)
        boundary = False
        limit = self._max_joint_step_rate * dt
        for slot, leg in enumerate(pair.legs):
            vx, vy, vz = pair.velocities[slot]
            if vx == 0.0 and vy == 0.0 and vz == 0.0:
                continue
            x, y, z = self.positions[leg - 1]
            target = (x + vx * dt, y + vy * dt, z + vz * dt)  # eq. (foot_integration)
            solution = self._inside(target, leg)
            if solution is not None:
                q0 = self.joints[leg - 1]
                largest = max(abs(solution[0] - q0[0]), abs(solution[1] - q0[1]), abs(solution[2] - q0[2]))
                if largest > limit:  # faster than the servos: shorten the step along the same line
                    scale = limit / largest
                    target = (x + vx * dt * scale, y + vy * dt * scale, z + vz * dt * scale)
                    solution = self._inside(target, leg)
            if solution is None:
                boundary = True  # workspace boundary (with margin): keep the last point
                continue
            self.positions[leg - 1] = target
            self.joints[leg - 1] = solution
            pair.strokes[slot].append(target, solution)
        if boundary:
            pair.t_pow_last = pair.time
            self._start_recovery(pair, velocity_command)

    # ---- recovery and hold -------------------------------------------------------------------

    def _start_recovery(self, pair: _Pair, velocity_command: VelocityCommand) -> None:
        targets = []
        for leg in pair.legs:
            start, _ = self.workspace.best_start(*self._direction(leg, velocity_command))
            targets.append(self._to_body(start, leg))
        self._plan(pair, targets, hold=False)
        pair.phase = PHASE_RECOVERY

    def _segment_path(self, leg: int, corners: Sequence[Vec3],
                      start: Optional[StrokePath] = None) -> Optional[Tuple[StrokePath, float]]:
        """Polyline through ``corners`` (after ``start``, a path from the current point, if given; else from
        the current point), sampled through the IK, with the largest joint travel (rad). None if a sample
        is unreachable."""
        path = start if start is not None else StrokePath(self.positions[leg - 1], self.joints[leg - 1])
        travel = [0.0, 0.0, 0.0]
        for a, b in zip(path.joints, path.joints[1:]):
            for j in range(3):
                travel[j] += abs(b[j] - a[j])
        last = path.joints[-1]
        step = self.params.path_sample
        previous = path.points[-1]
        for corner in corners:
            length = math.hypot(corner[0] - previous[0], corner[1] - previous[1], corner[2] - previous[2])
            count = max(1, int(math.ceil(length / step)))
            for k in range(1, count + 1):
                w = k / count
                point = corner if k == count else (previous[0] + w * (corner[0] - previous[0]),
                                                   previous[1] + w * (corner[1] - previous[1]),
                                                   previous[2] + w * (corner[2] - previous[2]))
                try:
                    joints = self.ik(point, leg)
                except UnreachableError:
                    return None
                for j in range(3):
                    travel[j] += abs(joints[j] - last[j])
                last = joints
                path.append(point, joints)
            previous = corner
        return path, max(travel)

    def _reverse_stroke(self, pair: _Pair, slot: int, leg: int) -> Optional[StrokePath]:
        """The pair's recorded power stroke of this leg, backwards from the current point (reachable)."""
        if slot >= len(pair.strokes) or pair.strokes[slot].points[-1] != self.positions[leg - 1]:
            return None
        stroke = pair.strokes[slot]
        reverse = StrokePath(stroke.points[-1], stroke.joints[-1])
        for point, joints in zip(reversed(stroke.points), reversed(stroke.joints)):
            reverse.append(point, joints)
        return reverse

    def _plan(self, pair: _Pair, targets: Sequence[Vec3], hold: bool) -> None:
        """Paths of the pair's feet to ``targets`` and the duration of the motion (see the module docstring):
        straight, else via the nominal point, else back along the power stroke and then straight; if all
        fail, the foot stays (a reachable point)."""
        paths = []
        travel = 0.0
        for slot, leg in enumerate(pair.legs):
            target = targets[slot]
            planned = self._segment_path(leg, [target])
            if planned is None:
                planned = self._segment_path(leg, [self.nominal[leg - 1], target])
            if planned is None:
                reverse = self._reverse_stroke(pair, slot, leg)
                if reverse is not None:
                    planned = self._segment_path(leg, [target], reverse) \
                        or self._segment_path(leg, [], self._reverse_stroke(pair, slot, leg))
            if planned is None:
                planned = (StrokePath(self.positions[leg - 1], self.joints[leg - 1]), 0.0)
            paths.append(planned[0])
            travel = max(travel, planned[1])
        servo_time = CUBIC_PEAK_TO_MEAN * travel / self._max_joint_step_rate
        if hold:
            duration = max(self.t_rec, servo_time)
        else:
            duration = max(servo_time, min(self.params.recovery_ratio * pair.t_pow_last, self.t_rec))
        pair.paths = paths
        pair.duration = duration
        pair.time = 0.0
        pair.velocities = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]

    def _move_step(self, pair: _Pair, dt: float) -> None:
        """Advance along the planned paths with the cubic time profile."""
        if pair.phase != PHASE_HOLD:
            pair.time += dt
        else:
            pair.time = self.hold_time
        s = 1.0 if pair.duration <= 0.0 else cubic_time_profile(pair.time / pair.duration)
        for slot, leg in enumerate(pair.legs):
            if slot >= len(pair.paths):
                continue
            path = pair.paths[slot]
            if s >= 1.0:
                self.positions[leg - 1] = path.points[-1]
                self.joints[leg - 1] = path.joints[-1]
                continue
            point, nearest = path.at_arc_length(path.length * s)
            if point == self.positions[leg - 1]:
                continue
            try:
                solution = self.ik(point, leg)
            except UnreachableError:
                point, solution = path.points[nearest], path.joints[nearest]
            self.positions[leg - 1] = point
            self.joints[leg - 1] = solution
