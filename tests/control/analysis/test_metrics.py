"""Tests of quadruped_control.analysis.metrics on signals with known answers."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from quadruped_common.so3 import wrap_angle
from quadruped_control.analysis.metrics import (
    axis_errors,
    compute_metrics,
    moving_average_centered,
    resample_uniform,
    settling_time,
)

DT = 0.01


def _grid(duration: float, dt: float = DT) -> np.ndarray:
    return np.arange(int(round(duration / dt)) + 1) * dt


# ------------------------------------------------------------------ moving average

def test_moving_average_of_constant_is_constant_including_edges() -> None:
    t = _grid(10.0)
    out = moving_average_centered(np.full(t.size, 2.5), t)
    assert np.allclose(out, 2.5)


def test_moving_average_of_linear_signal_is_exact_in_interior_and_biased_at_edges() -> None:
    t = _grid(10.0)
    x = 3.0 * t
    out = moving_average_centered(x, t, window=3.0)
    interior = (t >= 1.5) & (t <= 8.5)
    assert np.allclose(out[interior], x[interior], atol=1e-9)
    # At t = 0 the truncated window holds [0, 1.5] s: mean of 3 t over it is 2.25.
    assert out[0] == pytest.approx(2.25, abs=1e-9)
    assert out[-1] == pytest.approx(3.0 * (10.0 - 0.75), abs=1e-9)


def test_moving_average_window_has_odd_sample_count_for_uniform_sampling() -> None:
    t = _grid(10.0)
    x = np.zeros(t.size)
    x[500] = 1.0  # an impulse spreads over round(3 / dt) + 1 = 301 samples
    out = moving_average_centered(x, t, window=3.0)
    assert np.count_nonzero(out) == 301
    assert out[500] == pytest.approx(1.0 / 301.0)


def test_moving_average_removes_stroke_oscillation_with_period_dividing_window() -> None:
    t = _grid(20.0)
    x = 1.0 + np.sin(2.0 * math.pi * t / 1.5)  # period 1.5 s: two periods per 3 s window
    out = moving_average_centered(x, t)
    interior = (t >= 2.0) & (t <= 18.0)
    assert np.max(np.abs(out[interior] - 1.0)) < 0.01


def test_moving_average_accepts_columns() -> None:
    t = _grid(5.0)
    x = np.column_stack((t, -t, np.ones(t.size)))
    out = moving_average_centered(x, t)
    assert out.shape == x.shape
    for column in range(3):
        assert np.allclose(out[:, column], moving_average_centered(x[:, column], t))


def test_moving_average_rejects_bad_input() -> None:
    t = _grid(1.0)
    with pytest.raises(ValueError):
        moving_average_centered(np.full(t.size, np.nan), t)
    with pytest.raises(ValueError):
        moving_average_centered(np.zeros(t.size), t[::-1])
    with pytest.raises(ValueError):
        moving_average_centered(np.zeros(t.size - 1), t)
    with pytest.raises(ValueError):
        moving_average_centered(np.zeros(t.size), t, window=-1.0)


@given(st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=60), st.floats(0.0, 5.0))
def test_moving_average_stays_within_signal_range(values, window) -> None:
    x = np.array(values)
    t = np.arange(x.size) * 0.1
    out = moving_average_centered(x, t, window)
    assert np.all(np.isfinite(out))
    assert np.all(out >= x.min() - 1e-9) and np.all(out <= x.max() + 1e-9)


# ------------------------------------------------------------------ resampling and errors

def test_resample_uniform_interpolates_linearly() -> None:
    t = np.array([0.0, 0.3, 0.35, 1.0])
    grid, x = resample_uniform(t, 2.0 * t + 1.0, dt=0.1)
    assert np.allclose(grid, np.arange(11) * 0.1)
    assert np.allclose(x, 2.0 * grid + 1.0)


def test_axis_errors_unwrap_yaw_across_pi() -> None:
    yaw = np.radians(np.array([170.0, 179.0, -179.0, -170.0]))
    rpy = np.column_stack((np.zeros(4), np.zeros(4), yaw))
    errors = axis_errors(rpy, [0.0, 0.0, math.radians(175.0)])
    assert np.allclose(np.degrees(errors[:, 2]), [-5.0, 4.0, 6.0, 15.0])


def test_settling_time_finds_first_run_of_at_least_hold() -> None:
    t = _grid(100.0, 0.1)
    e = np.full(t.size, 10.0)
    e[(t >= 10.0) & (t < 20.0)] = 0.0   # 10 s in band: too short
    e[t >= 40.0] = 0.0                  # 60 s in band
    # Entry interpolated between e = 10 at 39.9 s and e = 0 at 40 s: 39.94 s.
    assert settling_time(t, e, 6.0, 30.0) == pytest.approx(39.94, abs=1e-9)
    assert settling_time(t, np.full(t.size, 10.0), 6.0, 30.0) is None
    assert settling_time(t, np.zeros(t.size), 6.0, 30.0) == 0.0
    short = np.full(t.size, 10.0)
    short[t >= 80.0] = 0.0               # only 20 s before the end: never settles
    assert settling_time(t, short, 6.0, 30.0) is None


# ------------------------------------------------------------------ compute_metrics

DELAY = 10.0


def _first_order_trial(setpoint_deg, initial_deg, tau=5.0, duration=120.0, dt=DT, delay=DELAY):
    """Each axis rests at its initial value for ``delay`` s, then approaches its setpoint exponentially
    with time constant tau. With the step away from the record's edges, the centred average scales the
    exponential by a constant, so the 10 % and 90 % crossings shift equally: t_r = tau ln 9 exactly."""
    t = _grid(duration, dt)
    sp = np.radians(setpoint_deg)
    y0 = np.radians(initial_deg)
    rpy = sp + (y0 - sp) * np.exp(-np.maximum(t - delay, 0.0) / tau)[:, None]
    geodesic = np.linalg.norm(rpy - sp, axis=1)  # a stand-in with the same shape
    return t, rpy, sp, geodesic


def _reference_rise_time(t: np.ndarray, progress: np.ndarray) -> float:
    """Rise time by brute force: 301-sample boxcar by convolution (interior only, the crossings are
    far from the edges) and crossings found by scanning, independent of the module's code."""
    smooth = np.convolve(progress, np.ones(301) / 301.0, mode="same")

    def crossing(level: float) -> float:
        for k in range(200, t.size - 200):
            if smooth[k] >= level:
                return float(t[k - 1] + (level - smooth[k - 1]) / (smooth[k] - smooth[k - 1]) * DT)
        raise AssertionError("no crossing")

    return crossing(0.9) - crossing(0.1)


