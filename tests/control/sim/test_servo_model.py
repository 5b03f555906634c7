"""Tests of the simulator's servo models (rate limit, first-order lag, ideal)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.config import ParameterError
from quadruped_control.sim import servo_model
from quadruped_control.sim.servo_model import (
    IdealServo,
    RateLimitedServo,
    ServoParams,
    dead_band_command,
    load_servo_params,
    make_servo_model,
    rate_limited_lag_step,
)

W_MAX = 95.0 * 2.0 * math.pi / 60.0


def test_ideal_servo_reaches_command_in_one_step() -> None:
    servo = IdealServo()
    servo.reset(np.zeros((4, 3)))
    target = np.arange(12.0).reshape(4, 3) * 0.1
    assert np.array_equal(servo.update(target, 0.01), target)
    assert np.array_equal(servo.position, target)


def test_rate_limit_caps_joint_speed_at_no_load_speed() -> None:
    servo = RateLimitedServo(ServoParams(max_speed=W_MAX, time_constant=0.03))
    servo.reset(np.zeros(12))
    command = np.full(12, 2.0)
    q = servo.update(command, 0.01)
    assert np.allclose(q, W_MAX * 0.01)   # far from the target: moves at the speed limit
    positions = [q]
    for _ in range(20):
        positions.append(servo.update(command, 0.01))
    speeds = np.abs(np.diff(np.array(positions), axis=0)) / 0.01
    assert np.max(speeds) <= W_MAX * (1.0 + 1e-12)


def test_small_step_follows_first_order_lag_exactly() -> None:
    tau = 0.05
    servo = RateLimitedServo(ServoParams(max_speed=W_MAX, time_constant=tau))
    servo.reset(np.zeros(12))
    step = 0.01 * np.ones(12)  # below the knee w_max tau ~ 0.5 rad: pure lag
    for k in range(1, 11):
        q = servo.update(step, 0.01)
        assert np.allclose(q, step * (1.0 - math.exp(-0.01 * k / tau)), rtol=1e-12, atol=1e-15)


def test_large_step_is_rate_limited_then_lags() -> None:
    tau = 0.03
    servo = RateLimitedServo(ServoParams(max_speed=W_MAX, time_constant=tau))
    servo.reset(np.zeros(12))
    target = 1.0
    # Analytic: linear at w_max until the error is w_max tau, then exponential.
    t_knee = (target - W_MAX * tau) / W_MAX
    q = None
    for k in range(1, 31):
        q = servo.update(np.full(12, target), 0.01)
        t = 0.01 * k
        if t <= t_knee:
            expected = W_MAX * t
        else:
            expected = target - W_MAX * tau * math.exp(-(t - t_knee) / tau)
        assert q[0] == pytest.approx(expected, abs=1e-12)
    assert q is not None and abs(q[0] - target) < 1e-3


def test_pure_rate_limiter_with_zero_time_constant() -> None:
    servo = RateLimitedServo(ServoParams(max_speed=1.0, time_constant=0.0))
    servo.reset(np.zeros(12))
    assert np.allclose(servo.update(np.full(12, -0.5), 0.1), -0.1)
    assert np.allclose(servo.update(np.full(12, -0.15), 0.1), -0.15)  # within reach: exact


@given(st.lists(st.floats(-3.0, 3.0), min_size=12, max_size=12), st.floats(1e-3, 0.05),
       st.floats(0.0, 0.2))
def test_rate_limited_servo_never_overshoots_and_respects_speed(command, dt, tau) -> None:
    servo = RateLimitedServo(ServoParams(max_speed=W_MAX, time_constant=tau))
    servo.reset(np.zeros(12))
    target = np.array(command)
    previous = np.zeros(12)
    for _ in range(5):
        q = servo.update(target, dt)
        assert np.all(np.abs(q - previous) <= W_MAX * dt * (1.0 + 1e-9) + 1e-15)
        # Moves monotonically towards the target, never past it.
        assert np.all(np.abs(target - q) <= np.abs(target - previous) + 1e-15)
        assert np.all((target - q) * (target - previous) >= -1e-15)
        previous = q


def test_shape_is_preserved_and_bad_input_rejected() -> None:
    servo = RateLimitedServo(ServoParams(max_speed=W_MAX, time_constant=0.03))
    servo.reset(np.zeros((4, 3)))
    assert servo.update(np.ones(12), 0.01).shape == (4, 3)
    with pytest.raises(ValueError):
        servo.update(np.full(12, np.nan), 0.01)
    with pytest.raises(ValueError):
        servo.update(np.zeros(11), 0.01)
    with pytest.raises(ValueError):
        servo.update(np.zeros(12), 0.0)
    before = servo.position
    with pytest.raises(ValueError):
        servo.update(np.full(12, np.inf), 0.01)
    assert np.array_equal(servo.position, before)  # a rejected command does not move the servos
    with pytest.raises(RuntimeError):
        IdealServo().position


def test_params_validation_and_config_loading() -> None:
    with pytest.raises(ParameterError):
        ServoParams(max_speed=0.0, time_constant=0.03)
    with pytest.raises(ParameterError):
        ServoParams(max_speed=1.0, time_constant=-1.0)
    params = load_servo_params()
    assert params.max_speed == pytest.approx(W_MAX)
    assert params.time_constant > 0.0
    with pytest.raises(ParameterError):
        load_servo_params(tree={"simulation": {}})
    with pytest.raises(ParameterError):
        load_servo_params(tree={"simulation": {"servo": {"time_constant": 0.1, "speed_scale": 2.0}}})
    with pytest.raises(ParameterError, match="no_load_speed_rpm"):  # one place for the servo speed: robot.yaml
        load_servo_params(tree={"simulation": {"servo": {"no_load_speed_rpm": 95, "time_constant": 0.1}}})
    assert isinstance(make_servo_model("ideal"), IdealServo)
    assert isinstance(make_servo_model("rate-limited"), RateLimitedServo)
    with pytest.raises(ValueError):
        make_servo_model("magic")


def test_update_trusted_matches_update() -> None:
    params = ServoParams(max_speed=W_MAX, time_constant=0.03)
    checked, trusted = RateLimitedServo(params), RateLimitedServo(params)
    checked.reset(np.zeros((4, 3)))
    trusted.reset(np.zeros((4, 3)))
    rng = np.random.default_rng(5)
    for _ in range(30):
        command = rng.uniform(-1.0, 1.0, (4, 3))
        np.testing.assert_array_equal(checked.update(command, 0.01), trusted.update_trusted(command, 0.01))


def _rk4(rate, x: float, dt: float, n: int = 20000) -> float:
    """x after ``dt`` of dx/dt = rate(x) in ``n`` RK4 sub-steps: the reference for the exact steps."""
    h = dt / n
    for _ in range(n):
        k1 = rate(x)
        k2 = rate(x + 0.5 * h * k1)
        k3 = rate(x + 0.5 * h * k2)
        k4 = rate(x + h * k3)
        x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


@settings(max_examples=30, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(1.0, 20.0), st.sampled_from([0.0, 0.005, 0.03, 0.2]),
       st.sampled_from([0.001, 0.01, 0.05]))
def test_exact_step_agrees_with_a_fine_integration_of_the_servo_ode(q, command, max_speed, tau, dt) -> None:
    """rate_limited_lag_step against 20,000 RK4 sub-steps of dq/dt = clip((q_cmd - q) / T, -w_max, w_max)
    (the rate limiter alone, T = 0, against its own definition)."""
    exact = rate_limited_lag_step(q, command, max_speed, tau, dt)
    if tau == 0.0:
        assert exact == pytest.approx(q + max(-max_speed * dt, min(max_speed * dt, command - q)), abs=1e-12)
        return

    def rate(x: float) -> float:
        return max(-max_speed, min(max_speed, (command - x) / tau))

    x = _rk4(rate, q, dt)
    assert exact == pytest.approx(x, abs=1e-7)  # RK4 meets the kink at |e| = w_max T once


def test_exact_step_keeps_nan_and_a_joint_at_its_command() -> None:
    assert math.isnan(rate_limited_lag_step(0.1, math.nan, 10.0, 0.03, 0.01))
    assert math.isnan(rate_limited_lag_step(0.1, math.nan, 10.0, 0.0, 0.01))
    assert rate_limited_lag_step(0.25, 0.25, 10.0, 0.03, 0.01) == 0.25


def test_the_batch_servo_step_is_the_exact_float_step_per_joint_compiled_or_not():
    rng = np.random.default_rng(6)
    q = rng.uniform(-1.0, 1.0, (50, 4, 3))
    command = q + rng.normal(0.0, 0.2, (50, 4, 3))
    command[:5] = q[:5]                 # no error
    command[5, 0, 0] = math.nan         # NaN passes through
    speed = rng.uniform(1.0, 12.0, 50)
    lag = rng.choice([0.0, 1e-13, 0.01, 0.03], 50)  # pure rate limiter included
    ideal = rng.random(50) < 0.2
    stall = np.where(rng.random(50) < 0.5, 0.0, rng.uniform(0.5, 4.0, 50))  # loaded servos on half the trials
    band = np.where(rng.random(50) < 0.5, 0.0, rng.uniform(0.0, 0.3, 50))   # dead bands on half, some errors inside
    loads = rng.normal(0.0, 1.0, (50, 4, 3))

    def target_of(i, leg, j):
        return dead_band_command(q[i, leg, j], command[i, leg, j], band[i])

    def speed_of(i, leg, j):
        return servo_model.loaded_speed(speed[i], target_of(i, leg, j) - q[i, leg, j], loads[i, leg, j], stall[i])

    expected = np.array([[[command[i, leg, j] if ideal[i] else
                           servo_model.rate_limited_lag_step(q[i, leg, j], target_of(i, leg, j), speed_of(i, leg, j),
                                                             lag[i], 0.01)
                           for j in range(3)] for leg in range(4)] for i in range(50)])
    assert (np.abs(command - q) < band[:, None, None]).any()  # some joints held by their dead band
    for step in (servo_model.servo_batch_step, servo_model.servo_batch_step.py_func):
        out, mid, rate = np.empty_like(q), np.empty_like(q), np.empty_like(q)
        step(q, command, ideal, speed, lag, stall, band, loads, 0.01, out, mid, rate)
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-15)
        # the held joints of PlantSimulator, bit for bit as numpy computes them
        assert np.array_equal(mid, 0.5 * (q + out), equal_nan=True)
        assert np.array_equal(rate, (out - q) / 0.01, equal_nan=True)


def test_a_loaded_servo_follows_its_torque_speed_line_against_the_load_and_only_against_it():
    """w = w_max (1 - tau_opp / tau_stall): half the stall torque against the motion halves the speed, in
    either direction; a load along the motion or no stall torque leaves w_max; at or past the stall the
    joint stops (a floor of 1e-6 w_max)."""
    from quadruped_control.sim.servo_model import loaded_speed
    assert loaded_speed(10.0, 0.3, -2.0, 4.0) == 5.0     # moving up, load pushing down
    assert loaded_speed(10.0, -0.3, 2.0, 4.0) == 5.0     # moving down, load pushing up
    assert loaded_speed(10.0, 0.3, 2.0, 4.0) == 10.0     # the load helps: no faster than no-load
    assert loaded_speed(10.0, 0.0, -2.0, 4.0) == 10.0    # not moving
    assert loaded_speed(10.0, 0.3, -2.0, 0.0) == 10.0    # no stall torque: the load does not matter
    assert loaded_speed(10.0, 0.3, -5.0, 4.0) == 10.0 * 1e-6
    # RateLimitedServo with loads: the joints pushed against run at half speed, the others at full
    servo = RateLimitedServo(ServoParams(max_speed=10.0, time_constant=0.0, stall_torque=4.0))
    servo.reset(np.zeros((4, 3)))
    servo.loads = [[-2.0, 2.0, 0.0]] * 4
    q = servo.update(np.full((4, 3), 1.0), 0.01)
    np.testing.assert_allclose(q, [[0.05, 0.1, 0.1]] * 4)
    servo.reset(np.zeros((4, 3)))
    assert servo.loads is None


@settings(max_examples=60, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0))
def test_no_dead_band_is_the_command_itself_bit_for_bit(q, command) -> None:
    assert dead_band_command(q, command, 0.0) == command


def test_a_dead_band_holds_errors_inside_it_and_shortens_the_rest_by_its_width() -> None:
    assert dead_band_command(0.1, 0.105, 0.01) == 0.1           # inside: the joint stays
    assert dead_band_command(0.1, 0.095, 0.01) == 0.1
    assert dead_band_command(0.0, 0.5, 0.01) == pytest.approx(0.49)
    assert dead_band_command(0.0, -0.5, 0.01) == pytest.approx(-0.49)
    assert math.isnan(dead_band_command(0.0, math.nan, 0.01))


@settings(max_examples=30, deadline=None)
@given(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(1.0, 20.0), st.sampled_from([0.005, 0.03, 0.2]),
       st.sampled_from([0.001, 0.01, 0.05]), st.sampled_from([0.002, 0.01, 0.05]))
def test_the_dead_band_step_agrees_with_a_fine_integration_of_its_ode(q, command, max_speed, tau, dt, band) -> None:
    """rate_limited_lag_step towards dead_band_command against RK4 sub-steps of
    dq/dt = clip(dz(q_cmd - q) / T, -w_max, w_max), dz(e) = sign(e) max(|e| - d, 0)."""
    exact = rate_limited_lag_step(q, dead_band_command(q, command, band), max_speed, tau, dt)

    def rate(x: float) -> float:
        error = command - x
        beyond = math.copysign(max(abs(error) - band, 0.0), error)
        return max(-max_speed, min(max_speed, beyond / tau))

    x = _rk4(rate, q, dt)
    assert exact == pytest.approx(x, abs=1e-7)


def test_a_servo_with_a_dead_band_stops_short_and_plays_like_backlash() -> None:
    """A step settles d short of the command; a command reversed by less than 2 d does not move the joint;
    a sine of amplitude A (slow next to the servo) moves the joint by A - d either side, a quarter of
    whose amplitude a stroke of A = 4 d loses."""
    band = 0.01
    servo = RateLimitedServo(ServoParams(max_speed=W_MAX, time_constant=0.03, dead_band=band))
    servo.reset(np.zeros((4, 3)))
    for _ in range(200):
        q = servo.update(np.full((4, 3), 0.2), 0.01)
    np.testing.assert_allclose(q, 0.2 - band, atol=1e-9)
    for _ in range(50):
        held = servo.update(np.full((4, 3), 0.2 - 1.9 * band), 0.01)   # reversed by 1.9 d: still inside
    np.testing.assert_array_equal(held, q)
    servo.reset(np.zeros((4, 3)))
    amplitude, t = 4.0 * band, np.arange(0.0, 8.0, 0.01)
    joint = np.array([servo.update(np.full((4, 3), amplitude * math.sin(2.0 * math.pi * 0.25 * k)), 0.01)[0, 0]
                      for k in t])
    late = joint[t > 4.0]
    assert late.max() == pytest.approx(amplitude - band, abs=2e-3) and late.min() == pytest.approx(-(amplitude - band),
                                                                                                  abs=2e-3)
    with pytest.raises(ParameterError, match="dead_band"):
        ServoParams(max_speed=W_MAX, time_constant=0.03, dead_band=-0.01)
    with pytest.raises(ParameterError, match="dead_band"):
        ServoParams(max_speed=W_MAX, time_constant=0.03, dead_band=math.nan)
