"""The paper's stroke scheme ``paper``: power and recovery stroke cycle (paper section "Power and Recovery
Stroke Cycle"), one implementation of :class:`quadruped_control.control.strokes.StrokeScheme`.

Two leg pairs alternate between a power phase, in which the feet move with the velocity command of
eq. (foot_vel), and a recovery phase, in which they return to the start of the stroke:

- Start-up: the FIRST configured pair (the paper's "(1,2)") starts with a half-duration recovery
  t_rec / 2 (it waits at the nominal pose: there is nothing to retrace), the second pair starts with a
  power phase at once. This delays one pair's power phase against the other's.
- Power phase: the velocity command v_i^cmd of each leg of the pair is computed ONCE, when the phase
  starts (a callback into the controller, which uses the torque of that instant), and held constant.
  The foot position is integrated with Euler's method from the start point (the nominal foot position
  ``RobotParams.nominal_foot_body(leg)``), eq. (foot_integration): r(t + dt) = r(t) + v^cmd dt, and mapped
  to joint angles by the inverse kinematics. The phase ends when the IK fails for a leg of the pair (a
  workspace boundary; the last reachable point of that leg is kept, the other leg keeps its new point if
  reachable) or when it has lasted t_pow^max.
- Recovery phase: each leg's recorded power trajectory is retraced in reverse, parametrised by arc
  length and linearly interpolated between the recorded points, with the cubic time profile
  s(u) = 3 u^2 - 2 u^3, u = t / t_rec (zero velocity at both ends), over t_rec. It ends exactly at the
  start point, and the next power phase starts there.
- Hold (safe state): no new power phase starts; a pair in power starts retracing its stroke at once (the
  same cubic retrace over t_rec), a pair in recovery completes it, and both then stay at the start
  (nominal) point. The reported phase is ``'hold'``. Resuming restarts the cycle cleanly: the first pair
  again waits half a recovery, the second starts a power phase as soon as its feet are back at the start.

The cycle itself (start-up, power, recovery, the switch between them) is written once, in
:mod:`quadruped_control.control.strokes.cycle`, which the batched simulator's controller runs too: this
class keeps one trial of its :class:`~quadruped_control.control.strokes.cycle.CycleState`, solves the IK
of the targets the cycle asks for with its own IK (:meth:`StrokeCycle.ik`, injectable; an unreachable
target raises UnreachableError, which it reports to the cycle as not reached), evaluates the velocity
command callback at each power start, enlarges the recorded strokes' arrays when they fill (no limit on a
stroke's length) and adds the hold and the restart.

Timing parameters changed with :meth:`StrokeCycle.set_timing` take effect at the next start of the
phase they govern (t_pow^max at a power start, t_rec at a recovery start).

Every joint target produced here comes from a successful IK (or a recorded IK solution), clamped
exactly into the servo ranges; nothing here returns NaN. Per-step time is elapsed time (the controller
clips it); a zero step changes nothing.
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_control.control.strokes.base import (PHASE_HOLD, PHASE_POWER, PHASE_RECOVERY, TIME_EPS, IkFunction,
                                                    StrokeScheme, Vec3, VelocityCommand)
from quadruped_control.control.strokes.cycle import (LegSolution, LegTarget, PairSolutions, PairTargets,
                                                     RecoveryTargets, new_cycle_state, path_nearly_full, power_step,
                                                     power_targets, recovery_step, recovery_targets, start_power,
                                                     start_recovery, wait_at_start)
from quadruped_control.model.kinematics import UnreachableError, joint_angles_floats
from quadruped_control.model.params import RobotParams

__all__ = [
    "PHASE_HOLD",
    "PHASE_POWER",
    "PHASE_RECOVERY",
    "IkFunction",
    "StrokeCycle",
    "VelocityCommand",
]

#: Points a recorded stroke holds at first (t_pow^max = 0.5 s at dt = 0.01 s takes 51); doubled when full.
_INITIAL_CAPACITY = 64
#: No solution: for a target the cycle does not need solved (it does not move), or one the IK cannot reach.
_NO_SOLUTION = LegSolution(False, 0.0, 0.0, 0.0)
#: The one trial of the cycle state this class keeps.
_I = 0


class StrokeCycle(StrokeScheme):
    """The two-pair power/recovery cycle of the paper with foot positions and joint targets for 4 legs.

    ``robot``: kinematic parameters and nominal foot positions; ``pairs``: the two leg pairs, the first
    starts with a half recovery; ``t_rec``, ``t_pow_max``: durations (s); ``ik``: inverse kinematics
    (default :func:`quadruped_control.model.kinematics.joint_angles` on ``robot``), injectable for tests.
    Raises ParameterError if a nominal foot position is unreachable.
    """

    name = "paper"

    def __init__(self, robot: RobotParams, pairs: Sequence[Sequence[int]] = ((1, 3), (2, 4)),
                 t_rec: float = 1.5, t_pow_max: float = 0.5, ik: Optional[IkFunction] = None) -> None:
        super().__init__(robot, pairs, t_rec, t_pow_max)
        self._ik_raw = ik if ik is not None else self._default_ik
        self._ik_injected = ik is not None
        self._set_nominal(robot)
        #: the pairs' legs, 0-based, as the cycle indexes them
        self._legs = np.array([[leg - 1 for leg in pair] for pair in self.pairs], dtype=np.int64)
        self._cycle = new_cycle_state(1, _INITIAL_CAPACITY, self.nominal, self.nominal_joints)
        self.reset()

    # ---- configuration -----------------------------------------------------------------------

    def _default_ik(self, point: Vec3, leg: int) -> Vec3:
        # joint_angles on floats (same result, no numpy round trip)
        return joint_angles_floats(point[0], point[1], point[2], leg, self.robot)

    def ik(self, point: Vec3, leg: int) -> Vec3:
        """IK of ``point`` for ``leg``, clamped exactly into the servo ranges (the IK's wrap allows 1e-9 rad)."""
        if self._ik_injected:
            t1, t2, t3 = self._ik_raw(point, leg)
        else:  # _default_ik, inlined (the controller's per-step IK)
            t1, t2, t3 = joint_angles_floats(point[0], point[1], point[2], leg, self.robot)
        (l1, h1), (l2, h2), (l3, h3) = self._bounds
        # min(max(t, low), high) inline, with the builtins' exact semantics (ties, NaN)
        t1 = l1 if l1 > t1 else t1
        t2 = l2 if l2 > t2 else t2
        t3 = l3 if l3 > t3 else t3
        return (h1 if h1 < t1 else t1, h2 if h2 < t2 else t2, h3 if h3 < t3 else t3)

    def set_timing(self, t_rec: Optional[float] = None, t_pow_max: Optional[float] = None) -> None:
        """New durations (s); each takes effect at the next start of the phase it governs."""
        self.t_rec, self.t_pow_max = self._checked_timing(t_rec, t_pow_max, self.t_rec, self.t_pow_max)

    # ---- state -------------------------------------------------------------------------------

    def reset(self) -> None:
        """All feet at the nominal pose, cycle at its start (first pair: half recovery; second: power)."""
        cycle = self._cycle
        cycle.positions[_I] = self.nominal
        cycle.joints[_I] = self.nominal_joints
        cycle.ik_fallbacks[_I] = 0
        self.holding = False
        self.hold_time = 0.0
        self._restart(fresh=True)
        self._sync()

    def _restart(self, fresh: bool = False) -> None:
        """Start the cycle from the current state (feet at, or retracing towards, their start points);
        ``fresh``: discard any retract in progress (the feet are at their start points)."""
        cycle = self._cycle
        for pair in range(2):
            time, t_move = float(cycle.phase_time[_I, pair]), float(cycle.t_move[_I, pair])
            incomplete = not fresh and not cycle.power[_I, pair] and time < t_move - TIME_EPS
            delay = 0.5 * self.t_rec if pair == 0 else 0.0
            if incomplete:
                # Keep retracing; the first pair additionally waits half a recovery from now.
                cycle.t_total[_I, pair] = max(t_move, time + delay)
            else:
                wait_at_start(cycle, _I, pair, self._legs, delay)

    def _sync(self) -> None:
        """``positions`` and ``joints`` (lists of float tuples, legs 1..4) from the cycle state."""
        self.positions = [tuple(row) for row in self._cycle.positions[_I].tolist()]
        self.joints = [tuple(row) for row in self._cycle.joints[_I].tolist()]

    def recorded_stroke(self, leg: int) -> List[Vec3]:
        """The recorded points of ``leg``'s current stroke (the start first)."""
        count = int(self._cycle.path_count[_I, leg - 1])
        return [tuple(row) for row in self._cycle.path_points[_I, leg - 1, :count].tolist()]

    @property
    def ik_fallbacks(self) -> int:
        """Recovery points replaced by the nearest recorded one since the last reset."""
        return int(self._cycle.ik_fallbacks[_I])

    @property
    def pair_phase(self) -> Tuple[str, str]:
        """Phase of each pair: 'power', 'recovery' or 'hold'."""
        if self.holding:
            return PHASE_HOLD, PHASE_HOLD
        power = self._cycle.power[_I]
        return (PHASE_POWER if power[0] else PHASE_RECOVERY), (PHASE_POWER if power[1] else PHASE_RECOVERY)

    @property
    def pair_phase_time(self) -> Tuple[float, float]:
        """Time since each pair's phase started (since the hold started while holding), s."""
        if self.holding:
            return self.hold_time, self.hold_time
        return float(self._cycle.phase_time[_I, 0]), float(self._cycle.phase_time[_I, 1])

    @property
    def velocity_commands(self) -> List[Vec3]:
        """Foot velocity commands in force per leg (legs 1..4; zero outside power phases and while
        holding)."""
        out: List[Vec3] = [(0.0, 0.0, 0.0)] * 4
        if not self.holding:
            for pair, legs in enumerate(self.pairs):
                if self._cycle.power[_I, pair]:
                    for leg in legs:
                        out[leg - 1] = tuple(self._cycle.velocities[_I, leg - 1].tolist())
        return out

    # ---- stepping ----------------------------------------------------------------------------

    def advance(self, dt: float, velocity_command: VelocityCommand) -> None:
        """Advance the cycle by ``dt`` s (>= 0). Leaves hold first (restarting the cycle) if holding.

        ``velocity_command(leg, r_start)`` is called once per leg at each power-phase start.
        """
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError("dt must be a finite non-negative time step, got %r" % (dt,))
        if self.holding:
            self.holding = False
            self.hold_time = 0.0
            self._restart()
        for pair in range(2):
            if self._cycle.power[_I, pair]:
                if dt > 0.0:
                    self._power_step(pair, dt)
            else:
                self._recovery_step(pair, dt, velocity_command)
        self._sync()

    def _enter_hold(self) -> None:
        """A pair in power retraces its stroke at once; both then stay at the start (nominal) points."""
        cycle = self._cycle
        for pair in range(2):
            if cycle.power[_I, pair]:
                start_recovery(cycle, _I, pair, self._legs, self.t_rec)
            cycle.t_total[_I, pair] = math.inf

    def _hold_step(self, dt: float) -> None:
        for pair in range(2):
            self._recovery_step(pair, dt, None)
        self._sync()

    def _solve(self, pair: int, targets: Union[PairTargets, RecoveryTargets]) -> PairSolutions:
        """This robot's IK (:meth:`ik`) of the targets the cycle asks for; unreachable is reported."""
        first, second = self.pairs[pair]
        return PairSolutions(self._solve_leg(targets.first, first), self._solve_leg(targets.second, second))

    def _solve_leg(self, target: LegTarget, leg: int) -> LegSolution:
        if not target.moves:
            return _NO_SOLUTION
        try:
            t1, t2, t3 = self.ik((float(target.x), float(target.y), float(target.z)), leg)
        except UnreachableError:
            return _NO_SOLUTION
        return LegSolution(True, t1, t2, t3)

    def _power_step(self, pair: int, dt: float) -> None:
        if path_nearly_full(self._cycle, _I, pair, self._legs):
            self._grow_strokes()
        targets = power_targets(self._cycle, _I, pair, self._legs, dt)
        power_step(self._cycle, _I, pair, self._legs, dt, self.t_rec, targets, self._solve(pair, targets))

    def _recovery_step(self, pair: int, dt: float, velocity_command: Optional[VelocityCommand]) -> None:
        """A recovery step; at its end the power phase starts, unless holding (``velocity_command`` None,
        the hold's t_total is infinite)."""
        cycle = self._cycle
        targets = recovery_targets(cycle, _I, pair, self._legs, dt)
        done = recovery_step(cycle, _I, pair, self._legs, targets, self._solve(pair, targets))
        if done and velocity_command is not None:
            commands = []
            for leg in self.pairs[pair]:
                vx, vy, vz = velocity_command(leg, tuple(cycle.positions[_I, leg - 1].tolist()))
                commands.append((float(vx), float(vy), float(vz)))
            start_power(cycle, _I, pair, self._legs, self.t_pow_max, commands[0], commands[1])

    def _grow_strokes(self) -> None:
        """Twice the points per recorded stroke (the robot's strokes have no length limit)."""
        cycle = self._cycle
        capacity = cycle.path_points.shape[2]

        def grown(a: np.ndarray) -> np.ndarray:
            out = np.zeros(a.shape[:2] + (2 * capacity,) + a.shape[3:], dtype=a.dtype)
            out[:, :, :capacity] = a
            return out

        self._cycle = cycle._replace(path_points=grown(cycle.path_points), path_joints=grown(cycle.path_joints),
                                     path_length=grown(cycle.path_length))
