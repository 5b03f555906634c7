"""The stroke-scheme interface: how the controller's torque becomes foot motion (paper section "Power and
Recovery Stroke Cycle" and beyond).

A stroke scheme owns the four feet: each control step the controller hands it the elapsed time and a
callback that evaluates the allocation, eq. (foot_speed) and (foot_vel), for one leg at one foot position
with a given share of the saturated torque; the scheme decides when each leg pair strokes (power) and
returns (recovery), integrates the foot positions (eq. (foot_integration)) and maps them to joint targets
with the inverse kinematics. Schemes: :mod:`quadruped_control.control.strokes.paper` (the paper's cycle) and
:mod:`quadruped_control.control.strokes.coordinated`.

Every scheme guarantees: joint targets inside the servo ranges, from successful IK solutions; no NaN;
``hold`` brings the feet back to the nominal pose without a jump; ``at_rest`` is true once a hold has
brought every foot to the nominal pose (the controller switches schemes only then, so a switch never
makes the feet jump).
"""
from __future__ import annotations

import abc
import bisect
import math
from typing import Callable, List, Optional, Sequence, Tuple

from quadruped_common.config import ParameterError
from quadruped_common.jit import hypot3, jitable
from quadruped_common.robot import LEGS
from quadruped_control.model.kinematics import UnreachableError
from quadruped_control.model.params import RobotParams

__all__ = ["PHASE_HOLD", "PHASE_POWER", "PHASE_RECOVERY", "IkFunction", "PairState", "StrokePath", "StrokeScheme", "TIME_EPS",
           "Vec3", "VelocityCommand", "arc_length_point", "arc_length_segment", "cubic_time_profile"]

Vec3 = Tuple[float, float, float]

PHASE_POWER = "power"
PHASE_RECOVERY = "recovery"
PHASE_HOLD = "hold"

#: (r_body, leg) -> (theta1, theta2, theta3); raises UnreachableError when the target cannot be reached.
IkFunction = Callable[[Vec3, int], Vec3]
#: (leg, r_body at the start of the power phase[, share]) -> foot velocity command v^cmd (body frame, m/s):
#: eq. (foot_vel) with the leg's torque tau_i = share * tau_sat (default share 1/4, the paper's equal split).
VelocityCommand = Callable[..., Vec3]


#: Slack when comparing phase times with durations (durations are sums of 0.01 s steps).
TIME_EPS = 1e-9


@jitable
def cubic_time_profile(u: float) -> float:
    """s(u) = 3 u^2 - 2 u^3 for u clipped into [0, 1]: s(0) = 0, s(1) = 1, s'(0) = s'(1) = 0."""
    if u <= 0.0:
        return 0.0
    if u >= 1.0:
        return 1.0
    return u * u * (3.0 - 2.0 * u)


@jitable
def arc_length_segment(cumulative, count: int, a: float) -> int:
    """The segment j of a polyline with cumulative lengths ``cumulative`` (first ``count``, 0 first) that
    holds arc length ``a``, for 0 < a < length: the last j with cumulative[j] <= a (``bisect_right - 1``;
    compiled code has no bisect: the paper's cycle, :mod:`~quadruped_control.control.strokes.cycle`, calls
    this, :class:`StrokePath` calls :func:`bisect.bisect_right` instead: an index, so both find the same
    one)."""
    low, high = 0, count - 1
    while high - low > 1:
        middle = (low + high) // 2
        if cumulative[middle] <= a:
            low = middle
        else:
            high = middle
    return low


@jitable
def arc_length_point(points, cumulative, j: int, a: float) -> Tuple[float, float, float, int]:
    """The point at arc length ``a`` on segment ``j`` (:func:`arc_length_segment`) of the polyline
    ``points`` (rows of x, y, z) with cumulative lengths ``cumulative``, interpolated linearly, and the
    index of the nearest recorded point: (x, y, z, index). The arithmetic of
    :meth:`StrokePath.at_arc_length` (on lists) and of the paper's cycle
    (:mod:`~quadruped_control.control.strokes.cycle`, on arrays), so both retrace strokes to the same bits."""
    w = (a - cumulative[j]) / (cumulative[j + 1] - cumulative[j])
    x0, y0, z0 = points[j][0], points[j][1], points[j][2]
    x1, y1, z1 = points[j + 1][0], points[j + 1][1], points[j + 1][2]
    return x0 + w * (x1 - x0), y0 + w * (y1 - y0), z0 + w * (z1 - z0), (j if w < 0.5 else j + 1)


