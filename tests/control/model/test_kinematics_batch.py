"""The batched leg kinematics against the robot's float paths."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_control.model.kinematics import (UnreachableError, _five_bar_closure, _five_bar_rates,
                                                joint_angles_floats, leg_kinematics_flat, leg_row)
from quadruped_control.model.kinematics_batch import LegGeometry, joint_angles_batch
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.simulation import nominal_joint_angles


@pytest.fixture(scope="module")
def robot():
    return load_robot_params()


def test_ik_batch_matches_float_path_inside_and_outside_the_workspace(robot):
    rng = np.random.default_rng(3)
    nominal = np.array([robot.nominal_foot_body(leg) for leg in (1, 2, 3, 4)])
    targets = nominal + rng.normal(0.0, 0.04, (400, 4, 3))  # many beyond reach
    angles, ok = joint_angles_batch(targets, LegGeometry.from_params(robot))
    reached = 0
    for n in range(targets.shape[0]):
        for leg in range(4):
            try:
                expected = joint_angles_floats(*targets[n, leg].tolist(), leg + 1, robot)
            except UnreachableError:
                assert not ok[n, leg]
                continue
            assert ok[n, leg]
            reached += 1
            np.testing.assert_allclose(angles[n, leg], expected, rtol=0, atol=1e-12)
    assert 100 < reached < 1600  # both cases exercised


def test_leg_row_flags_five_bars_that_cannot_close_where_the_float_cores_raise(robot):
    """leg_row (the compiled plants' per-leg kinematics) says ok exactly where the raising cores of
    leg_kinematics_flat succeed; with short passive links many motor angles cannot close the five-bar."""
    fb = robot.five_bar
    a1, a2, a3, a4, c = fb.a1, fb.a2, 0.6 * fb.a3, 0.6 * fb.a4, fb.c
    frame = (0.1, 0.2, 0.0, 1.0, 1.0, 1.0)
    rng = np.random.default_rng(7)
    outcomes = set()
    for t1, t2, t3 in rng.uniform(-math.pi, math.pi, (300, 3)):
        ok = leg_row(t1, t2, t3, 0.1, -0.2, 0.3, frame, a1, a2, a3, a4, c, robot.l_y, robot.l_z)[0]
        try:
            _, _, phi, psi = _five_bar_closure(t1, t2, a1, a2, a3, a4, c)
            _five_bar_rates(t1, t2, phi, psi, a1, a2)  # the singularity check
            closes = True
        except UnreachableError:
            closes = False
        assert ok == closes
        outcomes.add(ok)
    assert outcomes == {True, False}


def test_leg_kinematics_flat_says_why_a_leg_cannot_close(robot):
    """Where leg_row says no, the float path raises the raising cores' error (here: a NaN angle; the
    robot's own five-bar closes at every motor angle)."""
    q = nominal_joint_angles(robot).tolist()
    q[2] = [math.nan, q[2][1], q[2][2]]
    with pytest.raises(UnreachableError, match="finite"):
        leg_kinematics_flat(q, np.zeros((4, 3)).tolist(), robot)
