"""The tank plant's force laws on floats (:mod:`quadruped_control.sim.plants.tank_dynamics`) on their own: the
tether bent where it leaves the body. The other laws are tested through the plant, tests/control/sim/plants/
test_tank.py."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from quadruped_common.so3 import exp_so3, rpy_to_rot
from quadruped_control.sim.plants.tank_dynamics import tether_bend_torque, tether_relaxation_update, tilt_vector

ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)


def _flat(R: np.ndarray) -> tuple:
    return tuple(np.asarray(R, dtype=float).ravel().tolist())


@settings(max_examples=200, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), ANGLE)
def test_the_tilt_is_the_swing_that_takes_up_to_the_bodys_z_axis(roll: float, pitch: float, yaw: float) -> None:
    """Short of upside down (the next test), theta is horizontal, its length is the angle between the world's
    up and the body's z axis, and the rotation it names takes the one to the other; a turn about the body's
    z axis leaves it, a turn about the world's vertical turns it with the body."""
    R = rpy_to_rot(roll, pitch, yaw)
    theta = np.array(tilt_vector(_flat(R)))
    z = R[:, 2]
    assert theta[2] == 0.0
    assert np.linalg.norm(theta) == pytest.approx(math.acos(max(-1.0, min(1.0, z[2]))), abs=1e-9)
    np.testing.assert_allclose(Rotation.from_rotvec(theta).apply([0.0, 0.0, 1.0]), z, atol=1e-9)
    np.testing.assert_allclose(tilt_vector(_flat(R @ rpy_to_rot(0.0, 0.0, 0.7))), theta, atol=1e-12)
    np.testing.assert_allclose(tilt_vector(_flat(rpy_to_rot(0.0, 0.0, 0.7) @ R)), rpy_to_rot(0.0, 0.0, 0.7) @ theta,
                               atol=1e-9)


def test_the_tilt_of_an_upright_or_an_upside_down_body_is_zero() -> None:
    assert tilt_vector(_flat(np.eye(3))) == (0.0, 0.0, 0.0)
    assert tilt_vector(_flat(rpy_to_rot(0.0, 0.0, 2.0))) == (0.0, 0.0, 0.0)
    assert tilt_vector(_flat(np.diag([1.0, -1.0, -1.0]))) == (0.0, 0.0, 0.0)  # no horizontal axis: taken as 0
    np.testing.assert_allclose(tilt_vector(_flat(rpy_to_rot(0.3, 0.0, 0.0))), (0.3, 0.0, 0.0), atol=1e-15)


def _bend_energy(R: np.ndarray, elastic: float, relaxing: float) -> float:
    theta = np.array(tilt_vector(_flat(R)))
    return 0.5 * (elastic + relaxing) * float(theta @ theta)


@pytest.mark.parametrize("rpy", [(0.2, 0.0, 0.0), (0.0, -0.5, 1.0), (0.4, 0.3, -2.0), (1.2, -0.9, 0.5)])
def test_a_bend_relaxed_upright_is_the_gradient_of_its_energy(rpy) -> None:
    """With the relaxed tilt 0 both branches are the spring of potential (k_e + k) |theta|^2 / 2: the work of
    the torque over a small rotation about any axis is minus the change of that energy (a turn about the
    vertical changes neither)."""
    elastic, relaxing = 0.03, 0.05
    R = rpy_to_rot(*rpy)
    torque = np.array(tether_bend_torque(_flat(R), (elastic, relaxing, 5.0, 0.0, 0.0, 0.0)))  # body axes
    for axis in np.eye(3):
        e = 1e-6
        change = (_bend_energy(R @ exp_so3(e * axis), elastic, relaxing)
                  - _bend_energy(R @ exp_so3(-e * axis), elastic, relaxing)) / (2.0 * e)
        assert float(torque @ axis) == pytest.approx(-change, abs=1e-8)


def test_the_relaxing_branch_pulls_towards_the_relaxed_tilt_and_the_elastic_one_towards_upright() -> None:
    """Held at a 20 deg roll: relaxed there, only the elastic branch pulls (back to upright); relaxed upright,
    both do; no stiffness, no torque."""
    R = _flat(rpy_to_rot(math.radians(20.0), 0.0, 0.0))
    theta = math.radians(20.0)
    np.testing.assert_allclose(tether_bend_torque(R, (0.02, 0.1, 5.0, theta, 0.0, 0.0)), (-0.02 * theta, 0.0, 0.0),
                               atol=1e-15)
    np.testing.assert_allclose(tether_bend_torque(R, (0.02, 0.1, 5.0, 0.0, 0.0, 0.0)), (-0.12 * theta, 0.0, 0.0),
                               atol=1e-15)
    assert tether_bend_torque(R, (0.0, 0.0, 5.0, 0.1, 0.2, 0.0)) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("tau", [0.1, 5.0, 300.0])
def test_the_relaxed_tilt_follows_a_held_tilt_exactly_and_the_bend_fades_with_its_time(tau: float) -> None:
    """Held at a tilt, s = theta (1 - exp(-t / tau)) whatever the step: the relaxing branch's torque decays
    as exp(-t / tau), the elastic one stays."""
    R = _flat(rpy_to_rot(0.3, -0.2, 0.4))
    theta = np.array(tilt_vector(R))
    tether = (0.01, 0.1, tau, 0.0, 0.0, 0.0)
    for dt, steps in ((0.01, 500), (0.05, 100)):
        state = tether
        for _ in range(steps):
            state = state[:3] + tether_relaxation_update(R, state, dt)
        t = dt * steps
        np.testing.assert_allclose(state[3:], theta * (1.0 - math.exp(-t / tau)), rtol=1e-12, atol=1e-15)
        world = -0.01 * theta - 0.1 * theta * math.exp(-t / tau)
        np.testing.assert_allclose(tether_bend_torque(R, state), np.array(rpy_to_rot(0.3, -0.2, 0.4)).T @ world,
                                   rtol=1e-9, atol=1e-15)
