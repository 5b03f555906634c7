"""The batched leg kinematics against the robot's float paths."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from quadruped_control.model.kinematics import (UnreachableError, _five_bar_closure, _five_bar_rates,
                                                joint_angles_floats, leg_kinematics_flat)
from quadruped_control.model.kinematics_batch import LegGeometry, joint_angles_batch, leg_kinematics_batch
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


def test_leg_kinematics_batch_matches_float_path(robot):
    rng = np.random.default_rng(4)
    q0 = nominal_joint_angles(robot)
    q = q0 + rng.normal(0.0, 0.05, (50, 4, 3))
    q_dot = rng.normal(0.0, 2.0, (50, 4, 3))
    feet, rates, ok = leg_kinematics_batch(q, q_dot, LegGeometry.from_params(robot))
    assert ok.all()
    for n in range(50):
        flat = np.array(leg_kinematics_flat(q[n].tolist(), q_dot[n].tolist(), robot)).reshape(4, 6)
        np.testing.assert_allclose(feet[n], flat[:, :3], rtol=0, atol=1e-14)
        np.testing.assert_allclose(rates[n], flat[:, 3:], rtol=0, atol=1e-12)


def test_leg_kinematics_batch_flags_five_bars_that_cannot_close(robot):
    """With short passive links many motor angles cannot close the five-bar: the mask says which, where
    the float cores raise (closure or type-2 singularity)."""
    geometry = dataclasses.replace(LegGeometry.from_params(robot), a3=0.6 * robot.five_bar.a3,
                                   a4=0.6 * robot.five_bar.a4)
    rng = np.random.default_rng(7)
    q = np.repeat(rng.uniform(-math.pi, math.pi, (300, 1, 3)), 4, axis=1)  # the same angles on every leg
    _, _, ok = leg_kinematics_batch(q, np.zeros_like(q), geometry)
    g = geometry
    for n in range(300):
        try:
            _, _, phi, psi = _five_bar_closure(q[n, 0, 0], q[n, 0, 1], g.a1, g.a2, g.a3, g.a4, g.c)
            _five_bar_rates(q[n, 0, 0], q[n, 0, 1], phi, psi, g.a1, g.a2)  # the singularity check
            closes = True
        except UnreachableError:
            closes = False
        assert ok[n] == closes
    assert 10 < ok.sum() < 290
