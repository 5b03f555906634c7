"""quadruped_common.imu_plausibility across samples: RateChangeCheck (a rate inside the gyro's range can
still be impossible) and the limits that configure it."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.imu_plausibility import ImplausibleSample, RateChangeCheck, SensorLimits

LIMITS = SensorLimits(max_angular_acceleration=200.0, rate_change_margin=0.1, rate_change_confirm=3)
DT = 0.005  # 200 Hz


def test_a_rate_spike_inside_the_gyro_range_is_implausible():
    check = RateChangeCheck(LIMITS)
    check.check(0.0, (0.1, 0.0, 0.0))
    with pytest.raises(ImplausibleSample) as info:
        check.check(DT, (0.1, 12.0, 0.0))  # 12 rad/s in 5 ms: 2,400 rad/s^2, far inside the 36.7 rad/s range
    assert info.value.reason == "angular acceleration" and "rad/s^2" in str(info.value)
    check.check(2 * DT, (0.1, 0.0, 0.0))  # the reference is still the last good sample
    assert check.confirmed == 0


@settings(max_examples=50, deadline=None)
@given(st.floats(0.0, 150.0), st.floats(-1.0, 1.0), st.integers(0, 2))
def test_any_motion_the_body_can_make_passes(acceleration, direction, axis):
    """Rates ramping at up to 150 rad/s^2 (below the 200 rad/s^2 limit), with gyro noise, never drop."""
    check = RateChangeCheck(LIMITS)
    rng = np.random.default_rng(0)
    for k in range(200):
        rate = np.zeros(3)
        rate[axis] = math.copysign(acceleration, direction) * k * DT
        check.check(k * DT, rate + rng.normal(scale=0.01, size=3))


def test_a_real_jump_is_accepted_after_agreeing_samples():
    check = RateChangeCheck(LIMITS)
    check.check(0.0, (0.0, 0.0, 0.0))
    for k in (1, 2):
        with pytest.raises(ImplausibleSample):
            check.check(k * DT, (0.0, 0.0, 5.0))  # a knock against the tank wall: 5 rad/s at once
    check.check(3 * DT, (0.0, 0.0, 5.02))  # the third agreeing sample: the body really spins now
    assert check.confirmed == 1
    check.check(4 * DT, (0.0, 0.0, 5.0))


def test_samples_without_a_usable_time_are_not_judged():
    check = RateChangeCheck(LIMITS)
    check.check(1.0, (0.0, 0.0, 0.0))
    check.check(math.nan, (9.0, 9.0, 9.0))
    check.check(0.5, (9.0, 9.0, 9.0))  # older than the reference
    with pytest.raises(ImplausibleSample):
        check.check(1.0 + DT, (9.0, 9.0, 9.0))  # the reference did not move
    check.reset()
    check.check(2.0, (9.0, 9.0, 9.0))


@pytest.mark.parametrize("field, value", [("max_angular_acceleration", 0.0), ("rate_change_margin", math.inf),
                                          ("rate_change_confirm", 0), ("rate_change_confirm", 1.5)])
def test_limits_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        SensorLimits(**{field: value})
