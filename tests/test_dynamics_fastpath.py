"""The simulator's fast paths in quadruped_control.dynamics agree with the reference code they replace."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_control.dynamics import FloatingBaseModel, RigidBodyState, _as_mat3, leg_kinematics
from quadruped_control.kinematics import UnreachableError, foot_jacobian, foot_position
from quadruped_control.params import LEGS, load_robot_params
from quadruped_control.simulation import nominal_joint_angles
from quadruped_control.so3 import exp_so3

PARAMS = load_robot_params()
Q0 = nominal_joint_angles(PARAMS)


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1))
def test_leg_kinematics_matches_foot_position_and_jacobian(seed) -> None:
    rng = np.random.default_rng(seed)
    q = Q0 + rng.uniform(-0.4, 0.4, (4, 3))
    q_dot = rng.uniform(-5.0, 5.0, (4, 3))
    rows = np.array(leg_kinematics(q.tolist(), q_dot.tolist(), PARAMS))
    for row, leg in enumerate(LEGS):
        np.testing.assert_allclose(rows[row, :3], foot_position(q[row], leg, PARAMS), rtol=0, atol=1e-14)
        np.testing.assert_allclose(rows[row, 3:], foot_jacobian(q[row], leg, PARAMS) @ q_dot[row],
                                   rtol=1e-12, atol=1e-13)


def test_leg_kinematics_raises_the_kinematics_error_for_irregular_input() -> None:
    q = Q0.copy()
    q[2, 0] = np.nan
    with pytest.raises(UnreachableError):
        leg_kinematics(q.tolist(), np.zeros((4, 3)).tolist(), PARAMS)


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1), st.booleans())
def test_fused_stage_equals_composed_chart_derivative(seed, small_angle) -> None:
    rng = np.random.default_rng(seed)
    model = FloatingBaseModel(PARAMS, restoring_offset=rng.uniform(-0.02, 0.02, 3))
    context = model._context_from_joints(Q0 + rng.uniform(-0.2, 0.2, (4, 3)), rng.uniform(-3.0, 3.0, (4, 3)))
    R0 = _as_mat3(exp_so3(rng.uniform(-2.0, 2.0, 3)))
    y = (rng.normal(size=12) * [1, 1, 1, 0.5, 0.5, 0.5, 1, 1, 1, 2, 2, 2]).tolist()
    if small_angle:
        y[6:9] = [1e-6, -2e-6, 0.0]
    np.testing.assert_allclose(model._stage(context, R0, y), model._chart_derivative(context, R0, y),
                               rtol=1e-13, atol=1e-13)


def test_step_trusted_equals_step() -> None:
    model = FloatingBaseModel(PARAMS)
    state = RigidBodyState(rotation=exp_so3([0.3, -0.2, 0.5]), omega=np.array([0.2, 0.1, -0.3]))
    q_dot = np.full((4, 3), 0.7)
    a = model.step(state, Q0, q_dot, 0.01)
    b = model.step_trusted(state, Q0, q_dot, 0.01)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())
