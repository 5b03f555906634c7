"""Tests of quadruped_control.sim.plants.paper: floating-base model eq. (trans), (rot) and its RK4 integrator."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.robot import LEGS
from quadruped_common.so3 import exp_so3, geodesic_angle, hat, rot_to_rpy, rpy_to_rot
from quadruped_control.model import hydrodynamics as hd
from quadruped_control.model.kinematics import UnreachableError, foot_jacobian, foot_position, joint_angles
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.paper import (DynamicsError, FloatingBaseModel, RigidBodyState, held_joint_input,
                                                joint_velocity)
from quadruped_control.sim.plants.rigid_body import as_mat3

PARAMS = load_robot_params()
#: Paws with zero net buoyancy: no conservative force, so kinetic energy alone can only decrease.
NEUTRAL_PAWS = dataclasses.replace(PARAMS, paw_mass=PARAMS.rho * PARAMS.paw_volume)
DT = 0.01  # paper, section "Simulation Validation"

Q_NOMINAL = np.array([joint_angles(PARAMS.nominal_foot_body(leg), leg, PARAMS) for leg in LEGS])
STILL = np.zeros((4, 3))

# A smooth leg motion: every joint oscillates at 1 Hz around the nominal pose (seeded phases).
_rng = np.random.default_rng(11)
AMPLITUDE = _rng.uniform(0.05, 0.25, (4, 3))
PHASE = _rng.uniform(0.0, 2.0 * math.pi, (4, 3))
OMEGA_LEGS = 2.0 * math.pi


def joint_trajectory(t):
    angle = OMEGA_LEGS * t + PHASE
    return Q_NOMINAL + AMPLITUDE * np.sin(angle), AMPLITUDE * OMEGA_LEGS * np.cos(angle)


def tilted_state(omega=(0.3, -0.2, 0.4), velocity=(0.0, 0.0, 0.0)):
    return RigidBodyState(velocity=np.array(velocity, dtype=float), rotation=rpy_to_rot(0.2, -0.1, 0.5),
                          omega=np.array(omega, dtype=float))


def state_error(a, b):
    return float(np.max(np.abs(a.to_vector() - b.to_vector())))


# --------------------------------------------------------------------------------------------------
# Right-hand side
# --------------------------------------------------------------------------------------------------

def test_legs_still_body_at_rest_gives_zero_leg_wrench():
    model = FloatingBaseModel(PARAMS)
    wrench = model.wrench(RigidBodyState(rotation=rpy_to_rot(0.3, 0.2, -0.4)), Q_NOMINAL, STILL)
    assert np.all(wrench.foot_velocities_world == 0.0)
    assert np.all(wrench.leg_forces_world == 0.0)
    assert np.all(wrench.leg_torques_body == 0.0)
    assert np.all(wrench.drag_force_body == 0.0) and np.all(wrench.drag_torque_body == 0.0)


def test_upright_at_rest_only_paw_buoyancy_force_acts():
    model = FloatingBaseModel(PARAMS)
    derivative = model.derivative(RigidBodyState(), Q_NOMINAL, STILL)
    np.testing.assert_allclose(derivative.omega_dot, 0.0, atol=1e-15)
    np.testing.assert_allclose(derivative.velocity_dot, [0.0, 0.0, 4.0 * PARAMS.paw_net_buoyancy / PARAMS.mass],
                               rtol=1e-14)
    assert np.all(derivative.rotation_dot == 0.0)


def reference_accelerations(params, state, q, q_dot):
    """eq. (ee_vel), (fb_jac), (force_leg), (torque_leg), (buoy_torque), (drag_total), (trans), (rot),
    assembled directly from the kinematics and hydrodynamics functions, leg by leg."""
    R, v, w = state.rotation, state.velocity, state.omega
    force = np.zeros(3)
    torque = np.zeros(3)
    feet = []
    for row, leg in enumerate(LEGS):
        r = foot_position(q[row], leg, params)
        feet.append(r)
        v_foot = v - R @ hat(r) @ w + R @ foot_jacobian(q[row], leg, params) @ q_dot[row]
        f_leg, t_leg = hd.leg_wrench(v_foot, r, R, params)
        force += f_leg
        torque += t_leg
    f_buoy, t_buoy = hd.paw_buoyancy(np.array(feet), R, params)
    f_drag, t_drag = hd.body_drag(R.T @ v, w, params)
    force += f_buoy + R @ f_drag
    torque += t_buoy + t_drag
    inertia = params.inertia
    return force / params.mass, np.linalg.solve(inertia, torque - np.cross(w, inertia @ w))


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=0, max_value=2 ** 32 - 1))
def test_fast_derivative_matches_reference_assembly(seed):
    rng = np.random.default_rng(seed)
    state = RigidBodyState(position=rng.normal(size=3), velocity=rng.uniform(-0.5, 0.5, 3),
                           rotation=exp_so3(rng.uniform(-2.0, 2.0, 3)), omega=rng.uniform(-2.0, 2.0, 3))
    q = Q_NOMINAL + rng.uniform(-0.2, 0.2, (4, 3))
    q_dot = rng.uniform(-3.0, 3.0, (4, 3))
    model = FloatingBaseModel(PARAMS)
    derivative = model.derivative(state, q, q_dot)
    v_dot, omega_dot = reference_accelerations(PARAMS, state, q, q_dot)
    np.testing.assert_allclose(derivative.velocity_dot, v_dot, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(derivative.omega_dot, omega_dot, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(derivative.rotation_dot, state.rotation @ hat(state.omega), rtol=1e-15)
    np.testing.assert_array_equal(derivative.position_dot, state.velocity)
    # The telemetry breakdown adds up to the same right-hand side.
    wrench = model.wrench(state, q, q_dot)
    np.testing.assert_allclose(wrench.total_force_world / PARAMS.mass, v_dot, rtol=1e-10, atol=1e-13)
    inertia = PARAMS.inertia
    np.testing.assert_allclose(
        np.linalg.solve(inertia, wrench.total_torque_body - np.cross(state.omega, inertia @ state.omega)),
        omega_dot, rtol=1e-10, atol=1e-13)


def test_power_stroke_torque_direction():
    """Front-right leg 4 sweeps its paw backward: the water pushes the paw forward, F = +x, and the
    torque r x F (r = foot below and to the right of the CoM) pitches the nose up and yaws left."""
    model = FloatingBaseModel(PARAMS)
    foot_speed = 0.5
    q_dot = np.zeros((4, 3))
    leg_row = 3
    q_dot[leg_row] = np.linalg.solve(foot_jacobian(Q_NOMINAL[leg_row], 4, PARAMS), [-foot_speed, 0.0, 0.0])
    wrench = model.wrench(RigidBodyState(), Q_NOMINAL, q_dot)
    r = PARAMS.nominal_foot_body(4)
    expected_force = np.array([PARAMS.drag_constant * foot_speed ** 2, 0.0, 0.0])
    np.testing.assert_allclose(wrench.leg_forces_world[leg_row], expected_force, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(wrench.leg_torques_body[leg_row], np.cross(r, expected_force), rtol=1e-12, atol=1e-15)
    assert np.all(wrench.leg_torques_body[:3] == 0.0)
    torque = wrench.leg_torques_body[leg_row]
    assert torque[1] < 0.0 and torque[2] > 0.0  # r_z < 0: nose up (-y); r_y < 0: yaw left (+z)
    # Integrated, the body turns the same way.
    state = RigidBodyState()
    for _ in range(20):
        state = model.step(state, Q_NOMINAL, q_dot, DT)
    assert state.omega[1] < 0.0 and state.omega[2] > 0.0
    roll, pitch, yaw = rot_to_rpy(state.rotation)
    assert pitch < 0.0 and yaw > 0.0


# --------------------------------------------------------------------------------------------------
# Dissipation and energy
# --------------------------------------------------------------------------------------------------

def test_spin_about_principal_axis_slows_down():
    model = FloatingBaseModel(PARAMS)
    state = RigidBodyState(omega=np.array([0.0, 0.0, 2.0]))
    rates = []
    for _ in range(300):
        state = model.step(state, Q_NOMINAL, STILL, DT)
        rates.append(float(np.linalg.norm(state.omega)))
    assert all(b < a for a, b in zip(rates, rates[1:]))
    assert rates[-1] < 0.5 * 2.0
    np.testing.assert_allclose(state.omega[:2], 0.0, atol=1e-12)  # stays about z


def test_kinetic_energy_never_grows_with_legs_still():
    model = FloatingBaseModel(NEUTRAL_PAWS)
    state = tilted_state(omega=(1.5, -1.0, 2.0), velocity=(0.3, -0.2, 0.1))
    energies = [model.kinetic_energy(state)]
    for _ in range(500):
        state = model.step(state, Q_NOMINAL, STILL, DT)
        energies.append(model.kinetic_energy(state))
    assert all(b <= a * (1.0 + 1e-12) for a, b in zip(energies, energies[1:]))
    assert energies[-1] < 0.2 * energies[0]


@pytest.mark.parametrize("restoring_offset", [None, (0.0, 0.0, 0.01), (0.005, -0.01, -0.01)])
def test_mechanical_energy_never_grows_with_legs_still(restoring_offset):
    """With paw buoyancy (and an optional centre-of-buoyancy offset) the torques do work as the body
    turns; kinetic + potential energy is still non-increasing."""
    model = FloatingBaseModel(PARAMS, restoring_offset=restoring_offset)
    state = tilted_state(omega=(1.0, -0.8, 0.5), velocity=(0.2, 0.1, -0.1))
    energies = [model.kinetic_energy(state) + model.potential_energy(state, Q_NOMINAL)]
    for _ in range(500):
        state = model.step(state, Q_NOMINAL, STILL, DT)
        energies.append(model.kinetic_energy(state) + model.potential_energy(state, Q_NOMINAL))
    scale = abs(energies[0]) + model.kinetic_energy(tilted_state(omega=(1.0, -0.8, 0.5)))
    assert all(b <= a + 1e-12 * scale for a, b in zip(energies, energies[1:]))
    assert energies[-1] < energies[0]


def test_centre_of_buoyancy_above_com_rights_the_body():
    model = FloatingBaseModel(NEUTRAL_PAWS, restoring_offset=(0.0, 0.0, 0.01))
    state = RigidBodyState(rotation=rpy_to_rot(0.4, -0.3, 0.2))
    start = geodesic_angle(np.eye(3), rpy_to_rot(0.4, -0.3, 0.0))
    for _ in range(3000):
        state = model.step(state, Q_NOMINAL, STILL, DT)
    roll, pitch, _ = rot_to_rpy(state.rotation)
    assert math.hypot(roll, pitch) < 0.1 * start


def test_centre_of_buoyancy_below_com_capsizes_the_body():
    model = FloatingBaseModel(NEUTRAL_PAWS, restoring_offset=(0.0, 0.0, -0.01))
    state = RigidBodyState(rotation=rpy_to_rot(0.02, 0.0, 0.0))
    for _ in range(1000):
        state = model.step(state, Q_NOMINAL, STILL, DT)
    roll, pitch, _ = rot_to_rpy(state.rotation)
    assert math.hypot(roll, pitch) > 0.5


def test_restoring_torque_formula():
    model = FloatingBaseModel(NEUTRAL_PAWS, restoring_offset=(0.01, -0.02, 0.03), restoring_force=40.0)
    R = rpy_to_rot(0.3, 0.2, -1.0)
    wrench = model.wrench(RigidBodyState(rotation=R), Q_NOMINAL, STILL)
    np.testing.assert_allclose(wrench.restoring_torque_body,
                               np.cross([0.01, -0.02, 0.03], R.T @ [0.0, 0.0, 40.0]), rtol=1e-13)
    default = FloatingBaseModel(PARAMS, restoring_offset=(0.0, 0.0, 0.01))
    assert default.restoring_force == pytest.approx(PARAMS.mass * PARAMS.gravity)
    assert np.all(FloatingBaseModel(PARAMS).wrench(RigidBodyState(rotation=R), Q_NOMINAL, STILL)
                  .restoring_torque_body == 0.0)


# --------------------------------------------------------------------------------------------------
# Integrator accuracy
# --------------------------------------------------------------------------------------------------

DURATION = 2.0


def run_continuous(model, dt):
    state = tilted_state()
    for k in range(int(round(DURATION / dt))):
        state = model.step_continuous(state, k * dt, dt, joint_trajectory)
    return state


def run_held(model, dt):
    """The simulator's way: commands q_k = q(t_k) at each step, held midpoint and finite differences."""
    state = tilted_state()
    q_previous = joint_trajectory(0.0)[0]
    for k in range(int(round(DURATION / dt))):
        q_next = joint_trajectory((k + 1) * dt)[0]
        q_hold, q_dot = held_joint_input(q_previous, q_next, dt)
        state = model.step(state, q_hold, q_dot, dt)
        q_previous = q_next
    return state


