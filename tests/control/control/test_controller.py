"""Tests of quadruped_control.control.controller: eq. (error), (pid), (sat), allocation, stroke cycle, hold."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.config import ParameterError
from quadruped_common.robot import LEGS
from quadruped_common.so3 import attitude_error, exp_so3, geodesic_angle, rot_x, rpy_to_rot
from quadruped_control.control.allocation import foot_velocity_command
from quadruped_control.control.controller import (AttitudeController, ControllerOutput, control_torque,
                                          estimate_body_torque, saturate)
from quadruped_control.control.controller_config import ControllerConfig, Gains, load_controller_config
from quadruped_control.model import hydrodynamics as hd
from quadruped_control.model.kinematics import joint_angles, within_limits
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState, held_joint_input

PARAMS = load_robot_params()
DT = 0.01
GAINS = Gains(k_p=5.0, k_i=0.15, k_d=1.0, k_aw=0.25)
NOMINAL_FEET = np.array([PARAMS.nominal_foot_body(leg) for leg in LEGS])
NOMINAL_Q = np.array([joint_angles(r, leg, PARAMS) for leg, r in zip(LEGS, NOMINAL_FEET)])


def plain_config(**changes):
    """Paper gains without feedforward terms: tau_cmd = -Kp e - Ki z - Kd omega."""
    base = dict(gains=GAINS, gyroscopic_feedforward=False, buoyancy_feedforward=False)
    base.update(changes)
    return ControllerConfig(**base)


def controller(**changes):
    return AttitudeController(PARAMS, plain_config(**changes))


# --------------------------------------------------------------------------------------------------
# Control law, saturation, anti-windup
# --------------------------------------------------------------------------------------------------

def test_first_step_pid_by_hand():
    ctl = controller()
    angle = math.radians(10.0)
    omega = np.array([0.1, -0.2, 0.05])
    out = ctl.step(0.0, rot_x(angle), omega)
    s = out.state
    e = np.array([math.sin(angle), 0.0, 0.0])          # eq. (error): sin(a) n for R = R_d exp(a n)
    np.testing.assert_allclose(s.e_R, e, atol=1e-16)
    assert s.geodesic_error == pytest.approx(angle, rel=1e-14)
    z = DT * e                                          # first step integrates over dt
    np.testing.assert_allclose(s.integral, z, atol=1e-17)
    expected = -5.0 * e - 0.15 * z - 1.0 * omega
    np.testing.assert_allclose(s.tau_cmd, expected, rtol=1e-14)
    np.testing.assert_allclose(s.tau_sat, expected, rtol=1e-14)   # |tau| < 2 N m
    assert not s.saturated
    assert s.dt == DT and s.t == 0.0
    np.testing.assert_allclose(control_torque(e, omega, z, GAINS), expected, rtol=1e-14)


def test_second_step_integrates_elapsed_time_and_setpoint_error():
    ctl = controller()
    ctl.set_setpoint_rpy(0.0, 0.2, 0.0)
    R1, R2 = rpy_to_rot(0.1, 0.0, 0.0), rpy_to_rot(0.12, 0.05, 0.0)
    s1 = ctl.step(5.0, R1, np.zeros(3)).state
    s2 = ctl.step(5.013, R2, np.zeros(3)).state
    e1, e2 = attitude_error(rpy_to_rot(0.0, 0.2, 0.0), R1), attitude_error(rpy_to_rot(0.0, 0.2, 0.0), R2)
    np.testing.assert_allclose(s1.e_R, e1, atol=1e-15)
    np.testing.assert_allclose(s2.integral, DT * e1 + 0.013 * e2, atol=1e-15)
    assert s2.dt == pytest.approx(0.013)
    assert s2.geodesic_error == pytest.approx(geodesic_angle(rpy_to_rot(0.0, 0.2, 0.0), R2), abs=1e-14)
    np.testing.assert_allclose(s2.R_d, rpy_to_rot(0.0, 0.2, 0.0))
    np.testing.assert_array_equal(s2.setpoint, s2.R_d)


def test_irregular_time_steps_are_clipped():
    ctl = controller()
    R = rot_x(0.3)
    e = attitude_error(np.eye(3), R)
    ctl.step(1.0, R, np.zeros(3))
    z = ctl.step(3.0, R, np.zeros(3)).state.integral          # 2 s gap: clipped to 5 dt
    np.testing.assert_allclose(z, (DT + 5 * DT) * e, atol=1e-15)
    z2 = ctl.step(2.0, R, np.zeros(3)).state                  # time going backwards: nothing integrated
    assert z2.dt == 0.0
    np.testing.assert_allclose(z2.integral, z, atol=0.0)


def test_saturation_keeps_direction_and_limits_magnitude():
    tau, saturated = saturate([3.0, -4.0, 0.0], 2.0)
    np.testing.assert_allclose(tau, [1.2, -1.6, 0.0])
    assert saturated
    tau, saturated = saturate([0.3, 0.4, 0.0], 2.0)
    np.testing.assert_allclose(tau, [0.3, 0.4, 0.0]) and not saturated
    tau, saturated = saturate([0.0, 0.0, 0.0], 0.0)
    assert np.all(tau == 0.0) and not saturated


def test_saturated_step_and_anti_windup_term_by_hand():
    """g = h K_aw K_i <= 1 (every configured gain set at 100 Hz): the anti-windup term uses the excess of
    the torque commanded over the interval that just ended (controller docstring, forward form)."""
    ctl = controller()
    angle = math.radians(60.0)
    R = rot_x(angle)
    e = np.array([math.sin(angle), 0.0, 0.0])
    s1 = ctl.step(0.0, R, np.zeros(3)).state
    tau1 = s1.tau_cmd
    assert s1.saturated
    np.testing.assert_allclose(s1.tau_sat, 2.0 * tau1 / np.linalg.norm(tau1), rtol=1e-14)
    assert np.linalg.norm(s1.tau_sat) == pytest.approx(2.0)
    # First step: no torque was commanded before, z_1 = dt e; tau_cmd,1 = -K_p e - K_i z_1.
    np.testing.assert_allclose(s1.integral, DT * e, rtol=1e-13)
    np.testing.assert_allclose(s1.tau_cmd, -5.0 * e - 0.15 * s1.integral, rtol=1e-14)
    s2 = ctl.step(DT, R, np.zeros(3)).state
    # z_2 = z_1 + dt (e + K_aw Delta_sat,1), eq. (pid) with the excess of step 1's command.
    np.testing.assert_allclose(s2.integral, s1.integral + DT * (e + 0.25 * (s1.tau_cmd - s1.tau_sat)), rtol=1e-13)


def test_backward_euler_anti_windup_by_hand_when_the_loop_gain_of_a_step_exceeds_one():
    """g = h K_aw K_i > 1: backward Euler with the excess of this step's own command, in closed form."""
    gains = Gains(k_p=5.0, k_i=20.0, k_d=0.0, k_aw=10.0)   # g = 0.01 * 10 * 20 = 2
    ctl = AttitudeController(PARAMS, plain_config(gains=gains))
    angle = math.radians(60.0)
    R = rot_x(angle)
    e = np.array([math.sin(angle), 0.0, 0.0])
    s1 = ctl.step(0.0, R, np.zeros(3)).state
    assert s1.saturated
    delta1 = s1.tau_cmd - s1.tau_sat
    np.testing.assert_allclose(s1.integral, DT * (e + 10.0 * delta1), rtol=1e-12)
    np.testing.assert_allclose(s1.tau_cmd, -5.0 * e - 20.0 * s1.integral, rtol=1e-12)
    # |Delta_sat| = (|u| - tau_max) / (1 + g), u the command without the excess term.
    u = -5.0 * e - 20.0 * DT * e
    assert np.linalg.norm(delta1) == pytest.approx((np.linalg.norm(u) - 2.0) / (1.0 + 2.0), rel=1e-12)
    s2 = ctl.step(DT, R, np.zeros(3)).state
    np.testing.assert_allclose(s2.integral, s1.integral + DT * (e + 10.0 * (s2.tau_cmd - s2.tau_sat)), rtol=1e-12)