class StrokePath:
    """The recorded power trajectory of one foot: points (body frame) with their IK solutions.

    Point 0 is the stroke's start. :meth:`at_arc_length` interpolates linearly at a given arc length
    from the start; consecutive duplicate points are not stored, so a path of zero length has one point.
    """

    __slots__ = ("points", "joints", "cumulative")

    def __init__(self, point: Vec3, joints: Vec3) -> None:
        self.points: List[Vec3] = [point]
        self.joints: List[Vec3] = [joints]
        self.cumulative: List[float] = [0.0]

    def append(self, point: Vec3, joints: Vec3) -> None:
        """Record the next point (ignored if it equals the last one)."""
        lx, ly, lz = self.points[-1]
        step = hypot3(point[0] - lx, point[1] - ly, point[2] - lz)
        if step == 0.0:
            return
        self.points.append(point)
        self.joints.append(joints)
        self.cumulative.append(self.cumulative[-1] + step)

    @property
    def length(self) -> float:
        """Arc length of the path, m."""
        return self.cumulative[-1]

    @property
    def start(self) -> Vec3:
        return self.points[0]

    @property
    def end(self) -> Vec3:
        return self.points[-1]

    def at_arc_length(self, a: float) -> Tuple[Vec3, int]:
        """Point at arc length ``a`` (clipped to [0, length]) and the index of the nearest recorded point."""
        cumulative = self.cumulative
        total = cumulative[-1]
        if a <= 0.0 or total <= 0.0:
            return self.points[0], 0
        last = len(cumulative) - 1
        if a >= total:
            return self.points[last], last
        j = bisect.bisect_right(cumulative, a) - 1  # arc_length_segment, in C
        x, y, z, nearest = arc_length_point(self.points, cumulative, j, a)
        return (x, y, z), nearest


class PairState:
    """State of one leg pair that a scheme on objects keeps (the coordinated scheme; the paper's cycle keeps
    its state in arrays, :class:`~quadruped_control.control.strokes.cycle.CycleState`): its ``legs``,
    ``phase`` and the ``time`` since the phase started, the feet's ``paths`` (recovery / hold motion of each
    leg of the pair) and the latched foot ``velocities`` of a power phase (read by
    :attr:`StrokeScheme.pair_phase_time` and :attr:`StrokeScheme.velocity_commands`). Schemes add their
    own slots in a subclass."""

    __slots__ = ("legs", "phase", "time", "paths", "velocities")

    def __init__(self, legs: Tuple[int, int], phase: str) -> None:
        self.legs = legs
        self.phase = phase
        self.time = 0.0
        self.paths: List[StrokePath] = []
        self.velocities: List[Vec3] = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]


