"""Tests of quadruped_control.control.allocation: eq. (foot_speed), (foot_vel) and the torque they produce."""
import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from quadruped_common.robot import LEGS
from quadruped_common.so3 import exp_so3, rpy_to_rot
from quadruped_control.control.allocation import (allocate, estimate_body_torque, foot_speed, foot_velocity_command,
                                          force_direction, leg_torques)
from quadruped_control.control import allocation
from quadruped_control.model import hydrodynamics as hd
from quadruped_control.model.kinematics import joint_angles
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState

PARAMS = load_robot_params()
K = PARAMS.drag_constant

finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
vectors = st.tuples(finite, finite, finite).map(np.array)
# Physically meaningful sizes: torques up to 10 N m, feet 5 cm .. 1 m from the centre of mass.
torques = st.tuples(*[st.floats(-10.0, 10.0)] * 3).map(np.array).filter(lambda v: np.linalg.norm(v) > 1e-3)
arms = st.tuples(*[st.floats(-1.0, 1.0)] * 3).map(np.array).filter(lambda v: 0.05 < np.linalg.norm(v))
rates = st.tuples(*[st.floats(-3.0, 3.0)] * 3).map(np.array)
rotations = st.tuples(*[st.floats(-3.0, 3.0)] * 3).map(lambda w: exp_so3(np.array(w)))


def delivered_torque(v_cmd, r, R=np.eye(3), omega=np.zeros(3)):
    """Torque of the paw drag, eq. (torque_leg), for a body at rest in translation rotating at omega,
    with the foot moving relative to the body at v_cmd: v_e^W = R (omega x r + v_cmd), eq. (ee_vel)."""
    v_world = R @ (np.cross(omega, r) + v_cmd)
    _, torque = hd.leg_wrench(v_world, r, R, PARAMS)
    return torque


def perpendicular(tau, r):
    r_hat = r / np.linalg.norm(r)
    return tau - (tau @ r_hat) * r_hat


# --------------------------------------------------------------------------------------------------
# Hand-computed values
# --------------------------------------------------------------------------------------------------

def test_equal_split_among_legs():
    shares = leg_torques([0.8, -0.4, 2.0])
    assert shares.shape == (4, 3)
    np.testing.assert_allclose(shares, np.tile([0.2, -0.1, 0.5], (4, 1)))
    assert leg_torques([3.0, 0.0, 0.0], n_legs=3).shape == (3, 3)
    with pytest.raises(ValueError, match="n_legs"):
        leg_torques([1.0, 0.0, 0.0], n_legs=0)
    with pytest.raises(ValueError, match="non-finite"):
        leg_torques([math.nan, 0.0, 0.0])


def test_orthogonal_case_by_hand():
    # tau along +z, foot along +x: f = z x x = +y; the foot must move along -y, v = sqrt(|tau|/(k|r|)).
    tau, r = np.array([0.0, 0.0, 0.5]), np.array([0.3, 0.0, 0.0])
    np.testing.assert_allclose(force_direction(tau, r), [0.0, 1.0, 0.0])
    speed = math.sqrt(0.5 / (K * 0.3))
    assert foot_speed(tau, r, K) == pytest.approx(speed, rel=1e-15)
    np.testing.assert_allclose(foot_velocity_command(tau, r, np.zeros(3), K), [0.0, -speed, 0.0], rtol=1e-15)
    # Drag on a foot moving along -y at x = 0.3 m: F = +k v^2 y, torque r x F = 0.3 k v^2 z = tau.
    np.testing.assert_allclose(delivered_torque(foot_velocity_command(tau, r, np.zeros(3), K), r), tau,
                               rtol=1e-12, atol=1e-15)


def test_force_direction_as_written_has_norm_sin_angle():
    tau = np.array([1.0, 0.0, 1.0])  # 45 degrees from r
    r = np.array([2.0, 0.0, 0.0])
    f = force_direction(tau, r)
    assert np.linalg.norm(f) == pytest.approx(math.sin(math.pi / 4))
    np.testing.assert_allclose(force_direction(tau, r, normalize=True), [0.0, 1.0, 0.0], atol=1e-15)