def test_anti_windup_stops_the_integral_growing_under_saturation():
    """Under a sustained saturating error the integrand e + K_aw Delta_sat vanishes at a finite integral:
    z* = (tau_max + |e| / K_aw - K_p |e|) / K_i along e (the integral stops growing); without anti-windup
    (K_aw = 0) it grows linearly."""
    gains = Gains(k_p=5.0, k_i=1.0, k_d=0.0, k_aw=0.5)
    angle = math.radians(90.0)
    R = rot_x(angle)
    ctl = AttitudeController(PARAMS, plain_config(gains=gains))
    windup = AttitudeController(PARAMS, plain_config(gains=gains.replace(k_aw=0.0), integral_limit=1000.0))
    limited = AttitudeController(PARAMS, plain_config(gains=gains.replace(k_aw=0.0)))
    history = []
    for k in range(3000):
        s = ctl.step(k * DT, R, np.zeros(3)).state
        history.append(s.integral[0])
        w = windup.step(k * DT, R, np.zeros(3)).state
        bounded = limited.step(k * DT, R, np.zeros(3)).state
        assert s.saturated
    z_star = (2.0 + 1.0 / 0.5 - 5.0 * 1.0) / 1.0      # |e| = sin(90 deg) = 1
    assert history[-1] == pytest.approx(z_star, abs=1e-3)
    assert abs(history[-1] - history[-500]) < 1e-3       # stopped growing
    assert w.integral[0] == pytest.approx(30.0, rel=1e-9)  # 3000 steps of dt * 1
    assert bounded.integral[0] == pytest.approx(10.0)      # the default integral_limit


