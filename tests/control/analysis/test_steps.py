"""The step test's reading of a record (quadruped_control.analysis.steps)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_control.analysis import steps

DEG = math.radians(1.0)


def _record(before_deg: float, after_deg: float, shape, hold: float = 20.0, duration: float = 120.0):
    """A roll record at 100 Hz: held at ``before_deg`` for ``hold`` s, then after the step at ``hold`` the
    error to ``after_deg`` is ``shape(s)`` deg, s the time from the step."""
    t = np.arange(0.0, hold + duration + 1e-9, 0.01)
    roll = np.where(t < hold, before_deg, after_deg + shape(np.maximum(t - hold, 0.0)))
    rpy = np.column_stack([np.radians(roll), np.zeros_like(t), np.zeros_like(t)])
    step = steps.Step(hold, (before_deg * DEG, 0.0, 0.0), (after_deg * DEG, 0.0, 0.0))
    return t, rpy, step


def test_a_first_order_return_settles_when_its_error_enters_each_band() -> None:
    t, rpy, step = _record(45.0, 33.0, lambda s: 12.0 * np.exp(-s / 10.0))
    response = steps.step_response(t, rpy, step)
    # 12 exp(-s / 10) = 6 at 10 ln 2 and = 2 at 10 ln 6; the 3 s centred average of an exponential is it times
    # sinh(0.15) / 0.15, 0.4 % more, which moves each entry by 0.04 s
    assert response.settle_6 == pytest.approx(10.0 * math.log(2.0), abs=0.08)
    assert response.settle_2 == pytest.approx(10.0 * math.log(6.0), abs=0.08)
    assert response.overshoot_deg == 0.0 and response.held_error_deg == pytest.approx(0.0)
    assert response.axis == "roll" and response.towards_upright and response.duration == pytest.approx(120.0)


def test_an_overshoot_is_measured_past_the_new_setpoint_in_the_steps_direction() -> None:
    # away from upright (45 -> 57): the error rises from -12 deg along a parabola to a smooth peak of +4 deg at
    # 10 s, then decays as a Gaussian of 20 s: the 6 deg band is entered early and kept, the 2 deg band only once
    # the overshoot has decayed
    def shape(s):
        return np.where(s < 10.0, 4.0 - 16.0 * ((s - 10.0) / 10.0) ** 2, 4.0 * np.exp(-((s - 10.0) / 20.0) ** 2))

    t, rpy, step = _record(45.0, 57.0, shape)
    response = steps.step_response(t, rpy, step)
    assert not response.towards_upright
    # the 3 s centred average lowers the peak, by at most what it takes off the steeper side's parabola:
    # 0.16 x 1.5^2 / 3 = 0.12 deg
    assert 4.0 - 0.12 <= response.overshoot_deg <= 4.0
    assert response.settle_6 == pytest.approx(10.0 - 10.0 * math.sqrt(10.0 / 16.0), abs=0.1)
    assert response.settle_2 == pytest.approx(10.0 + 20.0 * math.sqrt(math.log(2.0)), abs=0.2)


def test_a_response_that_never_reaches_the_band_has_no_settling_time_and_a_badly_held_tilt_shows() -> None:
    t, rpy, step = _record(45.0, 33.0, lambda s: 12.0 - 0.01 * s)
    rpy[(t > 12.0) & (t < 20.0), 0] += 2.0 * DEG  # the tilt before the step held 2 deg off for its last 8 s
    response = steps.step_response(t, rpy, step)
    assert response.settle_6 is None and response.settle_2 is None
    assert response.held_error_deg == pytest.approx(2.0 * 8.0 / 10.0, abs=0.05)
    with pytest.raises(ValueError, match="fewer than two attitude samples"):
        steps.step_response(t, rpy, steps.Step(float(t[-1]) + 1.0, step.before, step.after))


def test_find_steps_keeps_real_changes_and_ignores_republished_setpoints() -> None:
    t = np.arange(6) * 1.0
    setpoints = np.radians([[0, 0, 0], [0, 0, 0.1], [45, 0, 0.1], [45, 0, 0.1], [45, 33, 0.1], [45, 33, 180]])
    setpoints[5, 2] = math.pi  # and yaw from +180 to -180 is no change
    setpoints = np.vstack([setpoints, np.radians([[45, 33, -180]])])
    found = steps.find_steps(np.arange(7) * 1.0, setpoints)
    assert [s.time for s in found] == [2.0, 4.0, 5.0]
    assert found[0].axis == 0 and found[0].single_axis and not found[0].towards_upright
    assert found[1].axis == 1 and found[1].single_axis
    assert found[2].axis == 2  # 0.1 -> 180 deg of yaw
    both = steps.Step(0.0, (45 * DEG, 0.0, 0.0), (33 * DEG, 10 * DEG, 0.0))
    assert both.axis == 0 and not both.single_axis and both.towards_upright
    assert steps.find_steps(t[:1], setpoints[:1]) == []


@pytest.mark.parametrize("model, robot, expected", [
    (10.0, 10.0, True), (19.9, 10.0, True), (20.1, 10.0, False), (5.0, 10.0, True), (4.9, 10.0, False),
    (None, None, True), (None, 10.0, False), (10.0, None, False),
    (0.0, 0.9, True), (0.0, 1.1, False)])  # below the 0.5 s floor a time counts as 0.5 s
def test_two_settling_times_agree_within_a_factor_two_or_when_neither_settles(model, robot, expected) -> None:
    assert steps.agrees(model, robot) is expected


def _roll_step(time: float) -> steps.Step:
    return steps.Step(time, (45.0 * DEG, 0.0, 0.0), (33.0 * DEG, 0.0, 0.0))


def test_a_response_ends_at_the_next_step_the_records_end_or_the_first_stop_after_it() -> None:
    sequence = [_roll_step(100.0), _roll_step(200.0), _roll_step(300.0)]
    assert steps.response_ends(sequence, [], 350.0) == [200.0, 300.0, 350.0]
    # disarmed at 250 s: the second step's response stops there, the third is read in full
    assert steps.response_ends(sequence, [250.0, 250.01, 250.02], 350.0) == [200.0, 250.0, 350.0]


def test_a_step_soon_after_a_stop_is_not_read() -> None:
    sequence = [_roll_step(100.0), _roll_step(200.0)]
    # a hold within HOLD_CHECK before the second step, and one at the first step's instant
    ends = steps.response_ends(sequence, [200.0 - steps.HOLD_CHECK + 0.5], 300.0)
    assert ends == [200.0 - steps.HOLD_CHECK + 0.5, None]
    assert steps.response_ends(sequence, [100.0], 300.0) == [None, 300.0]
    # a stop earlier than HOLD_CHECK before the step leaves it whole
    assert steps.response_ends(sequence, [100.0 - steps.HOLD_CHECK - 0.5], 300.0) == [200.0, 300.0]


def test_a_response_shorter_than_the_settling_hold_is_not_judged() -> None:
    t, rpy, step = _record(45.0, 33.0, lambda s: 12.0 * np.exp(-s / 10.0), duration=40.0)
    assert steps.judged(steps.step_response(t, rpy, step))
    short = steps.step_response(t, rpy, step, end=step.time + 29.0)
    assert short.settle_6 is None and not steps.judged(short)  # it cannot settle in 29 s, whatever it does