def test_rotation_compensation_term():
    r = np.array([0.2, -0.1, -0.15])
    omega = np.array([0.3, -0.5, 1.0])
    # Zero torque: the foot only cancels the motion the body rotation gives it.
    np.testing.assert_allclose(foot_velocity_command(np.zeros(3), r, omega, K), -np.cross(omega, r))


@pytest.mark.parametrize("tau, r", [
    ([0.0, 0.0, 0.0], [0.3, 0.2, -0.1]),        # no torque
    ([1e-14, 0.0, 0.0], [0.3, 0.2, -0.1]),      # below MIN_TORQUE
    ([0.5, 0.1, 0.0], [0.0, 0.0, 0.0]),         # foot at the body origin
    ([0.5, 0.0, 0.0], [0.3, 0.0, 0.0]),         # foot on the torque axis
    ([-0.5, 0.0, 0.0], [0.3, 0.0, 1e-12]),      # (almost) on the axis
])
@pytest.mark.parametrize("normalize", [False, True])
def test_degenerate_cases_give_zero_velocity(tau, r, normalize):
    assert np.all(force_direction(tau, r, normalize) == 0.0)
    v = foot_velocity_command(tau, r, np.zeros(3), K, normalize)
    assert np.all(v == 0.0)


def test_bad_input_raises():
    with pytest.raises(ValueError, match="non-finite"):
        force_direction([math.inf, 0.0, 0.0], [0.3, 0.0, 0.0])
    with pytest.raises(ValueError, match="3 elements"):
        foot_speed([1.0, 0.0], [0.3, 0.0, 0.0], K)
    with pytest.raises(ValueError, match="drag constant"):
        foot_speed([1.0, 0.0, 0.0], [0.3, 0.0, 0.0], 0.0)
    with pytest.raises(ValueError, match="omega"):
        foot_velocity_command([1.0, 0.0, 0.0], [0.0, 0.3, 0.0], [math.nan, 0.0, 0.0], K)


def test_allocate_all_legs():
    feet = np.array([PARAMS.nominal_foot_body(leg) for leg in LEGS])
    tau = np.array([0.8, -0.3, 0.2])
    omega = np.array([0.1, 0.2, -0.3])
    out = allocate(tau, feet, omega, K, normalize=True)
    assert out.shape == (4, 3)
    for row in range(4):
        np.testing.assert_allclose(out[row], foot_velocity_command(tau / 4, feet[row], omega, K, True))
    # Every leg's share adds up to tau_sat when the normalised directions are delivered: the sum of the
    # perpendicular parts is what legs can do; check the total points along tau.
    total = sum(delivered_torque(out[row], feet[row], omega=omega) for row in range(4))
    assert total @ tau > 0.0
    with pytest.raises(ValueError, match="shape"):
        allocate(tau, feet[0], omega, K)


# --------------------------------------------------------------------------------------------------
# Properties: the drag of the commanded foot motion produces the commanded torque
# --------------------------------------------------------------------------------------------------

@given(torques, arms, rotations, rates)
def test_as_written_delivers_sin_times_perpendicular_part(tau, r, R, omega):
    """With f = tau_hat x r_hat as written, the paw drag torque is sin(a) (tau - (tau.r_hat) r_hat), whatever
    the body attitude and rotation rate (the -omega x r term cancels the rotation)."""
    v = foot_velocity_command(tau, r, omega, K, normalize=False)
    torque = delivered_torque(v, r, R, omega)
    sin_a = np.linalg.norm(np.cross(tau, r)) / (np.linalg.norm(tau) * np.linalg.norm(r))
    np.testing.assert_allclose(torque, sin_a * perpendicular(tau, r), atol=1e-9 * np.linalg.norm(tau))
    assert torque @ tau >= -1e-12


@given(torques, arms, rotations, rates)
def test_normalised_delivers_full_magnitude_along_perpendicular_part(tau, r, R, omega):
    sin_a = np.linalg.norm(np.cross(tau, r)) / (np.linalg.norm(tau) * np.linalg.norm(r))
    assume(sin_a > 1e-3)
    v = foot_velocity_command(tau, r, omega, K, normalize=True)
    torque = delivered_torque(v, r, R, omega)
    assert np.linalg.norm(torque) == pytest.approx(np.linalg.norm(tau), rel=1e-9)
    direction = perpendicular(tau, r)
    np.testing.assert_allclose(torque / np.linalg.norm(torque), direction / np.linalg.norm(direction), atol=1e-9)


