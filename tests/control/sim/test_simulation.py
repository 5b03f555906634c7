"""Tests of the offline closed-loop simulator core (quadruped_control.sim.simulation)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.so3 import exp_so3, geodesic_angle, rot_to_quat, rot_to_rpy, rpy_to_rot
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.kinematics import UnreachableError, joint_angles_full
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.paper import DynamicsError, FloatingBaseModel, RigidBodyState, held_joint_input
from quadruped_control.sim.servo_model import IdealServo, RateLimitedServo, ServoParams
from quadruped_control.sim.simulation import (
    ClosedLoopSimulation,
    PlantSimulator,
    SimulationError,
    geodesic_angles,
    load_simulation_settings,
    nominal_joint_angles,
    rotations_to_quaternions,
    rotations_to_rpy,
)

ROBOT = load_robot_params()
CONFIG = load_controller_config(gain_set="simulation")
Q0 = nominal_joint_angles(ROBOT)


# ------------------------------------------------------------------ plant

def test_plant_with_legs_still_does_not_rotate() -> None:
    # Level: the paw buoyancy acts along the vertical through the symmetric feet, no torque at all.
    plant = PlantSimulator(ROBOT, IdealServo())
    for _ in range(200):
        state = plant.step(Q0)
    assert geodesic_angle(np.eye(3), state.rotation) < 1e-12
    assert np.allclose(state.omega, 0.0, atol=1e-15)
    # Tilted, with neutrally buoyant paws (no conservative torque): still no rotation.
    neutral = dataclasses.replace(ROBOT, paw_mass=ROBOT.rho * ROBOT.paw_volume)
    R0 = rpy_to_rot(0.3, -0.2, 1.0)
    plant = PlantSimulator(neutral, RateLimitedServo(ServoParams(10.0, 0.03)), initial_rotation=R0)
    for _ in range(200):
        state = plant.step(Q0.reshape(12))
    assert geodesic_angle(R0, state.rotation) < 1e-12
    assert np.allclose(state.omega, 0.0, atol=1e-15)
    assert np.allclose(plant.joint_velocities, 0.0)


def test_tilted_plant_with_negatively_buoyant_paws_swings_back_towards_level() -> None:
    # The paws sit below the centre of mass and are slightly heavier than water (config estimate):
    # a pendulum, whose tilt first decreases.
    plant = PlantSimulator(ROBOT, initial_rotation=rpy_to_rot(0.3, 0.0, 0.0))
    for _ in range(50):
        plant.step(Q0)
    assert 0.0 < rot_to_rpy(plant.state.rotation)[0] < 0.3


def test_plant_step_matches_dynamics_with_held_midpoint_input() -> None:
    plant = PlantSimulator(ROBOT, IdealServo(), initial_rotation=rpy_to_rot(0.1, 0.2, 0.3))
    model = FloatingBaseModel(ROBOT)
    state = RigidBodyState(rotation=rpy_to_rot(0.1, 0.2, 0.3))
    q_prev = Q0
    rng = np.random.default_rng(4)
    for _ in range(20):
        q_next = Q0 + rng.uniform(-0.05, 0.05, (4, 3))
        got = plant.step(q_next)
        state = model.step(state, *held_joint_input(q_prev, q_next, 0.01), 0.01)
        q_prev = q_next
        np.testing.assert_allclose(got.to_vector(), state.to_vector(), rtol=1e-12, atol=1e-14)


def _reference_plant_step(model: FloatingBaseModel, state: RigidBodyState, q0: np.ndarray, q1: np.ndarray,
                          h: float) -> RigidBodyState:
    q_hold, q_dot = held_joint_input(q0, q1, h)
    context = model._context(model.leg_input(q_hold, q_dot))
    return model._rk4(state, h, (context, context, context))


@settings(max_examples=30)
@given(st.integers(0, 2 ** 32 - 1), st.booleans(), st.booleans())
def test_plant_float_hold_equals_array_reference(seed, rate_limited, clamp) -> None:
    """PlantSimulator's float hold input (midpoint and finite difference on floats, held-input RK4)
    against the array formulas of held_joint_input, LegInput and the generic RK4."""
    rng = np.random.default_rng(seed)
    servo = RateLimitedServo(ServoParams(8.0, 0.03)) if rate_limited else IdealServo()
    plant = PlantSimulator(ROBOT, servo, initial_rotation=exp_so3(rng.uniform(-1.0, 1.0, 3)))
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


def test_plant_with_rate_limited_servo_lags_the_command() -> None:
    servo = RateLimitedServo(ServoParams(max_speed=10.0, time_constant=0.01))
    plant = PlantSimulator(ROBOT, servo)
    command = Q0 + 0.3
    plant.step(command)
    assert np.allclose(plant.joint_positions, Q0 + 0.1)  # error above the knee: 10 rad/s for 10 ms
    for _ in range(50):
        plant.step(command)
    assert np.allclose(plant.joint_positions, command, atol=1e-3)


def test_plant_clamps_commands_to_servo_ranges() -> None:
    plant = PlantSimulator(ROBOT)
    limits = ROBOT.joint_limits.as_array()
    command = Q0.copy()
    command[0, 2] = limits[2, 1] + 1.0  # hip of leg 1 beyond its range
    plant.step(command)
    assert plant.joint_positions[0, 2] == pytest.approx(limits[2, 1])
    assert plant.clamped_joints == 1


def test_plant_rejects_bad_commands_and_keeps_its_state() -> None:
    plant = PlantSimulator(ROBOT, RateLimitedServo(ServoParams(max_speed=10.0, time_constant=0.03)))
    plant.step(Q0 + 0.01)
    before = plant.state.to_vector()
    joints = plant.joint_positions
    for bad in (np.full(12, np.nan), np.zeros(11), [[1, 2, 3]]):
        with pytest.raises(ValueError):
            plant.step(bad)
    with pytest.raises(ValueError):
        plant.step(Q0, dt=0.0)
    assert np.array_equal(plant.state.to_vector(), before)
    assert np.array_equal(plant.joint_positions, joints)
    with pytest.raises(ValueError):
        PlantSimulator(ROBOT, initial_rotation=np.ones((3, 3)))


@pytest.mark.parametrize("error", [UnreachableError("five-bar cannot close", 1), DynamicsError("diverged")])
def test_plant_failure_raises_simulation_error_and_keeps_state(monkeypatch, error) -> None:
    plant = PlantSimulator(ROBOT, RateLimitedServo(ServoParams(10.0, 0.03)))
    before = plant.state.to_vector()

    def failing(*args, **kwargs):
        raise error

    monkeypatch.setattr(plant.model, "step_trusted", failing)
    with pytest.raises(SimulationError):
        plant.step(Q0 + 0.1)
    assert np.array_equal(plant.state.to_vector(), before)
    assert np.array_equal(plant.joint_positions, Q0)
    assert np.array_equal(plant.servo.position, Q0)  # the servo model is rolled back too
    assert plant.time == 0.0


def test_restoring_offset_rights_a_tilted_plant() -> None:
    plant = PlantSimulator(ROBOT, initial_rotation=rpy_to_rot(0.4, 0.0, 0.0), restoring_offset=[0.0, 0.0, 0.02])
    for _ in range(100):
        plant.step(Q0)
    roll = rot_to_rpy(plant.state.rotation)[0]
    assert roll < 0.4 - 0.05


# ------------------------------------------------------------------ conversions

@settings(max_examples=50)
@given(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_vectorised_conversions_match_so3(rotvec) -> None:
    R = exp_so3(rotvec)
    Rd = rpy_to_rot(0.2, -0.4, 2.0)
    np.testing.assert_allclose(rotations_to_rpy(R[None])[0], rot_to_rpy(R), atol=1e-12)
    q = rotations_to_quaternions(R[None])[0]
    expected = rot_to_quat(R)
    assert np.allclose(q, expected, atol=1e-12) or np.allclose(q, -expected, atol=1e-12)
    assert geodesic_angles(Rd, R[None])[0] == pytest.approx(geodesic_angle(Rd, R), abs=1e-12)


def test_gimbal_lock_rows_convert_like_so3() -> None:
    R = np.stack([rpy_to_rot(0.3, math.pi / 2, 0.0), rpy_to_rot(-0.2, -math.pi / 2, 0.0)])
    np.testing.assert_allclose(rotations_to_rpy(R), [rot_to_rpy(R[0]), rot_to_rpy(R[1])], atol=1e-9)


# ------------------------------------------------------------------ closed loop

def _short_run(seed: int, noise: float, duration: float = 3.0):
    sim = ClosedLoopSimulation(ROBOT, CONFIG, "ideal", np.eye(3), rpy_to_rot(0.3, 0.3, 0.3), seed=seed,
                               attitude_noise=noise, gyro_noise=noise)
    return sim.run(duration)


def test_closed_loop_is_deterministic_for_a_seed() -> None:
    a = _short_run(7, 0.01)
    b = _short_run(7, 0.01)
    c = _short_run(8, 0.01)
    np.testing.assert_array_equal(a.rotation, b.rotation)
    np.testing.assert_array_equal(a.joint_targets, b.joint_targets)
    assert not np.array_equal(a.rotation, c.rotation)


def test_a_run_continued_by_another_is_the_same_as_one_longer_run() -> None:
    whole = ClosedLoopSimulation(ROBOT, CONFIG, "ideal", np.eye(3), rpy_to_rot(0.3, 0.3, 0.3), seed=3,
                                 attitude_noise=0.01, gyro_noise=0.01).run(3.0)
    sim = ClosedLoopSimulation(ROBOT, CONFIG, "ideal", np.eye(3), rpy_to_rot(0.3, 0.3, 0.3), seed=3,
                               attitude_noise=0.01, gyro_noise=0.01)
    calls = []
    real_step = sim.controller.step
    sim.controller.step = lambda t, R, w: calls.append(t) or real_step(t, R, w)  # type: ignore[method-assign]
    first, second = sim.run(1.0), sim.run(2.0)
    # the second run starts at the first's last sample: that measurement and output, not a second draw or step
    np.testing.assert_array_equal(np.concatenate([first.rotation, second.rotation[1:]]), whole.rotation)
    np.testing.assert_array_equal(np.concatenate([first.joint_targets, second.joint_targets[1:]]),
                                  whole.joint_targets)
    assert len(calls) == len(set(calls)) == 301  # once per period, 0 .. 3 s


def test_a_setpoint_changed_between_runs_controls_the_shared_sample_again_without_a_new_measurement() -> None:
    sim = ClosedLoopSimulation(ROBOT, CONFIG, "ideal", seed=5, attitude_noise=0.01, gyro_noise=0.01)
    first = sim.run(1.0)
    seen = []
    real_step = sim.controller.step
    sim.controller.step = lambda t, R, w: seen.append((t, np.array(R))) or real_step(t, R, w)  # type: ignore
    last = sim._last_sample
    sim.set_setpoint(rpy_to_rot(0.2, 0.0, 0.0))
    result = sim.run(0.5)
    # the step at 1 s is controlled again on the measurement the first run's last sample drew
    assert seen[0][0] == pytest.approx(1.0) and seen[1][0] > 1.0
    np.testing.assert_array_equal(seen[0][1], last.R)
    assert len(seen) == 51
    # the shared sample is recorded in each run with the setpoint then in force
    np.testing.assert_array_equal(result.rotation[0], first.rotation[-1])
    assert not np.allclose(result.tau_cmd[0], first.tau_cmd[-1])


def _held_simulation():
    """A closed loop that acted 2 s towards roll 0.3 rad, then held 1 s with its controller off."""
    sim = ClosedLoopSimulation(ROBOT, CONFIG, "ideal", np.eye(3), rpy_to_rot(0.3, 0.0, 0.0))
    acting = sim.run(2.0)
    sim.set_controller(False)
    return sim, acting, sim.run(1.0)


def test_a_disarm_keeps_the_last_command_where_holding_retraces_to_the_nominal_pose() -> None:
    # disarmed mid-stroke, the robot's PCA9685 keeps its last pulses (failsafe hold); holding retraces instead
    runs = {}
    for name in ("disarmed", "holding"):
        sim = ClosedLoopSimulation(ROBOT, CONFIG, "ideal", np.eye(3), rpy_to_rot(0.3, 0.0, 0.0))
        acting = sim.run(1.03)
        last = sim.plant.last_command
        assert not np.allclose(last, Q0, atol=0.05)  # mid-stroke: away from the nominal pose
        if name == "disarmed":
            sim.disarm()
        else:
            sim.set_controller(False)
        runs[name] = (acting, last, sim.run(2.0), sim)
    acting, last, disarmed, sim = runs["disarmed"]
    assert disarmed.holding.all() and disarmed.info["controller"] == "disarmed"
    assert np.array_equal(disarmed.joint_targets, np.broadcast_to(last.reshape(12), disarmed.joint_targets.shape))
    assert np.array_equal(sim.plant.last_command, last)
    _, _, holding, _ = runs["holding"]
    assert holding.info["controller"] == "off"
    assert np.allclose(holding.joint_targets[-1], Q0.reshape(12))
    assert not np.allclose(holding.joint_targets[0], Q0.reshape(12), atol=0.05)
    # armed again (reset), it strokes from a cleared integral and the disarm is over
    sim.set_controller(True, reset=True)
    _, output = sim.step()
    assert not sim.disarmed and not output.state.holding and np.linalg.norm(output.state.integral) < 0.01


def test_the_controller_turned_off_holds_and_turned_on_cleared_starts_from_a_zero_integral() -> None:
    sim, acting, off = _held_simulation()
    # from the shared sample on (controlled again, off) the controller holds
    assert not acting.holding[-1] and off.holding.all() and off.info["controller"] == "off"
    sim.set_controller(True, reset=True)
    _, cleared = sim.step()
    kept_sim, _, _ = _held_simulation()
    kept_sim.set_controller(True)
    _, kept = kept_sim.step()
    assert not cleared.state.holding and not kept.state.holding
    # the hold froze the integral; arming again clears it (one period integrated), turning on alone does not
    assert np.linalg.norm(kept.state.integral) > 0.05
    assert np.linalg.norm(cleared.state.integral) < 0.02 * np.linalg.norm(kept.state.integral)


def test_closed_loop_records_consistent_arrays_and_turns_towards_setpoint() -> None:
    result = _short_run(0, 0.0, duration=5.0)
    n = 501
    assert result.t.shape == (n,) and result.t[-1] == pytest.approx(5.0)
    for name in ("omega", "tau_cmd", "tau_sat", "rpy"):
        assert getattr(result, name).shape == (n, 3)
    assert result.quaternion.shape == (n, 4)
    assert result.joint_targets.shape == (n, 12) and result.pair_phase.shape == (n, 2)
    assert set(np.unique(result.pair_phase)) <= {"power", "recovery", "hold"}
    assert np.all(np.linalg.norm(result.tau_sat, axis=1) <= CONFIG.tau_max + 1e-9)
    assert result.geodesic[-1] < result.geodesic[0] - math.radians(5.0)
    assert result.info["servo_model"] == "ideal" and result.info["controller_holds"] == 0
    assert all(np.isfinite(v) for v in result.rotation.reshape(-1))


def test_a_setpoint_changed_mid_run_steers_from_the_next_step_and_is_recorded() -> None:
    sim = ClosedLoopSimulation(ROBOT, CONFIG, "ideal")
    sim.run(0.5)
    setpoint = rpy_to_rot(0.3, 0.0, 0.0)
    sim.set_setpoint(setpoint)
    result = sim.run(3.0)
    np.testing.assert_allclose(result.setpoint, setpoint)
    assert result.rpy[-1, 0] > result.rpy[0, 0] + 0.01  # it turns towards the new roll
    with pytest.raises(ValueError):
        sim.set_setpoint(np.full((3, 3), math.nan))
    np.testing.assert_allclose(sim.setpoint_R, setpoint)  # a refused setpoint leaves the last one


def test_closed_loop_rejects_non_finite_targets(monkeypatch) -> None:
    sim = ClosedLoopSimulation(ROBOT, CONFIG)
    real_step = sim.controller.step

    def bad_step(t, R, omega):
        out = real_step(t, R, omega)
        out.joint_targets[2, 1] = math.nan
        return out

    monkeypatch.setattr(sim.controller, "step", bad_step)
    with pytest.raises(SimulationError):
        sim.step()


def test_closed_loop_counts_out_of_range_targets(monkeypatch) -> None:
    sim = ClosedLoopSimulation(ROBOT, CONFIG)
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


def test_closed_loop_equals_reference_components_bit_for_bit() -> None:
    """The simulator (float IK, float hold input, held-input RK4, single-buffer outputs) reproduces a loop
    built from the reference pieces: kinematics.joint_angles_full, held_joint_input, LegInput and _rk4."""
    R_d = rpy_to_rot(*np.radians([45.0, 45.0, 45.0]))
    sim = ClosedLoopSimulation(ROBOT, CONFIG, IdealServo(), np.eye(3), R_d)
    result = sim.run(3.0)

    controller = AttitudeController(ROBOT, CONFIG)
    controller.set_setpoint(R_d)
    stroke = controller.stroke
    stroke._ik_raw = lambda point, leg: tuple(joint_angles_full(point, leg, ROBOT)[:3].tolist())
    stroke._ik_injected = True
    model = FloatingBaseModel(ROBOT)
    state, q = RigidBodyState(), Q0.copy()
    limits = ROBOT.joint_limits.as_array()
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


def test_run_rejects_bad_duration_and_rotations() -> None:
    sim = ClosedLoopSimulation(ROBOT, CONFIG)
    with pytest.raises(ValueError):
        sim.run(0.0)
    with pytest.raises(ValueError):
        sim.run(float("nan"))
    with pytest.raises(ValueError):
        ClosedLoopSimulation(ROBOT, CONFIG, setpoint_R=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError):
        ClosedLoopSimulation(ROBOT, CONFIG, attitude_noise=-1.0)


def test_progress_callback_is_throttled_and_reports_the_end() -> None:
    calls = []
    sim = ClosedLoopSimulation(ROBOT, CONFIG, setpoint_R=rpy_to_rot(0.1, 0.0, 0.0))
    sim.run(2.0, progress=lambda t, d: calls.append((t, d)), progress_interval=1e9)
    assert calls == [(pytest.approx(2.0), 2.0)]


def test_settings_load_from_config() -> None:
    s = load_simulation_settings()
    assert s.dt == pytest.approx(0.01)
    assert s.servo_model == "ideal"  # the paper's model is the default
    assert s.servo.max_speed == pytest.approx(95.0 * 2.0 * math.pi / 60.0)
