"""The closed-loop simulator's float fast paths agree with the reference code they replace.

Covers FloatingBaseModel._stage9 / _rk4_held (held-input RK4 on unpacked floats) against _chart_derivative / _rk4,
kinematics.joint_angles_floats against joint_angles, PlantSimulator's float hold input against the array
formulas of held_joint_input, and the controller's single-buffer output arrays.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.robot import LEGS
from quadruped_common.so3 import exp_so3, rpy_to_rot
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.kinematics import UnreachableError, joint_angles, joint_angles_floats, joint_angles_full
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.paper import DynamicsError, FloatingBaseModel, RigidBodyState, _as_mat3, held_joint_input
from quadruped_control.sim.servo_model import IdealServo, RateLimitedServo, ServoParams
from quadruped_control.sim.simulation import ClosedLoopSimulation, PlantSimulator, SimulationError, nominal_joint_angles

PARAMS = load_robot_params()
Q0 = nominal_joint_angles(PARAMS)


def _random_state(rng: np.random.Generator) -> RigidBodyState:
    return RigidBodyState(rng.normal(size=3), 0.3 * rng.normal(size=3), exp_so3(rng.uniform(-2.0, 2.0, 3)),
                          rng.normal(size=3))


# ------------------------------------------------------------------ dynamics

@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from(["zero", "small", "large"]))
def test_stage9_equals_reference_chart_derivative(seed, xi_kind) -> None:
    rng = np.random.default_rng(seed)
    model = FloatingBaseModel(PARAMS, restoring_offset=rng.uniform(-0.02, 0.02, 3))
    context = model._context_from_joints(Q0 + rng.uniform(-0.2, 0.2, (4, 3)), rng.uniform(-3.0, 3.0, (4, 3)))
    R0 = _as_mat3(exp_so3(rng.uniform(-2.0, 2.0, 3)))
    y = (rng.normal(size=12) * [1, 1, 1, 0.5, 0.5, 0.5, 1, 1, 1, 2, 2, 2]).tolist()
    y[6:9] = {"zero": [0.0, 0.0, 0.0], "small": [1e-6, -2e-6, 0.0], "large": y[6:9]}[xi_kind]
    reference = model._chart_derivative(context, R0, y)
    fast = model._stage9(context, R0, *y[3:12])
    np.testing.assert_allclose(fast, reference[3:], rtol=1e-12, atol=1e-13)


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1), st.booleans())
def test_rk4_held_equals_reference_rk4(seed, restoring) -> None:
    rng = np.random.default_rng(seed)
    model = FloatingBaseModel(PARAMS, restoring_offset=rng.uniform(-0.02, 0.02, 3) if restoring else None)
    context = model._context_from_joints(Q0 + rng.uniform(-0.2, 0.2, (4, 3)), rng.uniform(-3.0, 3.0, (4, 3)))
    state = _random_state(rng)
    dt = float(rng.choice([0.001, 0.01, 0.05]))
    reference = model._rk4(state, dt, (context, context, context)).to_vector()
    fast = model._rk4_held(state, dt, context)
    np.testing.assert_allclose(fast.to_vector(), reference, rtol=1e-12, atol=1e-15)
    assert fast.rotation.shape == (3, 3) and fast.position.shape == fast.omega.shape == (3,)


def test_rk4_held_from_rest_keeps_state_and_state_fields_are_independent() -> None:
    model = FloatingBaseModel(PARAMS)
    context = model._context_from_joints(Q0, np.zeros((4, 3)))
    state = model._rk4_held(RigidBodyState(), 0.01, context)
    np.testing.assert_allclose(state.to_vector(),
                               model._rk4(RigidBodyState(), 0.01, (context,) * 3).to_vector(), atol=1e-15)
    before = state.to_vector()
    state.position += 1.0  # the fields share one buffer but do not overlap
    np.testing.assert_array_equal(state.to_vector()[3:], before[3:])


def test_rk4_held_raises_dynamics_error_when_diverging() -> None:
    model = FloatingBaseModel(PARAMS)
    context = model._context_from_joints(Q0, np.zeros((4, 3)))
    state = RigidBodyState(velocity=np.array([1e200, 0.0, 0.0]))
    with pytest.raises(DynamicsError):
        model._rk4_held(state, 0.01, context)


def test_step_trusted_accepts_nested_lists() -> None:
    model = FloatingBaseModel(PARAMS)
    state = RigidBodyState(rotation=exp_so3([0.3, -0.2, 0.5]), omega=np.array([0.2, 0.1, -0.3]))
    q_dot = np.full((4, 3), 0.7)
    a = model.step(state, Q0, q_dot, 0.01)
    b = model.step_trusted(state, Q0.tolist(), q_dot.tolist(), 0.01)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())


# ------------------------------------------------------------------ kinematics

@settings(max_examples=300)
@given(st.sampled_from(LEGS), st.tuples(*[st.floats(-0.08, 0.08)] * 3))
def test_joint_angles_floats_equals_reference_ik(leg, offset) -> None:
    target = np.array(PARAMS.nominal_foot_body(leg)) + np.array(offset)
    try:
        expected = joint_angles_full(target, leg, PARAMS)[:3].tolist()
    except UnreachableError as exc:
        with pytest.raises(UnreachableError) as info:
            joint_angles_floats(*target.tolist(), leg, PARAMS)
        assert str(info.value) == str(exc)
        return
    assert list(joint_angles_floats(*target.tolist(), leg, PARAMS)) == expected  # bit for bit
    assert joint_angles(target, leg, PARAMS).tolist() == expected


@pytest.mark.parametrize("target", [(math.nan, 0.0, 0.0), (math.inf, 0.1, 0.1), (0.0, -math.inf, 0.0)])
def test_joint_angles_floats_rejects_non_finite_targets(target) -> None:
    with pytest.raises(UnreachableError):
        joint_angles_floats(*target, 1, PARAMS)


def test_joint_angles_floats_rejects_bad_leg() -> None:
    with pytest.raises(ValueError):
        joint_angles_floats(0.1, 0.1, -0.1, 5, PARAMS)


# ------------------------------------------------------------------ plant

def _reference_plant_step(model: FloatingBaseModel, state: RigidBodyState, q0: np.ndarray, q1: np.ndarray,
                          h: float) -> RigidBodyState:
    q_hold, q_dot = held_joint_input(q0, q1, h)
    context = model._context(model.leg_input(q_hold, q_dot))
    return model._rk4(state, h, (context, context, context))


@settings(max_examples=30)
@given(st.integers(0, 2 ** 32 - 1), st.booleans(), st.booleans())
def test_plant_float_hold_equals_array_reference(seed, rate_limited, clamp) -> None:
    rng = np.random.default_rng(seed)
    servo = RateLimitedServo(ServoParams(8.0, 0.03)) if rate_limited else IdealServo()
    plant = PlantSimulator(PARAMS, servo, initial_rotation=exp_so3(rng.uniform(-1.0, 1.0, 3)))
    reference_servo = RateLimitedServo(ServoParams(8.0, 0.03)) if rate_limited else IdealServo()
    reference_servo.reset(Q0)
    state = plant.state
    q_prev = Q0.copy()
    low, high = plant._low, plant._high
    for _ in range(5):
        command = Q0 + rng.uniform(-0.1, 0.1, (4, 3))
        if clamp:
            command[1, 2] = high[1, 2] + 0.5
        q_next = reference_servo.update(np.clip(command, low, high), 0.01)
        state = _reference_plant_step(plant.model, state, q_prev, q_next, 0.01)
        new = plant.step(command)
        np.testing.assert_allclose(new.to_vector(), state.to_vector(), rtol=1e-13, atol=1e-15)
        np.testing.assert_array_equal(plant.joint_positions, q_next)
        q_prev = q_next
    assert plant.clamped_joints == (5 if clamp else 0)


def test_closed_loop_rejects_non_finite_targets(monkeypatch) -> None:
    sim = ClosedLoopSimulation(PARAMS, load_controller_config(gain_set="simulation"))
    real_step = sim.controller.step

    def bad_step(t, R, omega):
        out = real_step(t, R, omega)
        out.joint_targets[2, 1] = math.nan
        return out

    monkeypatch.setattr(sim.controller, "step", bad_step)
    with pytest.raises(SimulationError):
        sim.step()


def test_closed_loop_counts_out_of_range_targets(monkeypatch) -> None:
    sim = ClosedLoopSimulation(PARAMS, load_controller_config(gain_set="simulation"))
    real_step = sim.controller.step
    high = sim.plant._high

    def wide_step(t, R, omega):
        out = real_step(t, R, omega)
        out.joint_targets[0, 0] = high[0, 0] + 0.01
        return out

    monkeypatch.setattr(sim.controller, "step", wide_step)
    sim.step()
    assert sim.plant.clamped_joints == 1
    assert sim.plant.joint_positions[0, 0] == high[0, 0]


# ------------------------------------------------------------------ controller output

def test_controller_output_arrays_match_the_stroke_state() -> None:
    controller = AttitudeController(PARAMS, load_controller_config(gain_set="simulation"))
    controller.set_setpoint(rpy_to_rot(0.4, -0.2, 0.3))
    for k in range(60):
        out = controller.step(0.01 * k, np.eye(3), np.array([0.1, 0.0, -0.1]))
    stroke = controller.stroke
    np.testing.assert_array_equal(out.joint_targets, np.array(stroke.joints))
    np.testing.assert_array_equal(out.state.foot_targets, np.array(stroke.positions))
    np.testing.assert_array_equal(out.state.foot_velocity_commands, np.array(stroke.velocity_commands))
    np.testing.assert_array_equal(out.state.integral, np.array(controller._integral))
    # Fields do not overlap: writing one leaves the others as they were.
    before = out.state.tau_sat.copy(), out.state.foot_targets.copy()
    out.joint_targets[:] = 0.0
    out.state.e_R[:] = 9.0
    np.testing.assert_array_equal(out.state.tau_sat, before[0])
    np.testing.assert_array_equal(out.state.foot_targets, before[1])


# ------------------------------------------------------------------ whole loop

def test_step_context_from_flat_equals_rows_constructor() -> None:
    from quadruped_control.model.kinematics import leg_kinematics, leg_kinematics_flat
    from quadruped_control.sim.plants.paper import _StepContext
    rng = np.random.default_rng(3)
    q, q_dot = (Q0 + rng.uniform(-0.2, 0.2, (4, 3))).tolist(), rng.uniform(-3.0, 3.0, (4, 3)).tolist()
    restoring = tuple(rng.normal(size=9).tolist())
    a = _StepContext(leg_kinematics(q, q_dot, PARAMS), 0.37, restoring)
    b = _StepContext.from_flat(leg_kinematics_flat(q, q_dot, PARAMS), 0.37, restoring)
    assert a.feet == b.feet and a.up_torque == b.up_torque and a.flat == b.flat
    with pytest.raises(ValueError):
        leg_kinematics(q[:3], q_dot[:3], PARAMS)


def test_closed_loop_equals_reference_components_bit_for_bit() -> None:
    """The simulator (float IK, float hold input, held-input RK4, single-buffer outputs) reproduces a loop
    built from the reference pieces: kinematics.joint_angles, held_joint_input, LegInput and _rk4."""
    config = load_controller_config(gain_set="simulation")
    R_d = rpy_to_rot(*np.radians([45.0, 45.0, 45.0]))
    sim = ClosedLoopSimulation(PARAMS, config, IdealServo(), np.eye(3), R_d)
    result = sim.run(3.0)

    controller = AttitudeController(PARAMS, config)
    controller.set_setpoint(R_d)
    stroke = controller.stroke
    stroke._ik_raw = lambda point, leg: tuple(joint_angles_full(point, leg, PARAMS)[:3].tolist())
    stroke._ik_injected = True
    model = FloatingBaseModel(PARAMS)
    state, q = RigidBodyState(), Q0.copy()
    limits = PARAMS.joint_limits.as_array()
    low, high = np.tile(limits[:, 0], (4, 1)), np.tile(limits[:, 1], (4, 1))
    for k in range(result.t.size):
        np.testing.assert_allclose(result.rotation[k], state.rotation, rtol=0, atol=1e-10)
        np.testing.assert_allclose(result.omega[k], state.omega, rtol=0, atol=1e-10)
        out = controller.step(k * sim.dt, state.rotation, state.omega)
        np.testing.assert_array_equal(result.joint_targets[k], out.joint_targets.reshape(12))
        q_end = np.clip(out.joint_targets, low, high)
        context = model._context(model.leg_input(*held_joint_input(q, q_end, sim.dt)))
        state = model._rk4(state, sim.dt, (context, context, context))
        q = q_end


# ------------------------------------------------------------------ servo model

@settings(max_examples=100)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from([0.0, 1e-12, 0.001, 0.03, 0.2]),
       st.sampled_from([0.001, 0.05, 0.5, 3.0]), st.sampled_from([(4, 3), (12,)]))
def test_rate_limited_float_step_equals_array_formulas(seed, tau, spread, shape) -> None:
    rng = np.random.default_rng(seed)
    servo = RateLimitedServo(ServoParams(float(rng.uniform(1.0, 20.0)), tau))
    q = rng.uniform(-3.0, 3.0, shape)
    command = q + rng.normal(scale=spread, size=shape)
    command.reshape(-1)[0] = q.reshape(-1)[0]  # one joint exactly at its command
    dt = float(rng.choice([0.001, 0.01, 0.05]))
    fast = servo._advance(q, command, dt)
    assert fast.shape == shape
    np.testing.assert_allclose(fast, servo._advance_array(q, command, dt), rtol=1e-15, atol=1e-15)
    assert fast.reshape(-1)[0] == q.reshape(-1)[0]
