"""The reference poses the operator puts the limp legs in, and how far a joint may be swept from them.

Both poses hold every leg at the same joint angles (the mirror matrices of eq. (M_legs) make the legs
alike): ``stance``, the paper's nominal foot point (robot.yaml ``nominal_foot_leg``, through the IK of
eq. (ik_theta1245), (ik_theta3)), and ``open``, the stance with the five-bar opened and the hip turned by
:data:`OPEN_OFFSET_DEG`. Each is checked against the joint limits and :func:`five_bar_problem`, so a
robot.yaml whose geometry makes one unsafe is refused. docs/on_the_robot.md describes the jig marks.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_common.robot import LEGS
from quadruped_control.model.kinematics import UnreachableError, five_bar_problem, leg_ik_full
from quadruped_control.model.params import RobotParams

#: ``open`` minus ``stance``, degrees of theta1, theta2, theta3: far enough apart for the feedback's slope
#: (20 deg is 0.27 V on a 75 deg/V potentiometer), inside the five-bar's safe set.
OPEN_OFFSET_DEG = (-25.0, 25.0, -20.0)
#: Step (rad) of the scan for a joint's safe sweep.
_SCAN_STEP = math.radians(1.0)


@dataclass(frozen=True)
class ReferencePose:
    """A pose of the limp legs: ``name``, what the operator does, and the leg joint angles (rad)."""

    name: str
    instruction: str
    leg_angles: Tuple[float, float, float]

    def joint_angles(self) -> np.ndarray:
        """The twelve joint angles (JOINT_NAMES order)."""
        return np.tile(np.array(self.leg_angles), len(LEGS))


def _checked(pose: ReferencePose, params: RobotParams) -> ReferencePose:
    limits = params.joint_limits.as_array()
    q = np.array(pose.leg_angles)
    if np.any(q < limits[:, 0]) or np.any(q > limits[:, 1]):
        raise ParameterError("reference pose %s %s deg leaves the joint limits" % (pose.name, np.degrees(q).round(1)))
    problem = five_bar_problem(q[0], q[1], params.five_bar)
    if problem:
        raise ParameterError("reference pose %s is not a safe five-bar configuration: %s" % (pose.name, problem))
    return pose


def reference_poses(params: RobotParams) -> Tuple[ReferencePose, ReferencePose]:
    """``stance`` and ``open`` of ``params`` (module docstring); ParameterError if either is unsafe."""
    try:
        stance = tuple(float(v) for v in leg_ik_full(params.nominal_foot_leg, params)[:3])
    except UnreachableError as exc:
        raise ParameterError("reference pose stance (robot.yaml nominal_foot_leg): %s" % exc) from None
    opened = tuple(v + math.radians(d) for v, d in zip(stance, OPEN_OFFSET_DEG))
    return (_checked(ReferencePose("stance", "every leg at its stance marks (foot at the nominal point)",
                                   (stance[0], stance[1], stance[2])), params),
            _checked(ReferencePose("open", "every leg at its open marks (from stance: theta1 %+.0f, theta2 %+.0f, "
                                   "theta3 %+.0f deg)" % OPEN_OFFSET_DEG,
                                   (opened[0], opened[1], opened[2])), params))


def sweep_half_width(params: RobotParams, leg_angles: Tuple[float, float, float], joint: int,
                     largest: float) -> float:
    """The largest h <= ``largest`` (rad) such that joint ``joint`` (0: theta1, 1: theta2, 2: theta3) swept over
    [ref - h, ref + h] with the other two at ``leg_angles`` stays within its limits and keeps the five-bar safe.
    Symmetric, so a servo that turns the wrong way stays safe too."""
    low, high = params.joint_limits.as_array()[joint]
    h = 0.0
    while h + _SCAN_STEP <= largest + 1e-12:
        trial = h + _SCAN_STEP
        ok = True
        for sign in (-1.0, 1.0):
            q = list(leg_angles)
            q[joint] += sign * trial
            if not low <= q[joint] <= high or (joint < 2 and five_bar_problem(q[0], q[1], params.five_bar)):
                ok = False
        if not ok:
            break
        h = trial
    return h