def test_paper_gains_integral_bounded_under_saturation():
    ctl = AttitudeController(PARAMS, plain_config())
    R = rot_x(math.radians(90.0))
    z = [ctl.step(k * DT, R, np.zeros(3)).state.integral[0] for k in range(4000)]
    # Without anti-windup it would reach 40; with K_aw it converges to (2 + 1/0.25 - 5) / 0.15 = 6.67.
    assert max(z) < (2.0 + 4.0 - 5.0) / 0.15 + 1e-9
    assert np.all(np.diff(z) >= 0.0) and z[-1] - z[-1000] < 0.9 * (z[1000] - z[0])


def test_integral_limit_bounds_the_norm():
    ctl = controller(integral_limit=0.05)
    for k in range(200):
        s = ctl.step(k * DT, rpy_to_rot(0.3, 0.2, 0.0), np.zeros(3)).state
    assert np.linalg.norm(s.integral) == pytest.approx(0.05)


def test_gyroscopic_and_buoyancy_feedforward():
    R = rpy_to_rot(0.4, -0.3, 0.2)
    omega = np.array([0.5, -0.7, 0.3])
    base = controller().step(0.0, R, omega).state
    gyro = AttitudeController(PARAMS, plain_config(gyroscopic_feedforward=True)).step(0.0, R, omega).state
    # (both saturate: compare without the integral term, whose anti-windup excess differs)
    def no_integral(state):
        return state.tau_cmd + GAINS.k_i * state.integral
    np.testing.assert_allclose(no_integral(gyro) - no_integral(base), np.cross(omega, PARAMS.inertia @ omega),
                               atol=1e-15)
    buoy = AttitudeController(PARAMS, plain_config(buoyancy_feedforward=True)).step(0.0, R, omega).state
    # Buoyancy torque of eq. (buoy_torque) at the foot positions commanded before the step (nominal).
    _, tau_b = hd.paw_buoyancy(NOMINAL_FEET, R, PARAMS)
    assert np.linalg.norm(tau_b) > 1e-4
    np.testing.assert_allclose(no_integral(buoy) - no_integral(base), -tau_b, atol=1e-15)
    np.testing.assert_allclose(buoy.tau_feedforward, -tau_b, atol=1e-15)
    inertia = PARAMS.inertia
    np.testing.assert_allclose(control_torque(base.e_R, omega, base.integral, GAINS, inertia, tau_b),
                               base.tau_cmd + np.cross(omega, inertia @ omega) - tau_b, atol=1e-15)