@pytest.fixture(scope="module")
def reference_solution():
    return run_continuous(FloatingBaseModel(PARAMS), 0.0005)


def test_rk4_converges_with_fourth_order(reference_solution):
    """RK4 with the smooth joint motion sampled at the stage times: dt = 0.01 s matches dt = 0.0005 s
    to 1e-8 over 2 s (leg motion turns the body by ~20 degrees). The drag laws |v| v are only C^1 at
    zero velocity components, which caps the observed order; between dt = 0.04 s and 0.02 s the
    error still drops by more than 10 (fourth order gives 16)."""
    model = FloatingBaseModel(PARAMS)
    assert geodesic_angle(reference_solution.rotation, tilted_state().rotation) > math.radians(10.0)
    errors = {dt: state_error(run_continuous(model, dt), reference_solution) for dt in (0.04, 0.02, 0.01)}
    assert errors[0.01] < 1e-8
    assert errors[0.04] / errors[0.02] > 10.0


def test_held_command_at_paper_step_matches_reference(reference_solution):
    """The zero-order hold of the commands at dt = 0.01 s (held midpoint, finite-difference q_dot)
    tracks the continuous leg motion within 0.005 degrees and 5e-5 rad/s after 2 s, second order."""
    model = FloatingBaseModel(PARAMS)
    coarse = run_held(model, 0.02)
    fine = run_held(model, DT)
    angle = math.degrees(geodesic_angle(fine.rotation, reference_solution.rotation))
    assert angle < 0.005
    assert np.max(np.abs(fine.omega - reference_solution.omega)) < 5e-5
    ratio = state_error(coarse, reference_solution) / state_error(fine, reference_solution)
    assert 3.0 < ratio < 5.0


