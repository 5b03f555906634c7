"""The reference poses are safe, and the sweeps about them stay in the five-bar's safe set."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from quadruped_common.config import ParameterError
from quadruped_control.bringup.reference import OPEN_OFFSET_DEG, reference_poses, sweep_half_width
from quadruped_control.model.kinematics import five_bar_problem
from quadruped_control.model.params import load_robot_params

PARAMS = load_robot_params()


def test_stance_is_the_nominal_foot_and_open_is_apart_by_the_offsets():
    stance, opened = reference_poses(PARAMS)
    assert np.allclose(np.degrees(opened.leg_angles) - np.degrees(stance.leg_angles), OPEN_OFFSET_DEG)
    assert stance.joint_angles().shape == (12,)
    for pose in (stance, opened):
        assert five_bar_problem(pose.leg_angles[0], pose.leg_angles[1], PARAMS.five_bar) is None


def test_sweeps_stay_safe_on_both_sides():
    stance, _ = reference_poses(PARAMS)
    for joint in range(3):
        half = sweep_half_width(PARAMS, stance.leg_angles, joint, math.radians(60.0))
        assert half >= math.radians(20.0)
        for delta in np.linspace(-half, half, 41):
            q = list(stance.leg_angles)
            q[joint] += delta
            assert five_bar_problem(q[0], q[1], PARAMS.five_bar) is None


def test_sweep_stops_before_the_five_bar_folds():
    q = (math.radians(-160.0), math.radians(-120.0), math.radians(90.0))  # near the folded corner
    half = sweep_half_width(PARAMS, q, 1, math.radians(60.0))
    assert half < math.radians(60.0)
    assert five_bar_problem(q[0], q[1] - half - math.radians(1.0), PARAMS.five_bar) or \
        five_bar_problem(q[0], q[1] + half + math.radians(1.0), PARAMS.five_bar)


def test_a_geometry_that_makes_a_pose_unsafe_is_refused():
    folded = dataclasses.replace(PARAMS, nominal_foot_leg=np.array([0.015, -0.050, -0.040]))
    with pytest.raises(ParameterError, match="reference pose open is not a safe five-bar configuration: links a1 "
                       "and a3 fold or cross"):
        reference_poses(folded)
    out_of_reach = dataclasses.replace(PARAMS, nominal_foot_leg=np.array([0.015, -0.050, -0.180]))
    with pytest.raises(ParameterError, match="reference pose stance .*out of reach"):
        reference_poses(out_of_reach)


@pytest.mark.parametrize("t1, t2, words", [(-140.0, -40.0, None), (-230.0, 10.0, "a1 and a3 fold or cross"),
                                           (-100.0, -120.0, "a2 and a4 fold or cross")])
def test_five_bar_problem_names_why(t1, t2, words):
    problem = five_bar_problem(math.radians(t1), math.radians(t2), PARAMS.five_bar)
    assert (problem is None) if words is None else (words in problem)