def test_buoyancy_feedforward_uses_the_current_foot_targets():
    ctl = AttitudeController(PARAMS, plain_config(buoyancy_feedforward=True))
    R = rpy_to_rot(0.5, 0.0, 0.0)
    ctl.set_setpoint(R @ rot_x(-0.3))
    for k in range(20):
        previous_feet = ctl.stroke.foot_targets()
        s = ctl.step(k * DT, R, np.zeros(3)).state
    _, tau_b = hd.paw_buoyancy(np.array(previous_feet), R, PARAMS)
    np.testing.assert_allclose(s.tau_feedforward, -tau_b, atol=1e-15)


# --------------------------------------------------------------------------------------------------
# Allocation and stroke cycle inside the controller
# --------------------------------------------------------------------------------------------------

def test_power_phase_velocity_is_latched_from_the_torque_at_its_start():
    config = plain_config(normalize_force_direction=True)
    ctl = AttitudeController(PARAMS, config)
    R = rot_x(math.radians(20.0))
    omega = np.array([0.05, 0.0, 0.0])
    out = ctl.step(0.0, R, omega)
    s = out.state
    assert s.pair_phase == ("recovery", "power")
    for leg in (2, 4):  # second pair started its power phase at this step
        expected = foot_velocity_command(s.tau_sat / 4, NOMINAL_FEET[leg - 1], omega, PARAMS.drag_constant, True)
        np.testing.assert_allclose(s.foot_velocity_commands[leg - 1], expected, rtol=1e-14)
    latched = s.foot_velocity_commands.copy()
    # A different attitude on the next step does not change the held command.
    s2 = ctl.step(DT, rot_x(math.radians(5.0)), np.zeros(3)).state
    np.testing.assert_array_equal(s2.foot_velocity_commands, latched)
    np.testing.assert_allclose(s2.foot_targets[1], NOMINAL_FEET[1] + latched[1] * DT, atol=1e-15)


def test_zero_error_gives_no_stroke_amplitude():
    ctl = AttitudeController(PARAMS, load_controller_config())  # with both feedforward terms
    for k in range(400):
        out = ctl.step(k * DT, np.eye(3), np.zeros(3))
        np.testing.assert_array_equal(out.state.foot_targets, NOMINAL_FEET)
        np.testing.assert_allclose(out.joint_targets, NOMINAL_Q, atol=1e-15)
        assert np.all(out.state.tau_sat == 0.0)


def test_stroke_phases_reported_and_cycle_alternates():
    ctl = AttitudeController(PARAMS, load_controller_config())
    phases = [ctl.step(k * DT, rot_x(0.5), np.zeros(3)).state.pair_phase for k in range(400)]
    assert phases[0] == ("recovery", "power")
    first_power = next(k for k, p in enumerate(phases) if p[0] == "power")
    assert first_power == 74  # t_rec / 2 = 0.75 s
    assert all(p[0] in ("power", "recovery") and p[1] in ("power", "recovery") for p in phases)