class StrokeScheme(abc.ABC):
    """A stroke scheme for two leg pairs and four feet (see the module docstring).

    Attributes every scheme keeps current: ``positions`` (commanded r_e,i^B, legs 1..4), ``joints``
    (their joint targets), ``nominal`` (nominal foot positions), ``holding``, ``pairs``.
    """

    #: Name used in config/controller.yaml (``stroke.scheme``), the CLI and the node parameter.
    name = ""
    positions: List[Vec3]
    joints: List[Vec3]
    nominal: List[Vec3]
    holding: bool
    hold_time: float
    pairs: Tuple[Tuple[int, int], Tuple[int, int]]
    #: Per-pair state of the scheme (:class:`PairState`).
    _pairs: List[PairState]

    def __init__(self, robot: RobotParams, pairs: Sequence[Sequence[int]], t_rec: float, t_pow_max: float) -> None:
        """What every scheme sets first: robot, validated pairs and timing, servo ranges, no feet yet. A
        scheme then sets its own attributes and calls :meth:`_start`."""
        self.robot = robot
        self.pairs = self._checked_pairs(pairs)
        self.t_rec = self.t_pow_max = 0.0
        self.set_timing(t_rec, t_pow_max)
        limits = robot.joint_limits
        self._bounds = (limits.theta1, limits.theta2, limits.theta3)
        self.positions = []
        self.joints = []
        self.holding = False
        self.hold_time = 0.0

    def _start(self, pair_state: Callable[[Tuple[int, int]], PairState]) -> None:
        """Nominal feet (ParameterError if unreachable), one ``pair_state`` per pair, cycle at its start."""
        self._set_nominal(self.robot)
        self._pairs = [pair_state(self.pairs[0]), pair_state(self.pairs[1])]
        self.reset()

    # ---- shared set-up -------------------------------------------------------------------------

    @staticmethod
    def _checked_pairs(pairs: Sequence[Sequence[int]]) -> Tuple[Tuple[int, int], Tuple[int, int]]:
        """The two leg pairs as int tuples; ParameterError unless they partition the legs."""
        pair_tuples = tuple((int(p[0]), int(p[1])) for p in pairs)
        if len(pair_tuples) != 2 or sorted(leg for p in pair_tuples for leg in p) != list(LEGS):
            raise ParameterError("pairs %r must be two pairs forming a partition of the legs %s" % (pairs, LEGS))
        return pair_tuples[0], pair_tuples[1]

    def _set_nominal(self, robot: RobotParams) -> None:
        """``nominal`` and ``nominal_joints`` from the robot's nominal feet; ParameterError if unreachable."""
        self.nominal = []
        self.nominal_joints: List[Vec3] = []
        for leg in LEGS:
            point = tuple(float(x) for x in robot.nominal_foot_body(leg))
            try:
                joints = self.ik(point, leg)  # type: ignore[arg-type]
            except UnreachableError as exc:
                raise ParameterError("nominal foot position of leg %d %s is unreachable: %s"
                                     % (leg, point, exc)) from None
            self.nominal.append(point)  # type: ignore[arg-type]
            self.nominal_joints.append(joints)

    @staticmethod
    def _checked_timing(t_rec: Optional[float], t_pow_max: Optional[float], old_rec: float,
                        old_pow: float) -> Tuple[float, float]:
        """New (t_rec, t_pow_max), None keeping the old value; ParameterError unless positive and finite."""
        new_rec = old_rec if t_rec is None else float(t_rec)
        new_pow = old_pow if t_pow_max is None else float(t_pow_max)
        for name, value in (("t_rec", new_rec), ("t_pow_max", new_pow)):
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError("%s must be a positive finite duration, got %r" % (name, value))
        return new_rec, new_pow

    @abc.abstractmethod
    def ik(self, point: Vec3, leg: int) -> Vec3:
        """IK of ``point`` for ``leg`` clamped into the servo ranges; raises UnreachableError."""

    @abc.abstractmethod
    def reset(self) -> None:
        """All feet at the nominal pose, cycle at its start."""

    @abc.abstractmethod
    def set_timing(self, t_rec: float, t_pow_max: float) -> None:
        """New durations (s), validated; each takes effect at the next start of the phase it governs."""

    @abc.abstractmethod
    def advance(self, dt: float, velocity_command: VelocityCommand) -> None:
        """Advance by ``dt`` s (>= 0) while stroking; leaves a hold first (restarting the cycle)."""

    def hold(self, dt: float) -> None:
        """Safe state: no new power strokes, the feet go back to the nominal pose; advance ``dt`` s.

        A non-finite or negative ``dt`` counts as 0. The first call enters the hold
        (:meth:`_enter_hold`), later ones count ``hold_time``; every call moves the feet
        (:meth:`_hold_step`)."""
        if not (math.isfinite(dt) and dt >= 0.0):
            dt = 0.0
        if not self.holding:
            self.holding = True
            self.hold_time = 0.0
            self._enter_hold()
        else:
            self.hold_time += dt
        self._hold_step(dt)

    @abc.abstractmethod
    def _enter_hold(self) -> None:
        """Start the way back to the nominal pose (called once, when a hold begins)."""

    @abc.abstractmethod
    def _hold_step(self, dt: float) -> None:
        """Move the feet ``dt`` s further on their way back while holding."""

    @property
    @abc.abstractmethod
    def pair_phase(self) -> Tuple[str, str]:
        """Phase of each pair: 'power', 'recovery' or 'hold'."""

    @property
    def pair_phase_time(self) -> Tuple[float, float]:
        """Time since each pair's phase started (since the hold started while holding), s."""
        if self.holding:
            return self.hold_time, self.hold_time
        return self._pairs[0].time, self._pairs[1].time

    @property
    def velocity_commands(self) -> List[Vec3]:
        """Foot velocity commands in force per leg (legs 1..4; zero outside power phases and while
        holding)."""
        out: List[Vec3] = [(0.0, 0.0, 0.0)] * 4
        if not self.holding:
            for pair in self._pairs:
                if pair.phase == PHASE_POWER:
                    for slot, leg in enumerate(pair.legs):
                        out[leg - 1] = pair.velocities[slot]
        return out

    @property
    def at_rest(self) -> bool:
        """Holding with every foot at its nominal position (a scheme switch may happen now)."""
        return self.holding and self.positions == self.nominal

    def foot_targets(self) -> List[Vec3]:
        """Commanded foot positions r_e,i^B (legs 1..4), m."""
        return list(self.positions)

    def joint_targets(self) -> List[Vec3]:
        """Joint targets (theta1, theta2, theta3) per leg (legs 1..4), rad, within the servo ranges."""
        return list(self.joints)
