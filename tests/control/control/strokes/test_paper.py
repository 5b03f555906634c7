"""Tests of quadruped_control.stroke: the power/recovery cycle of section "Power and Recovery Stroke Cycle"."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from quadruped_common.config import ParameterError
from quadruped_common.robot import LEGS
from quadruped_control.control.strokes.base import cubic_time_profile
from quadruped_control.control.strokes.paper import PHASE_HOLD, PHASE_POWER, PHASE_RECOVERY, StrokeCycle
from quadruped_control.model.kinematics import UnreachableError, joint_angles, within_limits
from quadruped_control.model.params import load_robot_params

PARAMS = load_robot_params()
DT = 0.01
NOMINAL = {leg: tuple(PARAMS.nominal_foot_body(leg).tolist()) for leg in LEGS}
SLOW = (0.0, 0.0, -0.05)   # 2.5 cm in 0.5 s: stays inside the workspace
FAST = (0.0, 0.0, -1.0)    # leaves the workspace (6 cm below nominal) after ~6 steps


class Recorder:
    """Velocity-command callback returning a fixed velocity per leg and recording its calls."""

    def __init__(self, velocity=SLOW):
        self.velocity = velocity
        self.calls = []

    def __call__(self, leg, r):
        self.calls.append((leg, r))
        return self.velocity(leg) if callable(self.velocity) else self.velocity


def run(cycle, command, steps, dt=DT):
    """Advance ``steps`` times; returns per step (phases, times, foot positions (4x3), joints (4x3))."""
    log = []
    for _ in range(steps):
        cycle.advance(dt, command)
        log.append((cycle.pair_phase, cycle.pair_phase_time, np.array(cycle.foot_targets()),
                    np.array(cycle.joint_targets())))
    return log


def first_index(log, pair, phase, start=0):
    return next(k for k in range(start, len(log)) if log[k][0][pair] == phase)


# --------------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------------

def test_unreachable_nominal_foot_is_a_configuration_error():
    bad = dataclasses.replace(PARAMS, nominal_foot_leg=np.array([0.0, -0.5, -0.5]))
    with pytest.raises(ParameterError, match="nominal foot position of leg 1"):
        StrokeCycle(bad)


@pytest.mark.parametrize("pairs", [((1, 2), (1, 4)), ((1, 2),), ((1, 2), (3, 5))])
def test_bad_pairs(pairs):
    with pytest.raises(ParameterError, match="partition"):
        StrokeCycle(PARAMS, pairs)


def test_bad_timing_and_dt():
    cycle = StrokeCycle(PARAMS)
    for kwargs in (dict(t_rec=0.0), dict(t_pow_max=-1.0), dict(t_rec=math.nan)):
        with pytest.raises(ParameterError):
            cycle.set_timing(**kwargs)
    assert (cycle.t_rec, cycle.t_pow_max) == (1.5, 0.5)
    for dt in (-0.01, math.nan, math.inf):
        with pytest.raises(ValueError, match="dt"):
            cycle.advance(dt, Recorder())


# --------------------------------------------------------------------------------------------------
# Timing of the cycle
# --------------------------------------------------------------------------------------------------

def test_start_first_pair_half_recovery_second_pair_power():
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    command = Recorder()
    log = run(cycle, command, 80)
    # Step 0: the second pair starts its power phase, with the command latched at the nominal feet.
    assert log[0][0] == (PHASE_RECOVERY, PHASE_POWER)
    assert log[0][1] == (pytest.approx(DT), 0.0)
    assert command.calls[:2] == [(2, NOMINAL[2]), (4, NOMINAL[4])]
    # The first pair stays at the nominal pose for t_rec / 2 = 0.75 s, then starts its power phase.
    start = first_index(log, 0, PHASE_POWER)
    assert (start + 1) * DT == pytest.approx(0.75)
    for k in range(start + 1):
        for leg in (1, 3):
            np.testing.assert_array_equal(log[k][2][leg - 1], NOMINAL[leg])
    assert [leg for leg, _ in command.calls] == [2, 4, 1, 3]
    assert command.calls[2:] == [(1, NOMINAL[1]), (3, NOMINAL[3])]


def test_power_phase_integrates_the_held_velocity_and_lasts_t_pow_max():
    velocities = {1: (0.01, 0.0, -0.05), 2: (0.0, 0.02, -0.04), 3: (-0.01, 0.0, 0.03), 4: (0.0, -0.02, 0.05)}
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    log = run(cycle, Recorder(lambda leg: velocities[leg]), 60)
    # Second pair: power from step 0 (time 0) to step 50 (time 0.5 s), then recovery.
    assert [log[k][0][1] for k in range(50)] == [PHASE_POWER] * 50
    assert log[50][0][1] == PHASE_RECOVERY and log[50][1][1] == 0.0
    for k in range(51):  # eq. (foot_integration): r(t) = r0 + v t with v held
        for leg in (2, 4):
            np.testing.assert_allclose(log[k][2][leg - 1], np.add(NOMINAL[leg], np.multiply(velocities[leg], k * DT)),
                                       atol=1e-15)
    # The joint targets are the IK of the foot targets.
    np.testing.assert_allclose(log[30][3][1], joint_angles(log[30][2][1], 2, PARAMS), atol=1e-12)


def test_period_is_t_pow_max_plus_t_rec_and_pairs_alternate():
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    log = run(cycle, Recorder(), 700)
    for pair in (0, 1):
        starts = [k for k in range(1, len(log)) if log[k][0][pair] == PHASE_POWER
                  and log[k - 1][0][pair] != PHASE_POWER]
        if pair == 1:
            starts = [0] + starts
        assert np.all(np.diff(starts) == 200)  # 0.5 s power + 1.5 s recovery
        assert starts[0] == (74 if pair == 0 else 0)


def test_ik_failure_ends_the_power_phase_and_keeps_the_last_reachable_point():
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    log = run(cycle, Recorder(FAST), 20)
    end = first_index(log, 1, PHASE_RECOVERY)
    assert 1 < end < 50  # long before t_pow_max
    for leg in (2, 4):
        last = log[end][2][leg - 1]
        joint_angles(last, leg, PARAMS)  # reachable
        with pytest.raises(UnreachableError):
            joint_angles(last + np.array(FAST) * DT, leg, PARAMS)
        # The failing step kept the point of the step before, which had moved by v dt.
        np.testing.assert_array_equal(last, log[end - 1][2][leg - 1])
        np.testing.assert_allclose(last, log[end - 2][2][leg - 1] + np.array(FAST) * DT, atol=1e-15)


def test_recovery_retraces_the_stroke_with_the_cubic_profile_and_ends_at_rest_at_the_start():
    velocity = (0.03, -0.02, -0.05)
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    log = run(cycle, Recorder(velocity), 205)
    start = np.array(NOMINAL[2])
    end_point = log[50][2][1]
    np.testing.assert_allclose(end_point, start + 0.5 * np.array(velocity), atol=1e-14)
    length = np.linalg.norm(end_point - start)
    for k in range(51, 200):  # recovery steps 51..200, phase time (k - 50) dt
        point = log[k][2][1]
        s = cubic_time_profile((k - 50) * DT / 1.5)
        # On the stroke (a straight line here) at arc length L (1 - s) from the start.
        np.testing.assert_allclose(point, start + (1.0 - s) * (end_point - start), atol=1e-12)
        assert log[k][0][1] == PHASE_RECOVERY
    # Ends exactly at the start, then a new power phase starts there.
    assert log[199][0][1] == PHASE_RECOVERY and log[200][0][1] == PHASE_POWER
    np.testing.assert_array_equal(log[200][2][1], start)
    # Zero velocity at both ends: the first and last steps move far less than the mean speed.
    first_step = np.linalg.norm(log[51][2][1] - log[50][2][1])
    last_step = np.linalg.norm(log[200][2][1] - log[199][2][1])
    mean_step = length / 150
    assert first_step < 0.02 * mean_step and last_step < 0.03 * mean_step


def test_zero_velocity_command_gives_no_stroke_amplitude():
    cycle = StrokeCycle(PARAMS)
    log = run(cycle, Recorder((0.0, 0.0, 0.0)), 450)
    for entry in log:
        for leg in LEGS:
            np.testing.assert_array_equal(entry[2][leg - 1], NOMINAL[leg])
    # The phases still cycle.
    assert {entry[0][1] for entry in log} == {PHASE_POWER, PHASE_RECOVERY}


def test_zero_time_step_changes_nothing():
    cycle = StrokeCycle(PARAMS)
    command = Recorder()
    run(cycle, command, 10)
    before = (cycle.pair_phase, cycle.pair_phase_time, cycle.foot_targets())
    run(cycle, command, 5, dt=0.0)
    assert (cycle.pair_phase, cycle.pair_phase_time, cycle.foot_targets()) == before


def test_timing_changes_take_effect_at_the_next_phase_start():
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    command = Recorder()
    run(cycle, command, 10)                    # second pair 0.09 s into its power phase
    cycle.set_timing(t_rec=1.0, t_pow_max=0.3)
    log = run(cycle, command, 300)
    # The running power phase keeps its 0.5 s, the recovery then uses the new 1.0 s and the next power
    # phase the new 0.3 s.
    end = first_index(log, 1, PHASE_RECOVERY)
    assert end + 10 == 50
    restart = first_index(log, 1, PHASE_POWER, end)
    assert restart - end == 100
    second_end = first_index(log, 1, PHASE_RECOVERY, restart)
    assert second_end - restart == 30


def test_each_leg_keeps_its_own_velocity_and_velocity_commands_are_reported():
    velocities = {1: (0.0, 0.0, -0.05), 3: (0.0, 0.0, 0.05), 2: (0.01, 0.0, 0.0), 4: (-0.01, 0.0, 0.0)}
    cycle = StrokeCycle(PARAMS)
    cycle.advance(DT, Recorder(lambda leg: velocities[leg]))
    commands = cycle.velocity_commands
    assert commands[1] == velocities[2] and commands[3] == velocities[4]
    assert commands[0] == (0.0, 0.0, 0.0) and commands[2] == (0.0, 0.0, 0.0)


def test_non_finite_velocity_command_means_no_stroke():
    cycle = StrokeCycle(PARAMS)
    run(cycle, Recorder((math.nan, 0.0, 0.0)), 30)
    assert cycle.foot_targets() == [NOMINAL[leg] for leg in LEGS]


# --------------------------------------------------------------------------------------------------
# Hold and restart
# --------------------------------------------------------------------------------------------------

def test_hold_mid_power_retraces_to_nominal_and_restart_is_clean():
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    command = Recorder((0.0, 0.02, -0.05))
    run(cycle, command, 100)  # second pair in recovery, first pair in power
    assert cycle.pair_phase == (PHASE_POWER, PHASE_RECOVERY)
    calls = len(command.calls)
    positions = []
    for _ in range(200):
        cycle.hold(DT)
        assert cycle.pair_phase == (PHASE_HOLD, PHASE_HOLD)
        positions.append(np.array(cycle.foot_targets()))
    assert cycle.pair_phase_time == (pytest.approx(199 * DT), pytest.approx(199 * DT))
    # Feet back at nominal (within t_rec), smoothly (no jumps), and no new stroke was commanded.
    np.testing.assert_array_equal(positions[-1], np.array([NOMINAL[leg] for leg in LEGS]))
    assert np.max(np.abs(np.diff(positions, axis=0))) < 0.002
    assert len(command.calls) == calls
    assert cycle.velocity_commands == [(0.0, 0.0, 0.0)] * 4
    # Restart: first pair half recovery, second pair power at once.
    log = run(cycle, command, 80)
    assert log[0][0] == (PHASE_RECOVERY, PHASE_POWER)
    assert first_index(log, 0, PHASE_POWER) == 74


def test_restart_before_the_retract_completes_finishes_it_first():
    cycle = StrokeCycle(PARAMS, ((1, 3), (2, 4)), t_rec=1.5, t_pow_max=0.5)
    command = Recorder((0.0, 0.02, -0.05))
    run(cycle, command, 30)      # second pair 0.29 s into power
    cycle.hold(DT)
    cycle.hold(DT)               # retract just started
    log = run(cycle, command, 200)
    # The second pair keeps retracting (no jump), reaches the start, and only then starts a power phase.
    assert log[0][0][1] == PHASE_RECOVERY
    restart = first_index(log, 1, PHASE_POWER)
    np.testing.assert_array_equal(log[restart][2][1], NOMINAL[2])
    steps = np.diff([entry[2] for entry in log[:restart + 1]], axis=0)
    assert np.max(np.abs(steps)) < 0.002
    # The first pair was at nominal: it waits half a recovery from the restart.
    assert first_index(log, 0, PHASE_POWER) == 74


def test_reset_returns_to_nominal_and_initial_schedule():
    cycle = StrokeCycle(PARAMS)
    run(cycle, Recorder(), 120)
    cycle.reset()
    assert cycle.foot_targets() == [NOMINAL[leg] for leg in LEGS]
    log = run(cycle, Recorder(), 1)
    assert log[0][0] == (PHASE_RECOVERY, PHASE_POWER)


def test_recovery_falls_back_to_recorded_points_when_a_chord_is_unreachable():
    calls = {"fail": False}

    def picky_ik(point, leg):
        if calls["fail"]:
            raise UnreachableError("test: interpolated point rejected", leg)
        return tuple(joint_angles(point, leg, PARAMS).tolist())

    cycle = StrokeCycle(PARAMS, ik=picky_ik)
    run(cycle, Recorder((0.0, 0.0, -0.05)), 51)  # second pair stroke recorded, recovery started
    calls["fail"] = True
    log = run(cycle, Recorder((0.0, 0.0, -0.05)), 40)
    recorded = set(cycle.recorded_stroke(2))  # the second pair's first leg
    for entry in log:
        assert tuple(entry[2][1]) in recorded
        assert within_limits(entry[3][1], PARAMS)


@given(st.lists(st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)),
                min_size=4, max_size=4),
       st.lists(st.floats(0.0, 0.05), min_size=1, max_size=6), st.booleans())
def test_joint_targets_always_reachable_and_within_limits(velocities, steps, hold_midway):
    cycle = StrokeCycle(PARAMS)
    command = Recorder(lambda leg: velocities[leg - 1])
    schedule = (steps * 60)[:250]
    for index, dt in enumerate(schedule):
        if hold_midway and 100 <= index < 140:
            cycle.hold(dt)
        else:
            cycle.advance(dt, command)
        for leg, (r, q) in enumerate(zip(cycle.foot_targets(), cycle.joint_targets()), start=1):
            assert within_limits(q, PARAMS, tol=0.0)
            np.testing.assert_allclose(joint_angles(r, leg, PARAMS), q, atol=1e-9)


def test_a_stroke_longer_than_the_first_record_is_kept_whole_and_retraced():
    """The robot's strokes have no length limit: the record grows past its first 64 points."""
    cycle = StrokeCycle(PARAMS, t_rec=1.5, t_pow_max=1.5)
    slow = (0.0, 0.0, -0.01)  # 1.5 cm in 1.5 s: inside the workspace
    log = run(cycle, Recorder(slow), 151)
    end = first_index(log, 1, PHASE_RECOVERY)
    assert end == 150  # started at the first step, then 150 power steps of the second pair (legs 2, 4)
    for leg in (2, 4):
        stroke = cycle.recorded_stroke(leg)
        assert len(stroke) == 151
        assert stroke[0] == NOMINAL[leg]
        np.testing.assert_array_equal(stroke[-1], log[end][2][leg - 1])
        np.testing.assert_allclose(stroke[-1], np.array(NOMINAL[leg]) + 1.5 * np.array(slow), atol=1e-12)
    log = run(cycle, Recorder(slow), 150)  # the recovery, t_rec = 1.5 s
    for leg in (2, 4):
        assert cycle.foot_targets()[leg - 1] == NOMINAL[leg]