def test_output_types_and_shapes():
    out = AttitudeController(PARAMS, load_controller_config()).step(0.0, rot_x(0.2), np.zeros(3))
    assert isinstance(out, ControllerOutput)
    assert out.joint_targets.shape == (4, 3) and out.state.foot_targets.shape == (4, 3)
    for name in ("e_R", "tau_cmd", "tau_sat", "integral", "tau_feedforward"):
        assert getattr(out.state, name).shape == (3,)
    assert out.state.R_d.shape == (3, 3)
    assert isinstance(out.state.saturated, bool) and isinstance(out.state.holding, bool)
    assert isinstance(out.state.pair_phase, tuple) and len(out.state.pair_phase_time) == 2


# --------------------------------------------------------------------------------------------------
# Invalid input
# --------------------------------------------------------------------------------------------------

BAD_ROTATIONS = [
    np.full((3, 3), math.nan),
    np.diag([1.0, 1.0, math.inf]),
    np.diag([1.0, 1.0, -1.0]),          # reflection
    2.0 * np.eye(3),                    # not orthonormal
    np.eye(3) + 1e-4,                   # beyond the tolerance
    np.eye(2),                          # wrong shape
    np.zeros(9),
]


@pytest.mark.parametrize("R", BAD_ROTATIONS)
def test_bad_attitude_raises_and_leaves_state_unchanged(R):
    ctl = controller()
    ctl.step(0.0, rot_x(0.3), np.zeros(3))
    before = ctl.step(DT, rot_x(0.3), np.zeros(3)).state
    with pytest.raises(ValueError):
        ctl.step(2 * DT, R, np.zeros(3))
    after = ctl.step(2 * DT, rot_x(0.3), np.zeros(3)).state
    np.testing.assert_allclose(after.integral, before.integral + DT * before.e_R, rtol=1e-14)


@pytest.mark.parametrize("omega", [[math.nan, 0.0, 0.0], [0.0, -math.inf, 0.0], [0.0, 0.0], "abc"])
def test_bad_rate_raises(omega):
    with pytest.raises(ValueError):
        controller().step(0.0, np.eye(3), omega)


@pytest.mark.parametrize("t", [math.nan, math.inf, -math.inf])
def test_bad_time_raises(t):
    with pytest.raises(ValueError, match="time"):
        controller().step(t, np.eye(3), np.zeros(3))


def test_setpoint_validation():
    ctl = controller()
    for R in BAD_ROTATIONS:
        with pytest.raises(ValueError):
            ctl.set_setpoint(R)
    np.testing.assert_array_equal(ctl.setpoint, np.eye(3))
    ctl.set_setpoint_rpy(0.1, -0.2, 0.3)
    np.testing.assert_allclose(ctl.setpoint, rpy_to_rot(0.1, -0.2, 0.3))
    with pytest.raises(ValueError):
        ctl.set_setpoint_rpy(math.nan, 0.0, 0.0)


def test_live_reconfigure():
    ctl = controller()
    ctl.set_gains(Gains(10.0, 3.0, 0.5, 0.25))
    assert ctl.config.gains.k_p == 10.0
    s = ctl.step(0.0, rot_x(0.1), np.zeros(3)).state
    assert s.tau_cmd[0] == pytest.approx(-10.0 * math.sin(0.1) - 3.0 * DT * math.sin(0.1))
    with pytest.raises(ParameterError):
        ctl.set_gains((1.0, 2.0, 3.0, 4.0))
    with pytest.raises(ParameterError, match="2 t_pow_max"):
        ctl.set_timing(t_rec=0.8)
    assert ctl.config.t_rec == 1.5 and ctl.stroke.t_rec == 1.5
    ctl.set_timing(t_rec=1.0, tau_max=0.5)
    assert ctl.config.t_rec == 1.0 and ctl.stroke.t_rec == 1.0 and ctl.config.tau_max == 0.5
    s = ctl.step(DT, rot_x(0.5), np.zeros(3)).state
    assert np.linalg.norm(s.tau_sat) == pytest.approx(0.5)
    ctl.set_timing()  # nothing to change
    with pytest.raises(ParameterError, match="tau_max"):
        ctl.set_timing(tau_max=-1.0)