def test_rotation_stays_in_so3_over_ten_thousand_steps():
    model = FloatingBaseModel(PARAMS)
    state = tilted_state(omega=(3.0, -2.0, 4.0))
    worst = 0.0
    for k in range(10000):
        q, q_dot = joint_trajectory(k * DT)
        state = model.step(state, q, q_dot, DT)
        if k % 100 == 0:
            state.omega = state.omega + np.array([1.0, -1.0, 1.5])  # keep it tumbling against the drag
        R = state.rotation
        worst = max(worst, float(np.max(np.abs(R.T @ R - np.eye(3)))))
    assert worst < 1e-12
    assert np.linalg.det(state.rotation) == pytest.approx(1.0, abs=1e-12)


def test_step_does_not_modify_its_input():
    model = FloatingBaseModel(PARAMS)
    state = tilted_state()
    before = state.to_vector().copy()
    model.step(state, Q_NOMINAL, STILL, DT)
    np.testing.assert_array_equal(state.to_vector(), before)


# --------------------------------------------------------------------------------------------------
# Inputs and bad input
# --------------------------------------------------------------------------------------------------

def test_joint_velocity_and_held_input():
    q0 = Q_NOMINAL
    q1 = Q_NOMINAL + 0.01
    np.testing.assert_allclose(joint_velocity(q0, q1, 0.01), np.ones((4, 3)), rtol=1e-12)
    q_hold, q_dot = held_joint_input(q0.reshape(12), q1.reshape(12), 0.02)
    np.testing.assert_allclose(q_hold, Q_NOMINAL + 0.005, rtol=1e-15)
    np.testing.assert_allclose(q_dot, 0.5 * np.ones((4, 3)), rtol=1e-12)
    with pytest.raises(ValueError, match="dt"):
        joint_velocity(q0, q1, 0.0)
    with pytest.raises(ValueError, match="non-finite"):
        joint_velocity(q0, np.full((4, 3), np.nan), 0.01)
    with pytest.raises(ValueError, match="shape"):
        joint_velocity(q0, np.zeros((3, 3)), 0.01)


