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
import math
from typing import Any, Callable, List, Optional, Sequence, Tuple

from quadruped_common.config import ParameterError
from quadruped_common.robot import LEGS
from quadruped_control.model.kinematics import UnreachableError
from quadruped_control.model.params import RobotParams

__all__ = ["PHASE_HOLD", "PHASE_POWER", "PHASE_RECOVERY", "IkFunction", "StrokeScheme", "Vec3", "VelocityCommand"]

Vec3 = Tuple[float, float, float]

PHASE_POWER = "power"
PHASE_RECOVERY = "recovery"
PHASE_HOLD = "hold"

#: (r_body, leg) -> (theta1, theta2, theta3); raises UnreachableError when the target cannot be reached.
IkFunction = Callable[[Vec3, int], Vec3]
#: (leg, r_body at the start of the power phase[, share]) -> foot velocity command v^cmd (body frame, m/s):
#: eq. (foot_vel) with the leg's torque tau_i = share * tau_sat (default share 1/4, the paper's equal split).
VelocityCommand = Callable[..., Vec3]


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
    #: Per-pair state of the scheme; each has ``legs``, ``phase``, ``time`` and ``velocities`` (latched
    #: foot velocity per leg of the pair), read by :attr:`pair_phase_time` and :attr:`velocity_commands`.
    _pairs: List[Any]

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

    @abc.abstractmethod
    def hold(self, dt: float) -> None:
        """Safe state: no new power strokes, the feet go back to the nominal pose; advance ``dt`` s."""

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