# --------------------------------------------------------------------------------------------------
# Hold and reset
# --------------------------------------------------------------------------------------------------

def test_hold_freezes_integral_retracts_feet_and_restarts_cleanly():
    ctl = AttitudeController(PARAMS, load_controller_config())
    R = rot_x(0.6)
    for k in range(100):
        s = ctl.step(k * DT, R, np.zeros(3)).state
    assert np.any(np.abs(s.foot_targets - NOMINAL_FEET) > 1e-3)  # mid-stroke
    frozen = s.integral.copy()
    last_e = s.e_R.copy()
    for k in range(100, 300):
        out = ctl.hold(k * DT, "imu timeout")
        assert out.state.holding and out.state.hold_reason == "imu timeout"
        assert out.state.pair_phase == ("hold", "hold")
        np.testing.assert_array_equal(out.state.integral, frozen)
        assert np.all(out.state.tau_sat == 0.0) and not out.state.saturated
        np.testing.assert_array_equal(out.state.e_R, last_e)
        assert all(within_limits(q, PARAMS, tol=0.0) for q in out.joint_targets)
    assert ctl.holding
    # Back at the nominal pose: joint targets are the IK of the nominal feet.
    np.testing.assert_array_equal(out.state.foot_targets, NOMINAL_FEET)
    np.testing.assert_allclose(out.joint_targets, NOMINAL_Q, atol=1e-15)
    # The next step restarts the cycle: first pair half recovery, reason cleared, integral resumes.
    s = ctl.step(3.0, R, np.zeros(3)).state
    assert not s.holding and s.hold_reason == ""
    assert s.pair_phase == ("recovery", "power")
    # The excess of the last command is cleared by the hold: z = z_frozen + dt e_R.
    np.testing.assert_allclose(s.integral, frozen + DT * s.e_R, rtol=1e-12)


def test_hold_never_raises_and_works_before_any_step():
    ctl = controller()
    for t in (math.nan, None, "bad", 0.0):
        out = ctl.hold(t, "startup")
        assert np.all(np.isfinite(out.joint_targets)) and math.isfinite(out.state.t)
    np.testing.assert_allclose(out.joint_targets, NOMINAL_Q, atol=1e-15)


def test_reset_clears_integral_and_stroke():
    ctl = controller()
    for k in range(60):
        ctl.step(k * DT, rot_x(0.4), np.zeros(3))
    ctl.reset()
    s = ctl.step(10.0, rot_x(0.4), np.zeros(3)).state
    np.testing.assert_allclose(s.integral, DT * s.e_R, rtol=1e-15)
    assert s.pair_phase == ("recovery", "power") and s.dt == DT


# --------------------------------------------------------------------------------------------------
# Properties and closed loop
# --------------------------------------------------------------------------------------------------

rotation_vectors = st.tuples(*[st.floats(-3.2, 3.2)] * 3).map(np.array)


@settings(max_examples=40)
@given(rotation_vectors, rotation_vectors, st.tuples(*[st.floats(-5.0, 5.0)] * 3).map(np.array),
       st.sampled_from(["simulation", "experiment"]), st.booleans())
def test_joint_targets_always_finite_and_within_limits(attitude, setpoint, omega, gain_set, normalize):
    config = load_controller_config(gain_set=gain_set).replace(normalize_force_direction=normalize)
    ctl = AttitudeController(PARAMS, config)
    ctl.set_setpoint(exp_so3(setpoint))
    R = exp_so3(attitude)
    for k in range(120):
        out = ctl.step(k * DT, R @ exp_so3(omega * k * DT * 0.1), omega)
        assert np.all(np.isfinite(out.joint_targets)) and np.all(np.isfinite(out.state.tau_cmd))
        for leg, q in zip(LEGS, out.joint_targets):
            assert within_limits(q, PARAMS, tol=0.0)
        assert np.linalg.norm(out.state.tau_sat) <= config.tau_max * (1 + 1e-12)


