"""Tests of quadruped_control.sim.plants.rigid_body: the plants' shared state, input checks, SO(3) chart
helpers and step context, each against its readable counterpart."""
import decimal
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.robot import LEGS
from quadruped_common.so3 import exp_so3, hat
from quadruped_control.model import hydrodynamics as hd
from quadruped_control.model.kinematics import joint_angles, leg_kinematics, leg_kinematics_rows
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.rigid_body import (SERIES_ANGLE, DynamicsError, RigidBodyState, StepContext, as_mat3,
                                                     chart_coefficients, chart_point, chart_rate, chart_step_end,
                                                     check_dt, exp_rotation, joint_array, matmul)

PARAMS = load_robot_params()
Q0 = np.array([joint_angles(PARAMS.nominal_foot_body(leg), leg, PARAMS) for leg in LEGS])

#: Rotation vectors of these norms, on both sides of the series threshold SERIES_ANGLE = 0.02.
xi_norms = st.sampled_from([0.0, 1e-7, 5e-5, 2e-4, 0.005, 0.0199, 0.0201, 0.3, 2.0, 3.0])


def _closed_forms_exactly(t):
    """(sin t / t, (1 - cos t) / t^2, 1/t^2 - (1 + cos t) / (2 t sin t)) in 60-digit decimal arithmetic
    (sine and cosine by their Taylor sums): the closed forms without their cancellation."""
    with decimal.localcontext() as context:
        context.prec = 60
        T = decimal.Decimal(t)
        sin_t, cos_t, term = decimal.Decimal(0), decimal.Decimal(0), decimal.Decimal(1)
        for k in range(60):  # term = t^k / k!
            if k % 4 == 0:
                cos_t += term
            elif k % 4 == 1:
                sin_t += term
            elif k % 4 == 2:
                cos_t -= term
            else:
                sin_t -= term
            term = term * T / (k + 1)
        return (float(sin_t / T), float((1 - cos_t) / (T * T)),
                float(1 / (T * T) - (1 + cos_t) / (2 * T * sin_t)))


@pytest.mark.parametrize("t", [1e-6, 1e-3, 0.005, 0.0199, 0.02, 0.05, 0.5, 3.0])
def test_chart_coefficients_are_the_closed_forms_to_rounding(t):
    """Below SERIES_ANGLE the series are exact to rounding; above it the closed forms carry their
    cancellation (about eps / t^2) as before the series' threshold moved up to 0.02."""
    exact = _closed_forms_exactly(t)
    tolerance = 3e-16 if t < SERIES_ANGLE else max(3e-16, 4e-16 / (t * t))
    np.testing.assert_allclose(chart_coefficients(t * t), exact, rtol=0, atol=tolerance)