def test_first_order_step_has_known_rise_time_no_overshoot_and_settles() -> None:
    tau = 5.0
    t, rpy, sp, geo = _first_order_trial([30.0, 0.0, -20.0], [0.0, 0.0, 0.0], tau=tau)
    m = compute_metrics(t, rpy, sp, geo)
    # Rise time of a first-order step is tau ln 9 before smoothing; the average near the corner of
    # the step delays the 10 % crossing a little.
    expected = _reference_rise_time(t, 1.0 - np.exp(-np.maximum(t - DELAY, 0.0) / tau))
    assert tau * math.log(9.0) < expected < tau * math.log(9.0) + 0.5
    assert m["roll"]["t_r"] == pytest.approx(expected, abs=1e-6)
    assert m["yaw"]["t_r"] == pytest.approx(expected, abs=1e-6)
    assert m["pitch"]["t_r"] is None and m["pitch"]["M_p"] is None  # no commanded change
    assert m["roll"]["M_p"] == 0.0
    assert abs(m["roll"]["e_ss"]) < 1e-3
    # |e| = 30 exp(-(t - 10) / 5) <= 6 from t = 10 + 5 ln 5; the average scales the error by
    # k = sinh(1.5 / tau) / (1.5 / tau).
    k = math.sinh(1.5 / tau) / (1.5 / tau)
    assert m["roll"]["t_s"] == pytest.approx(DELAY + tau * math.log(5.0 * k), abs=0.02)
    assert m["pitch"]["t_s"] == 0.0
    assert m["theta_init_deg"] == pytest.approx(math.degrees(float(geo[0])))
    assert m["settled"] is True
    assert m["roll"]["initial_deg"] == pytest.approx(0.0) and m["roll"]["setpoint_deg"] == pytest.approx(30.0)


def test_overshoot_and_steady_state_error_of_known_signal() -> None:
    t = _grid(120.0)
    # Second-order-like response: goes to 1.25 x the change, then settles with a 2 degree offset.
    change = 40.0
    response = change * (1.0 + 0.25 * np.exp(-(t - 20.0) ** 2 / 20.0)) * (1.0 - np.exp(-t / 3.0))
    response = np.where(t > 60.0, change + 2.0, response)
    rpy = np.radians(np.column_stack((response, np.zeros(t.size), np.zeros(t.size))))
    sp = np.radians([change, 0.0, 0.0])
    geo = np.abs(rpy[:, 0] - sp[0])
    m = compute_metrics(t, rpy, sp, geo)
    assert m["roll"]["e_ss"] == pytest.approx(2.0, abs=1e-6)
    assert 20.0 < m["roll"]["M_p"] <= 25.5
    assert m["settled"] is True


def test_negative_change_rise_time_and_overshoot_are_positive() -> None:
    t, rpy, sp, geo = _first_order_trial([-45.0, 0.0, 0.0], [10.0, 0.0, 0.0], tau=4.0)
    m = compute_metrics(t, rpy, sp, geo)
    expected = _reference_rise_time(t, 1.0 - np.exp(-np.maximum(t - DELAY, 0.0) / 4.0))
    assert m["roll"]["t_r"] == pytest.approx(expected, abs=1e-6)
    assert m["roll"]["M_p"] == 0.0
    assert m["roll"]["change_deg"] == pytest.approx(-55.0)