def test_closed_loop_reduces_a_30_degree_roll_error():
    """Smoke test of the whole loop on the paper's model (eq. (trans), (rot); RK4, dt = 0.01 s) with the
    simulation gains: a 30 deg roll error is brought down to a few degrees within 60 s."""
    model = FloatingBaseModel(PARAMS)
    ctl = AttitudeController(PARAMS, load_controller_config(gain_set="simulation"))
    state = RigidBodyState(rotation=rot_x(math.radians(30.0)))
    q_previous = NOMINAL_Q
    errors = []
    for k in range(6000):
        out = ctl.step(k * DT, state.rotation, state.omega)
        q_hold, q_dot = held_joint_input(q_previous, out.joint_targets, DT)
        state = model.step(state, q_hold, q_dot, DT)
        q_previous = out.joint_targets
        errors.append(math.degrees(geodesic_angle(np.eye(3), state.rotation)))
    errors = np.array(errors)
    # The stroke cycle leaves oscillations (paper, Fig. "sim"); their mean over the last 10 s is small.
    assert errors[-1000:].mean() < 6.0
    assert errors[-1000:].max() < 15.0
    assert errors[:500].min() < 20.0  # the error is reduced from the start


def test_estimate_body_torque_is_reexported():
    q_dot = np.zeros((4, 3))
    assert np.all(estimate_body_torque(NOMINAL_Q, q_dot, np.eye(3), np.zeros(3), PARAMS) == 0.0)


def test_controller_output_arrays_match_the_stroke_state():
    """The step's output arrays (one buffer, filled from the stroke's float state) hold the stroke's values
    and do not overlap."""
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