def random_rotation_vector(seed, norm):
    """(rng, xi): a seeded generator and a rotation vector of the given norm in a random direction."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    return rng, norm * axis / np.linalg.norm(axis)


@settings(max_examples=80)
@given(st.integers(0, 2 ** 32 - 1), xi_norms)
def test_exp_rotation_equals_exp_so3(seed, norm):
    rng, xi = random_rotation_vector(seed, norm)
    np.testing.assert_allclose(np.reshape(exp_rotation(*xi.tolist()), (3, 3)), exp_so3(xi), rtol=0, atol=1e-15)
    R0 = exp_so3(rng.uniform(-2.0, 2.0, 3))
    np.testing.assert_allclose(np.reshape(matmul(as_mat3(R0), exp_rotation(*xi.tolist())), (3, 3)),
                               R0 @ exp_so3(xi), rtol=0, atol=1e-15)


@settings(max_examples=80)
@given(st.integers(0, 2 ** 32 - 1), xi_norms)
def test_chart_rate_inverts_the_right_jacobian(seed, norm):
    """omega = J_r(xi) d xi/dt, checked by differentiating exp(hat(xi(t))) numerically."""
    rng, xi = random_rotation_vector(seed, norm)
    omega = rng.normal(size=3)
    rate = np.array(chart_rate(*xi.tolist(), *omega.tolist()))
    h = 1e-6
    R_dot = (exp_so3(xi + h * rate) - exp_so3(xi - h * rate)) / (2.0 * h)
    np.testing.assert_allclose(exp_so3(xi).T @ R_dot, hat(omega), rtol=0, atol=1e-8)


def test_chart_point_at_zero_is_the_identity_of_the_chart():
    R0 = as_mat3(exp_so3([0.3, -1.2, 2.0]))
    R, rate = chart_point(R0, 0.0, 0.0, 0.0, 0.4, -0.1, 0.7)
    assert R == matmul(R0, exp_rotation(0.0, 0.0, 0.0)) and rate == chart_rate(0.0, 0.0, 0.0, 0.4, -0.1, 0.7)
    R, rate = chart_point(R0, 0.01, 0.0, -0.02, 0.4, -0.1, 0.7)
    assert R == matmul(R0, exp_rotation(0.01, 0.0, -0.02)) and rate == chart_rate(0.01, 0.0, -0.02, 0.4, -0.1, 0.7)


def test_chart_step_end_polishes_the_rotation_and_refuses_non_finite_states():
    R0 = exp_so3([0.3, -1.2, 2.0])
    drifted = as_mat3(R0 + 1e-9 * np.arange(9.0).reshape(3, 3))  # off SO(3) by about 1e-8
    state = chart_step_end(drifted, (1.0, 2.0, 3.0, 0.1, 0.2, 0.3), (0.01, 0.02, -0.01), (0.5, 0.6, 0.7), 0.01,
                           RigidBodyState())
    R = state.rotation
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-15
    np.testing.assert_allclose(R, np.reshape(drifted, (3, 3)) @ exp_so3([0.01, 0.02, -0.01]), atol=1e-7)
    assert state.position.tolist() == [1.0, 2.0, 3.0] and state.omega.tolist() == [0.5, 0.6, 0.7]
    before = state.to_vector()
    state.velocity += 1.0  # one buffer, disjoint fields
    np.testing.assert_array_equal(np.delete(state.to_vector(), [3, 4, 5]), np.delete(before, [3, 4, 5]))
    with pytest.raises(DynamicsError, match="non-finite state"):
        chart_step_end(as_mat3(R0), (0.0, 0.0, math.nan, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01,
                       RigidBodyState())
    with pytest.raises(DynamicsError, match="non-finite state"):
        chart_step_end(as_mat3(R0), (0.0,) * 6, (0.0, 0.0, 0.0), (1e308, 1e308, math.inf), 0.01, RigidBodyState())


def test_step_context_from_rows_equals_flat_constructor():
    rng = np.random.default_rng(3)
    q, q_dot = (Q0 + rng.uniform(-0.2, 0.2, (4, 3))).tolist(), rng.uniform(-3.0, 3.0, (4, 3)).tolist()
    restoring = tuple(rng.normal(size=9).tolist())
    a = StepContext.from_rows(leg_kinematics(q, q_dot, PARAMS), 0.37, restoring)
    b = StepContext(leg_kinematics_rows(q, q_dot, PARAMS), 0.37, restoring)
    assert a.feet == b.feet and a.up_torque == b.up_torque and a.lift == b.lift
    # U = restoring + B_net hat(sum_i r_i): the paw buoyancy torque of hydrodynamics plus the restoring one.
    feet = np.array(b.feet)[:, :3]
    R = exp_so3([0.4, -0.3, 1.1])
    force, torque = hd.paw_buoyancy(feet, R, PARAMS)
    context = StepContext(leg_kinematics_rows(q, q_dot, PARAMS), PARAMS.paw_net_buoyancy, restoring)
    np.testing.assert_allclose(np.reshape(context.up_torque, (3, 3)) @ R[2, :],
                               torque + np.reshape(restoring, (3, 3)) @ R[2, :], rtol=1e-12, atol=1e-15)
    assert context.lift == force[2]


def test_input_checks():
    np.testing.assert_array_equal(joint_array(np.arange(12.0), "q"), np.arange(12.0).reshape(4, 3))
    with pytest.raises(ValueError, match="shape"):
        joint_array(np.zeros((3, 3)), "q")
    with pytest.raises(ValueError, match="q_dot has non-finite"):
        joint_array(np.full(12, math.inf), "q_dot")
    assert check_dt(1) == 1.0 and isinstance(check_dt(1), float)
    for bad in (0.0, -0.01, math.nan, math.inf):
        with pytest.raises(ValueError, match="dt"):
            check_dt(bad)
