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

Timing parameters changed with :meth:`StrokeCycle.set_timing` take effect at the next start of the
phase they govern (t_pow^max at a power start, t_rec at a recovery start).

Every joint target produced here comes from a successful IK (or a recorded IK solution), clamped
exactly into the servo ranges; nothing here returns NaN. Per-step time is elapsed time (the controller
clips it); a zero step changes nothing.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

from quadruped_control.control.strokes.base import (PHASE_HOLD, PHASE_POWER, PHASE_RECOVERY, TIME_EPS, IkFunction,
                                                    PairState, StrokePath, StrokeScheme, Vec3, VelocityCommand,
                                                    cubic_time_profile)
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


class _Pair(PairState):
    """Phase state of one leg pair of the paper's cycle."""

    __slots__ = ("t_move", "t_total", "t_pow")

    def __init__(self, legs: Tuple[int, int]) -> None:
        super().__init__(legs, PHASE_RECOVERY)
        self.t_move = 0.0      # duration of the cubic retrace motion (recovery)
        self.t_total = 0.0     # duration of the recovery phase (>= t_move)
        self.t_pow = 0.0       # latched t_pow_max of the current power phase


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
        self._start(_Pair)

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
        self.positions = list(self.nominal)
        self.joints = list(self.nominal_joints)
        self.holding = False
        self.hold_time = 0.0
        self._restart(fresh=True)

    def _restart(self, fresh: bool = False) -> None:
        """Start the cycle from the current state (feet at, or retracing towards, their start points);
        ``fresh``: discard any retract in progress (the feet are at their start points)."""
        for index, pair in enumerate(self._pairs):
            incomplete = (not fresh and pair.phase == PHASE_RECOVERY
                          and pair.time < pair.t_move - TIME_EPS)
            delay = 0.5 * self.t_rec if index == 0 else 0.0
            if incomplete:
                # Keep retracing; the first pair additionally waits half a recovery from now.
                pair.t_total = max(pair.t_move, pair.time + delay)
            else:
                pair.phase = PHASE_RECOVERY
                pair.time = 0.0
                pair.t_move = 0.0
                pair.t_total = delay
                pair.paths = [StrokePath(self.positions[leg - 1], self.joints[leg - 1]) for leg in pair.legs]
            pair.velocities = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]

    @property
    def pair_phase(self) -> Tuple[str, str]:
        """Phase of each pair: 'power', 'recovery' or 'hold'."""
        if self.holding:
            return PHASE_HOLD, PHASE_HOLD
        return self._pairs[0].phase, self._pairs[1].phase

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
        for pair in self._pairs:
            if pair.phase == PHASE_POWER:
                self._power_step(pair, dt)
            else:
                self._recovery_step(pair, dt, velocity_command)

    def _enter_hold(self) -> None:
        """A pair in power retraces its stroke at once; both then stay at the start (nominal) points."""
        for pair in self._pairs:
            if pair.phase == PHASE_POWER:
                self._start_recovery(pair)
            pair.t_total = math.inf

    def _hold_step(self, dt: float) -> None:
        for pair in self._pairs:
            self._recovery_step(pair, dt, None)

    def _start_recovery(self, pair: _Pair) -> None:
        pair.phase = PHASE_RECOVERY
        pair.time = 0.0
        pair.t_move = pair.t_total = self.t_rec
        pair.velocities = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]

    def _start_power(self, pair: _Pair, velocity_command: VelocityCommand) -> None:
        pair.phase = PHASE_POWER
        pair.time = 0.0
        pair.t_pow = self.t_pow_max
        velocities = []
        paths = []
        for leg in pair.legs:
            start = self.positions[leg - 1]
            vx, vy, vz = velocity_command(leg, start)
            vel = (float(vx), float(vy), float(vz))
            if not (math.isfinite(vel[0]) and math.isfinite(vel[1]) and math.isfinite(vel[2])):
                vel = (0.0, 0.0, 0.0)  # defensive: a non-finite command means no stroke
            velocities.append(vel)
            paths.append(StrokePath(start, self.joints[leg - 1]))
        pair.velocities = velocities
        pair.paths = paths

    def _power_step(self, pair: _Pair, dt: float) -> None:
        if dt <= 0.0:
            return
        pair.time += dt
        boundary = False
        positions, joints = self.positions, self.joints
        for slot, leg in enumerate(pair.legs):
            vx, vy, vz = pair.velocities[slot]
            x, y, z = positions[leg - 1]
            target = (x + vx * dt, y + vy * dt, z + vz * dt)  # eq. (foot_integration)
            if target == (x, y, z):
                continue  # zero command: no motion, the IK solution is current
            try:
                solution = self.ik(target, leg)
            except UnreachableError:
                boundary = True  # workspace boundary: keep the last reachable point
                continue
            positions[leg - 1] = target
            joints[leg - 1] = solution
            pair.paths[slot].append(target, solution)
        if boundary or pair.time >= pair.t_pow - TIME_EPS:
            self._start_recovery(pair)

    def _recovery_step(self, pair: _Pair, dt: float, velocity_command: Optional[VelocityCommand]) -> None:
        pair.time += dt
        if pair.t_move > 0.0:
            s = cubic_time_profile(pair.time / pair.t_move)
        else:
            s = 1.0
        positions, joints = self.positions, self.joints
        done = velocity_command is not None and pair.time >= pair.t_total - TIME_EPS
        for slot, leg in enumerate(pair.legs):
            path = pair.paths[slot]
            if done or s >= 1.0:
                positions[leg - 1] = path.points[0]
                joints[leg - 1] = path.joints[0]
                continue
            point, nearest = path.at_arc_length(path.length * (1.0 - s))
            if point == positions[leg - 1]:
                continue  # not moving (e.g. at rest between strokes): the IK solution is current
            try:
                solution = self.ik(point, leg)
            except UnreachableError:
                # The chord between two recorded (reachable) points left the workspace: use the
                # nearest recorded point, whose IK solution is known.
                point, solution = path.points[nearest], path.joints[nearest]
            positions[leg - 1] = point
            joints[leg - 1] = solution
        if done:
            assert velocity_command is not None
            self._start_power(pair, velocity_command)
