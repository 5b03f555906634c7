"""The guided stroke test: does a torque command about each body axis make paw motions that turn the body
that way?

For a small torque about body axis a, the controller's own allocation (eq. (foot_vel)) gives each foot's
power-stroke direction from the stance; the controller's IK (eq. (ik_theta3), (ik_theta1245)) turns the short
stroke into joint targets, commanded through the calibration file. The stroke the paws really made is read
back from the feedback through the forward kinematics (eq. (ee_body)), and its drag torque on the body,
eq. (torque_leg) with F = -k |d| d for each foot's displacement d, must point along a (within
:data:`MAX_ANGLE_DEG`). A sign error anywhere on that chain (allocation, mirror matrices, IK, a channel or a
feedback that lies the same way as its command) turns it away.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional

import numpy as np

from quadruped_common.robot import LEGS
from quadruped_control.bringup.reference import ReferencePose
from quadruped_control.bringup.servo_check import Bench
from quadruped_control.control.allocation import foot_velocity_command, leg_torques
from quadruped_control.model.kinematics import UnreachableError, foot_position, joint_angles
from quadruped_control.model.params import RobotParams

__all__ = ["AXES", "MAX_ANGLE_DEG", "StrokeCheckResult", "check_strokes"]

AXES = ("roll", "pitch", "yaw")
#: The drag torque of the strokes made must be within this angle of the commanded axis (deg).
MAX_ANGLE_DEG = 45.0


@dataclass
class StrokeCheckResult:
    """Per axis: the angle (deg) between the commanded axis and the drag torque of the strokes made; problems."""

    angles_deg: List[float] = field(default_factory=list)
    problems: List[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.problems and len(self.angles_deg) == len(AXES)


def _feet(q: np.ndarray, params: RobotParams) -> np.ndarray:
    return np.array([foot_position(q[3 * (leg - 1):3 * leg], leg, params) for leg in LEGS])


def check_strokes(bench: Bench, params: RobotParams, stance: ReferencePose, torque: float = 0.4,
                  stroke_m: float = 0.015, settle_s: float = 0.4) -> StrokeCheckResult:
    """Run the test of the module docstring on ``bench`` (outputs on, held at ``stance`` between strokes)."""
    result = StrokeCheckResult()
    q0 = stance.joint_angles()
    feet0 = _feet(q0, params)
    bench.outputs(True)
    bench.move_to(q0)
    bench.hold(q0, settle_s)
    for a, name in enumerate(AXES):
        tau = np.zeros(3)
        tau[a] = torque
        shares = leg_torques(tau, len(LEGS))
        velocities = np.array([foot_velocity_command(shares[i], feet0[i], np.zeros(3), params.drag_constant)
                               for i in range(len(LEGS))])
        fastest = float(np.max(np.linalg.norm(velocities, axis=1)))
        if fastest <= 0.0:
            result.problems.append("%s: the allocation makes no stroke" % name)
            continue
        targets = feet0 + velocities * (stroke_m / fastest)
        try:
            q1 = np.concatenate([joint_angles(targets[i], leg, params) for i, leg in enumerate(LEGS)])
        except UnreachableError as exc:
            result.problems.append("%s: the test stroke is out of reach: %s" % (name, exc))
            continue
        before = _read_feet(bench, params)
        bench.move_to(q1)
        bench.hold(q1, settle_s)
        after = _read_feet(bench, params)
        bench.move_to(q0)
        bench.hold(q0, settle_s)
        if before is None or after is None:
            result.problems.append("%s: the feedback gave no foot position" % name)
            continue
        d = after - before
        drag = -params.drag_constant * np.linalg.norm(d, axis=1)[:, None] * d
        made = np.sum(np.cross(before, drag), axis=0)
        norm = float(np.linalg.norm(made))
        angle = 180.0 if norm == 0.0 else math.degrees(math.acos(max(-1.0, min(1.0, made[a] / norm))))
        result.angles_deg.append(round(angle, 1))
        if angle > MAX_ANGLE_DEG:
            result.problems.append("%s: a %+.1f N m command made strokes whose drag turns the body about %s "
                                   "(%.0f deg from the commanded axis): a sign is wrong between the allocation "
                                   "and the paws (leg origins, mirror matrices, wiring)" % (
                                       name, torque, np.round(made / norm, 2).tolist(), angle))
    return result


def _read_feet(bench: Bench, params: RobotParams, samples: int = 5) -> Optional[np.ndarray]:
    readings = []
    for _ in range(samples):
        readings.append(bench.read_angles())
        bench.hold(bench.current, 0.01)
    q = np.mean(readings, axis=0)
    if not np.all(np.isfinite(q)):
        return None
    try:
        return _feet(q, params)
    except UnreachableError:
        return None