def test_state_vector_round_trip_and_validation():
    state = tilted_state(velocity=(0.1, 0.2, 0.3))
    again = RigidBodyState.from_vector(state.to_vector())
    np.testing.assert_array_equal(again.to_vector(), state.to_vector())
    copy = state.copy()
    copy.omega[0] = 99.0
    assert state.omega[0] != 99.0
    with pytest.raises(ValueError, match="SO\\(3\\)"):
        RigidBodyState(rotation=2.0 * np.eye(3)).validate()
    with pytest.raises(ValueError, match="SO\\(3\\)"):
        RigidBodyState(rotation=np.diag([1.0, 1.0, -1.0])).validate()  # reflection
    with pytest.raises(ValueError, match="non-finite"):
        RigidBodyState(omega=np.array([0.0, np.nan, 0.0])).validate()
    with pytest.raises(ValueError, match="18"):
        RigidBodyState.from_vector(np.zeros(17))


def test_step_rejects_bad_input_and_leaves_state_untouched():
    model = FloatingBaseModel(PARAMS)
    state = tilted_state()
    before = state.to_vector().copy()
    bad_q = Q_NOMINAL.copy()
    bad_q[2, 1] = np.inf
    with pytest.raises(ValueError, match="q has non-finite"):
        model.step(state, bad_q, STILL, DT)
    with pytest.raises(ValueError, match="shape"):
        model.step(state, Q_NOMINAL[:3], STILL, DT)
    with pytest.raises(ValueError, match="dt"):
        model.step(state, Q_NOMINAL, STILL, -0.01)
    with pytest.raises(ValueError, match="dt"):
        model.step(state, Q_NOMINAL, STILL, float("nan"))
    unassemblable = Q_NOMINAL.copy()
    # Elbows coincide (a1 cos t1 = c + a1 cos t2, sin t1 = sin t2): the foot is undefined.
    elbow = math.acos(0.5 * PARAMS.five_bar.c / PARAMS.five_bar.a1)
    unassemblable[0, :2] = (elbow, math.pi - elbow)
    with pytest.raises(UnreachableError):
        model.step(state, unassemblable, STILL, DT)
    np.testing.assert_array_equal(state.to_vector(), before)