def _first_release_law(R_d, R, w, z, delta_sat, h, k_p, k_i, k_d, k_aw, tau_max, integral_limit, inertia,
                       gyroscopic, buoyancy, feet_sum, net_buoyancy):
    """The control law as the first release wrote it, component by component (the reference the named
    form must reproduce bit for bit: the paper-sim limit cycles are sensitive to the last bit)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    d00, d01, d02, d10, d11, d12, d20, d21, d22 = R_d
    wx, wy, wz = w
    e01 = d00 * r01 + d10 * r11 + d20 * r21
    e02 = d00 * r02 + d10 * r12 + d20 * r22
    e10 = d01 * r00 + d11 * r10 + d21 * r20
    e12 = d01 * r02 + d11 * r12 + d21 * r22
    e20 = d02 * r00 + d12 * r10 + d22 * r20
    e21 = d02 * r01 + d12 * r11 + d22 * r21
    ex, ey, ez = 0.5 * (e21 - e12), 0.5 * (e02 - e20), 0.5 * (e10 - e01)
    trace = (d00 * r00 + d10 * r10 + d20 * r20) + (d01 * r01 + d11 * r11 + d21 * r21) \
        + (d02 * r02 + d12 * r12 + d22 * r22)
    geodesic = math.atan2(math.sqrt(ex * ex + ey * ey + ez * ez), 0.5 * (trace - 1.0))
    fx = fy = fz = 0.0
    if gyroscopic:
        i0, i1, i2, i3, i4, i5, i6, i7, i8 = inertia
        hx, hy, hz = i0 * wx + i1 * wy + i2 * wz, i3 * wx + i4 * wy + i5 * wz, i6 * wx + i7 * wy + i8 * wz
        fx += wy * hz - wz * hy
        fy += wz * hx - wx * hz
        fz += wx * hy - wy * hx
    if buoyancy:
        sx, sy, sz = feet_sum
        ux, uy, uz = net_buoyancy * r20, net_buoyancy * r21, net_buoyancy * r22
        fx -= sy * uz - sz * uy
        fy -= sz * ux - sx * uz
        fz -= sx * uy - sy * ux
    g = h * k_aw * k_i
    if g <= 1.0:
        zx = z[0] + h * (ex + k_aw * delta_sat[0])
        zy = z[1] + h * (ey + k_aw * delta_sat[1])
        zz = z[2] + h * (ez + k_aw * delta_sat[2])
    else:
        zx, zy, zz = z[0] + h * ex, z[1] + h * ey, z[2] + h * ez
        ux = -k_p * ex - k_i * zx - k_d * wx + fx
        uy = -k_p * ey - k_i * zy - k_d * wy + fy
        uz = -k_p * ez - k_i * zz - k_d * wz + fz
        norm_u = math.sqrt(ux * ux + uy * uy + uz * uz)
        if norm_u > tau_max:
            step = h * k_aw * (norm_u - tau_max) / ((1.0 + g) * norm_u)
            zx, zy, zz = zx + step * ux, zy + step * uy, zz + step * uz
    norm_z = math.sqrt(zx * zx + zy * zy + zz * zz)
    if norm_z > integral_limit:
        scale = integral_limit / norm_z
        zx, zy, zz = zx * scale, zy * scale, zz * scale
    cx = -k_p * ex - k_i * zx - k_d * wx + fx
    cy = -k_p * ey - k_i * zy - k_d * wy + fy
    cz = -k_p * ez - k_i * zz - k_d * wz + fz
    norm_c = math.sqrt(cx * cx + cy * cy + cz * cz)
    if norm_c <= tau_max:
        sat, saturated = (cx, cy, cz), False
    else:
        s = tau_max / norm_c
        sat, saturated = (cx * s, cy * s, cz * s), True
    return (ex, ey, ez), geodesic, (zx, zy, zz), (cx, cy, cz), sat, saturated, (fx, fy, fz)


def test_control_law_on_named_quantities_computes_the_first_release_law_bit_for_bit():
    """control_law_f (LawGains, Feedforward, LawResult, the vec3 helpers) against the law written out
    component by component, on random inputs through both discretisations of the integral, saturated and
    not, with and without the feedforward terms: every float equal."""
    from quadruped_common.vec3 import Mat3
    from quadruped_control.control.controller import Feedforward, LawGains, LawResult, control_law_f

    rng = np.random.default_rng(11)
    inertia = tuple(np.asarray(PARAMS.inertia, dtype=float).ravel().tolist())
    branches = set()
    for n in range(400):
        R_d = tuple(exp_so3(rng.normal(0.0, 1.5, 3)).ravel().tolist())
        R = tuple(exp_so3(rng.normal(0.0, 1.5, 3)).ravel().tolist())
        w, z, delta_sat, feet_sum = (tuple(rng.normal(0.0, s, 3).tolist()) for s in (2.0, 3.0, 2.0, 0.3))
        h = float(rng.uniform(0.0, 0.03))
        k_p, k_i, k_d = (float(x) for x in rng.uniform(0.0, 20.0, 3))
        k_aw = float(rng.choice([0.0, 0.25, float(rng.uniform(0.0, 50.0))]))
        tau_max = float(rng.uniform(0.1, 5.0)) if n % 3 else 1e3
        integral_limit = float(rng.uniform(0.1, 5.0))
        gyroscopic, buoyancy = bool(n % 2), bool((n // 2) % 2)
        law = control_law_f(Mat3(*R_d), Mat3(*R), w, z, delta_sat, h,
                            LawGains(k_p, k_i, k_d, k_aw, tau_max, integral_limit),
                            Feedforward(gyroscopic, Mat3(*inertia), buoyancy, PARAMS.paw_net_buoyancy), feet_sum)
        assert isinstance(law, LawResult)
        expected = _first_release_law(R_d, R, w, z, delta_sat, h, k_p, k_i, k_d, k_aw, tau_max, integral_limit,
                                      inertia, gyroscopic, buoyancy, feet_sum, PARAMS.paw_net_buoyancy)
        assert tuple(law) == expected
        branches.add((h * k_aw * k_i > 1.0, law.saturated))
    assert branches == {(False, False), (False, True), (True, False), (True, True)}