@given(torques, arms, rotations, rates)
def test_orthogonal_torque_is_delivered_exactly(tau, r, R, omega):
    tau_perp = perpendicular(tau, r)
    assume(np.linalg.norm(tau_perp) > 1e-3)
    for normalize in (False, True):
        v = foot_velocity_command(tau_perp, r, omega, K, normalize)
        np.testing.assert_allclose(delivered_torque(v, r, R, omega), tau_perp, atol=1e-9)


@given(vectors, vectors, vectors, st.booleans(),
       st.sampled_from([0.0, 5e-324, 1e-300, 1e-15, 1e-9, 1.0, 1e3]))
def test_never_nan_for_finite_input(tau, r, omega, normalize, scale):
    v = foot_velocity_command(tau * scale, r * scale, omega, K, normalize)
    assert np.all(np.isfinite(v))
    assert np.all(np.isfinite(force_direction(tau * scale, r, normalize)))
    assert math.isfinite(foot_speed(tau, r * scale, K))


# --------------------------------------------------------------------------------------------------
# Torque estimate from joint motion (eq. (torque_leg) summed)
# --------------------------------------------------------------------------------------------------

def test_estimate_body_torque_matches_the_dynamics_model():
    q = np.array([joint_angles(PARAMS.nominal_foot_body(leg), leg, PARAMS) for leg in LEGS])
    rng = np.random.default_rng(3)
    q_dot = rng.uniform(-2.0, 2.0, (4, 3))
    R = rpy_to_rot(0.3, -0.2, 1.0)
    omega = np.array([0.2, -0.4, 0.1])
    velocity = np.array([0.05, -0.02, 0.01])
    wrench = FloatingBaseModel(PARAMS).wrench(RigidBodyState(velocity=velocity, rotation=R, omega=omega), q, q_dot)
    expected = wrench.leg_torques_body.sum(axis=0)
    np.testing.assert_allclose(estimate_body_torque(q, q_dot, R, omega, PARAMS, velocity), expected, atol=1e-12)
    # Legs still, body still: no torque. Wrong shapes and NaN are rejected.
    assert np.all(estimate_body_torque(q, np.zeros((4, 3)), R, np.zeros(3), PARAMS) == 0.0)
    with pytest.raises(ValueError, match="12 elements"):
        estimate_body_torque(q[:3], q_dot[:3], R, omega, PARAMS)
    with pytest.raises(ValueError, match="finite"):
        estimate_body_torque(q, q_dot * math.nan, R, omega, PARAMS)


def test_allocation_compiles_to_the_float_path_including_degenerate_cases():
    """foot_velocity_command_f, which the batched controller runs compiled, against itself in Python."""
    from quadruped_common import jit

    rng = np.random.default_rng(5)
    tau = rng.normal(0.0, 1.0, (300, 3))
    r = rng.normal(0.0, 0.2, (300, 3))
    tau[:10] = 0.0                      # no torque: no stroke
    r[10:20] = 0.0                      # no arm
    r[20:30] = 0.3 * tau[20:30]         # foot on the torque axis
    omega = rng.normal(0.0, 0.5, (300, 3))
    normalize = rng.random(300) < 0.5

    def commands(tau, r, omega, normalize, out):
        for i in range(tau.shape[0]):
            out[i, 0], out[i, 1], out[i, 2] = allocation.foot_velocity_command_f(
                (tau[i, 0], tau[i, 1], tau[i, 2]), (r[i, 0], r[i, 1], r[i, 2]), (omega[i, 0], omega[i, 1], omega[i, 2]),
                3.3, normalize[i])

    plain = np.zeros((300, 3))
    commands(tau, r, omega, normalize, plain)
    np.testing.assert_array_equal(plain[:30], -np.cross(omega[:30], r[:30]))  # no stroke: v = -omega x r
    if jit.AVAILABLE:
        compiled = np.zeros((300, 3))
        jit.kernel(commands)(tau, r, omega, normalize, compiled)
        np.testing.assert_allclose(compiled, plain, rtol=1e-12, atol=1e-15)