def test_divergence_raises_dynamics_error():
    model = FloatingBaseModel(PARAMS)
    exploding = RigidBodyState(velocity=np.array([1e200, 0.0, 0.0]), omega=np.array([1e200, 1e200, 0.0]))
    with pytest.raises(DynamicsError, match="diverged"):
        model.step(exploding, Q_NOMINAL, STILL, DT)


def test_restoring_parameters_validated():
    with pytest.raises(ValueError, match="restoring_offset"):
        FloatingBaseModel(PARAMS, restoring_force=10.0)
    with pytest.raises(ValueError, match="restoring_force"):
        FloatingBaseModel(PARAMS, restoring_offset=(0.0, 0.0, 0.01), restoring_force=-1.0)
    with pytest.raises(ValueError, match="non-finite"):
        FloatingBaseModel(PARAMS, restoring_offset=(0.0, float("nan"), 0.01))


# --------------------------------------------------------------------------------------------------
# The integrator's fast path (stages on floats, held-input RK4) against the readable forms
# --------------------------------------------------------------------------------------------------

def reference_chart_rate(xi, omega):
    """d xi/dt for R = R0 exp(hat(xi)), R^T dR/dt = hat(omega), from the right Jacobian of SO(3):
    omega = J_r(xi) d xi/dt with J_r = I - (1 - cos t)/t^2 hat(xi) + (t - sin t)/t^3 hat(xi)^2, t = |xi|
    (Taylor series of both coefficients below t = 1e-3)."""
    t = float(np.linalg.norm(xi))
    if t < 1e-3:
        a, b = 0.5 - t * t / 24.0, 1.0 / 6.0 - t * t / 120.0
    else:
        a, b = (1.0 - math.cos(t)) / t ** 2, (t - math.sin(t)) / t ** 3
    X = hat(xi)
    return np.linalg.solve(np.eye(3) - a * X + b * X @ X, omega)


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from(["zero", "small", "large"]))
def test_stage_equals_reference_chart_derivative(seed, xi_kind):
    """The integrator's stage (the chart derivative on floats) against the same derivative assembled
    from the readable pieces: so3.exp_so3, the telemetry wrench (readable hydrodynamics functions and the
    restoring torque), eq. (trans), (rot) solved with numpy, and the right Jacobian of SO(3)."""
    rng = np.random.default_rng(seed)
    model = FloatingBaseModel(PARAMS, restoring_offset=rng.uniform(-0.02, 0.02, 3))
    q, q_dot = Q_NOMINAL + rng.uniform(-0.2, 0.2, (4, 3)), rng.uniform(-3.0, 3.0, (4, 3))
    context = model._context_from_joints(q, q_dot)
    R0 = exp_so3(rng.uniform(-2.0, 2.0, 3))
    y = (rng.normal(size=12) * [1, 1, 1, 0.5, 0.5, 0.5, 1, 1, 1, 2, 2, 2]).tolist()
    y[6:9] = {"zero": [0.0, 0.0, 0.0], "small": [1e-6, -2e-6, 0.0], "large": y[6:9]}[xi_kind]
    v, xi, omega = np.array(y[3:6]), np.array(y[6:9]), np.array(y[9:12])
    state = RigidBodyState(velocity=v, rotation=R0 @ exp_so3(xi), omega=omega)
    wrench = model.wrench(state, q, q_dot)
    inertia = PARAMS.inertia
    reference = np.concatenate((wrench.total_force_world / PARAMS.mass, reference_chart_rate(xi, omega),
                                np.linalg.solve(inertia, wrench.total_torque_body - np.cross(omega, inertia @ omega))))
    fast = model._stage(context, as_mat3(R0), *y[3:12])
    np.testing.assert_allclose(fast, reference, rtol=1e-12, atol=1e-13)
    assert model._chart_derivative(context, as_mat3(R0), y) == tuple(y[3:6]) + fast


