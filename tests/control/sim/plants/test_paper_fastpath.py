"""The simulator's fast paths in quadruped_control.sim.plants.paper agree with the reference code they replace."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.robot import LEGS
from quadruped_common.so3 import exp_so3
from quadruped_control.model.kinematics import UnreachableError, foot_jacobian, foot_position
from quadruped_control.model.params import load_robot_params
from quadruped_control.model.kinematics import leg_kinematics
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState
from quadruped_control.sim.simulation import nominal_joint_angles

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


def test_step_trusted_equals_step() -> None:
    model = FloatingBaseModel(PARAMS)
    state = RigidBodyState(rotation=exp_so3([0.3, -0.2, 0.5]), omega=np.array([0.2, 0.1, -0.3]))
    q_dot = np.full((4, 3), 0.7)
    a = model.step(state, Q0, q_dot, 0.01)
    b = model.step_trusted(state, Q0, q_dot, 0.01)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())
