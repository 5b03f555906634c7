"""Tests of the pure node-support helpers: statistics, rate, IMU sample checks, joint velocity filter."""
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from quadruped_common.monitoring import (LowPassDifferentiator, RateMonitor, WindowStatistics,
                                          imu_sample_problem)

UNIT = (0.0, 0.0, 0.0, 1.0)


def test_window_statistics_percentiles_and_window():
    stats = WindowStatistics(size=100)
    assert math.isnan(stats.percentile(50))
    for value in range(1000):
        stats.add(float(value))
    assert len(stats) == 100  # only the last 100 samples: 900..999
    assert stats.percentile(50) == pytest.approx(949.5)
    assert stats.maximum() == 999.0
    stats.add(math.nan)  # ignored, not poisoning the percentiles
    assert stats.summary(scale=2.0)["max"] == 1998.0
    with pytest.raises(ValueError):
        WindowStatistics(size=0)


def test_rate_monitor_measures_100_hz():
    monitor = RateMonitor(window=1.0)
    for k in range(500):
        monitor.tick(k * 0.01)
    assert monitor.rate(4.99) == pytest.approx(100.0, rel=1e-6)
    assert monitor.rate(10.0) == 0.0  # everything left the window


@pytest.mark.parametrize("q, w, stamp, expected", [
    (UNIT, (0, 0, 0), 10.0, None),
    ((math.nan, 0, 0, 1), (0, 0, 0), 10.0, "non-finite"),
    (UNIT, (0, math.inf, 0), 10.0, "angular rate has non-finite"),
    ((0, 0, 0, 0.9), (0, 0, 0), 10.0, "quaternion norm"),
    ((0, 0, 0, 0), (0, 0, 0), 10.0, "quaternion norm"),
    (UNIT, (0, 0, 0), 9.9, "stale"),
    (UNIT, (0, 0, 0), 10.1, "future"),
])
def test_imu_sample_problem(q, w, stamp, expected):
    problem = imu_sample_problem(q, w, stamp, now=10.0, max_age=0.05)
    if expected is None:
        assert problem is None
    else:
        assert expected in problem


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4),
       st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3))
def test_imu_sample_problem_never_raises(q, w):
    result = imu_sample_problem(q, w, 0.0, 0.0, 0.05)
    assert result is None or isinstance(result, str)


def test_differentiator_converges_to_ramp_slope_and_survives_nan():
    diff = LowPassDifferentiator(size=2, time_constant=0.02)
    for k in range(200):
        t = k * 0.01
        velocity = diff.update(t, [0.5 * t, math.nan if 50 <= k < 60 else -t])
    assert velocity == pytest.approx([0.5, -1.0], rel=1e-6)
    assert np.all(np.isfinite(velocity))


def test_hold_episodes_count_runs_and_time_held():
    from quadruped_common.monitoring import HoldEpisodes

    holds = HoldEpisodes()
    # 10 ms ticks: stroking, then a 7-tick stale gap, stroking, a 2-tick controller error, stroking.
    pattern = [False] * 5 + [True] * 7 + [False] * 3 + [True] * 2 + [False] * 2
    kinds = ["", ] * 5 + ["stale IMU"] * 7 + [""] * 3 + ["controller"] * 2 + [""] * 2
    for k, (holding, kind) in enumerate(zip(pattern, kinds)):
        holds.update(0.01 * k, holding, kind)
    assert holds.episodes == 2
    assert holds.held_ticks == 9
    assert holds.time_held == pytest.approx(0.09)
    assert holds.episodes_of("stale IMU") == 1 and holds.episodes_of("controller") == 1
    assert not holds.holding


def test_hold_episodes_ignore_bad_time_and_count_an_open_episode():
    from quadruped_common.monitoring import HoldEpisodes

    holds = HoldEpisodes()
    holds.update(1.0, True, "stale IMU")
    holds.update(float("nan"), True, "stale IMU")
    holds.update(0.5, True, "stale IMU")  # backwards: no time
    holds.update(1.25, True, "stale IMU")
    assert holds.episodes == 1 and holds.held_ticks == 4
    assert holds.time_held == pytest.approx(0.25)
    assert holds.holding


def test_hold_kind_recognises_the_stale_wording_of_time_problem():
    from quadruped_common.monitoring import STALE_IMU, hold_kind, time_problem
    assert hold_kind(time_problem(0.0, 0.08, 0.05)) == STALE_IMU
    assert hold_kind("no IMU sample received yet") == "other"