def _random_state(rng: np.random.Generator) -> RigidBodyState:
    return RigidBodyState(rng.normal(size=3), 0.3 * rng.normal(size=3), exp_so3(rng.uniform(-2.0, 2.0, 3)),
                          rng.normal(size=3))


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1), st.booleans())
def test_rk4_held_equals_reference_rk4(seed, restoring):
    rng = np.random.default_rng(seed)
    model = FloatingBaseModel(PARAMS, restoring_offset=rng.uniform(-0.02, 0.02, 3) if restoring else None)
    context = model._context_from_joints(Q_NOMINAL + rng.uniform(-0.2, 0.2, (4, 3)), rng.uniform(-3.0, 3.0, (4, 3)))
    state = _random_state(rng)
    dt = float(rng.choice([0.001, 0.01, 0.05]))
    reference = model._rk4(state, dt, (context, context, context)).to_vector()
    fast = model._rk4_held(state, dt, context)
    np.testing.assert_allclose(fast.to_vector(), reference, rtol=1e-12, atol=1e-15)
    assert fast.rotation.shape == (3, 3) and fast.position.shape == fast.omega.shape == (3,)


def test_rk4_held_from_rest_keeps_state_and_state_fields_are_independent():
    model = FloatingBaseModel(PARAMS)
    context = model._context_from_joints(Q_NOMINAL, np.zeros((4, 3)))
    state = model._rk4_held(RigidBodyState(), 0.01, context)
    np.testing.assert_allclose(state.to_vector(),
                               model._rk4(RigidBodyState(), 0.01, (context,) * 3).to_vector(), atol=1e-15)
    before = state.to_vector()
    state.position += 1.0  # the fields share one buffer but do not overlap
    np.testing.assert_array_equal(state.to_vector()[3:], before[3:])


def test_rk4_held_raises_dynamics_error_when_diverging():
    model = FloatingBaseModel(PARAMS)
    context = model._context_from_joints(Q_NOMINAL, np.zeros((4, 3)))
    state = RigidBodyState(velocity=np.array([1e200, 0.0, 0.0]))
    with pytest.raises(DynamicsError):
        model._rk4_held(state, 0.01, context)


def test_step_trusted_equals_step():
    model = FloatingBaseModel(PARAMS)
    state = RigidBodyState(rotation=exp_so3([0.3, -0.2, 0.5]), omega=np.array([0.2, 0.1, -0.3]))
    q_dot = np.full((4, 3), 0.7)
    a = model.step(state, Q_NOMINAL, q_dot, 0.01)
    b = model.step_trusted(state, Q_NOMINAL, q_dot, 0.01)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())


def test_step_trusted_accepts_nested_lists():
    model = FloatingBaseModel(PARAMS)
    state = RigidBodyState(rotation=exp_so3([0.3, -0.2, 0.5]), omega=np.array([0.2, 0.1, -0.3]))
    q_dot = np.full((4, 3), 0.7)
    a = model.step(state, Q_NOMINAL, q_dot, 0.01)
    b = model.step_trusted(state, Q_NOMINAL.tolist(), q_dot.tolist(), 0.01)
    np.testing.assert_array_equal(a.to_vector(), b.to_vector())