def test_yaw_wrap_around_target_near_180_degrees() -> None:
    # Yaw from 150 to -170 degrees: the short way is +40 degrees through +-180.
    t = _grid(90.0)
    path = math.radians(150.0) + math.radians(40.0) * (1.0 - np.exp(-np.maximum(t - DELAY, 0.0) / 3.0))
    yaw = np.asarray(wrap_angle(path))
    rpy = np.column_stack((np.zeros(t.size), np.zeros(t.size), yaw))
    sp = np.radians([0.0, 0.0, -170.0])
    m = compute_metrics(t, rpy, sp, np.abs(path - math.radians(190.0)))
    assert m["yaw"]["change_deg"] == pytest.approx(40.0)
    expected = _reference_rise_time(t, 1.0 - np.exp(-np.maximum(t - DELAY, 0.0) / 3.0))
    assert m["yaw"]["t_r"] == pytest.approx(expected, abs=1e-6)
    assert abs(m["yaw"]["e_ss"]) < 1e-3
    assert m["yaw"]["M_p"] == 0.0


def test_oscillating_trial_does_not_settle() -> None:
    t = _grid(120.0)
    roll = math.radians(30.0) + math.radians(10.0) * np.sin(2.0 * math.pi * t / 20.0)
    rpy = np.column_stack((roll, np.zeros(t.size), np.zeros(t.size)))
    sp = np.radians([30.0, 0.0, 0.0])
    m = compute_metrics(t, rpy, sp, np.abs(roll - sp[0]))
    assert m["roll"]["t_s"] is None
    assert m["settled"] is False


def test_non_uniform_timestamps_match_uniform_result() -> None:
    t, rpy, sp, geo = _first_order_trial([30.0, -20.0, 60.0], [0.0, 5.0, -30.0], tau=6.0)
    uniform = compute_metrics(t, rpy, sp, geo)
    rng = np.random.default_rng(3)
    keep = np.sort(rng.choice(t.size, size=t.size // 2, replace=False))
    keep[0] = 0
    jittered = compute_metrics(t[keep], rpy[keep], sp, geo[keep])
    assert jittered["resampled"] is True and uniform["resampled"] is False
    for axis in ("roll", "pitch", "yaw"):
        assert jittered[axis]["t_r"] == pytest.approx(uniform[axis]["t_r"], abs=0.1)
        assert jittered[axis]["t_s"] == pytest.approx(uniform[axis]["t_s"], abs=0.1)
        assert jittered[axis]["e_ss"] == pytest.approx(uniform[axis]["e_ss"], abs=0.01)


def test_non_finite_rows_are_dropped_and_output_is_json_without_nan() -> None:
    t, rpy, sp, geo = _first_order_trial([30.0, 0.0, 0.0], [0.0, 0.0, 0.0], duration=60.0)
    rpy = rpy.copy()
    rpy[100, 1] = np.nan
    geo = geo.copy()
    geo[200] = np.inf
    m = compute_metrics(t, rpy, sp, geo)
    assert m["samples_dropped"] == 2
    text = json.dumps(m, allow_nan=False)  # raises on NaN / inf
    assert "roll" in json.loads(text)


def test_short_trial_is_not_settled_and_has_no_settling_time() -> None:
    t, rpy, sp, geo = _first_order_trial([10.0, 0.0, 0.0], [0.0, 0.0, 0.0], duration=5.0)
    m = compute_metrics(t, rpy, sp, geo)
    assert m["settled"] is False
    assert m["roll"]["t_s"] is None


def test_compute_metrics_rejects_bad_shapes() -> None:
    t = _grid(1.0)
    with pytest.raises(ValueError):
        compute_metrics(t, np.zeros((t.size, 2)), [0, 0, 0], np.zeros(t.size))
    with pytest.raises(ValueError):
        compute_metrics(t, np.zeros((t.size, 3)), [0, 0], np.zeros(t.size))
    with pytest.raises(ValueError):
        compute_metrics(t, np.zeros((t.size, 3)), [0, 0, 0], np.zeros(t.size - 1))
    with pytest.raises(ValueError):
        compute_metrics(t[:1], np.zeros((1, 3)), [0, 0, 0], np.zeros(1))


@given(st.floats(-170.0, 170.0), st.floats(-170.0, 170.0), st.floats(1.0, 10.0))
def test_metrics_are_finite_or_none_for_any_step(initial, setpoint, tau) -> None:
    t, rpy, sp, geo = _first_order_trial([setpoint, 0.0, setpoint], [initial, 0.0, initial], tau=tau,
                                         duration=40.0, dt=0.05)
    m = compute_metrics(t, rpy, sp, geo)
    json.dumps(m, allow_nan=False)
    for axis in ("roll", "yaw"):
        for key in ("t_r", "t_s", "e_ss", "M_p"):
            value = m[axis][key]
            assert value is None or math.isfinite(value)
        if m[axis]["t_r"] is not None:
            assert m[axis]["t_r"] >= 0.0
