"""The fault campaign's figures from synthetic timelines: each definition of analysis.fault_metrics."""
import numpy as np
import pytest

from quadruped_control.analysis.fault_metrics import (FaultRecord, InjectionResult, Timeline, judge_injection,
                                                      kind_summary, limp_rows, lost_messages, motion_rows,
                                                      pulses_outside_limits, safe_rows, stamp_keys, tracking_rows)

FREQ = 50.0
TICK = 1e6 / (FREQ * 4096.0)
MIN_US, MAX_US = [500.0] * 12, [2500.0] * 12
DT = 0.01


def stroking(n, t0=0.0):
    """n chip rows of a stroking robot: every width moves by 3 ticks per step."""
    t = t0 + DT * np.arange(n)
    widths = 1500.0 + 3 * TICK * np.sin(np.arange(n))[:, None] * np.ones(12) + 10 * TICK * np.arange(n)[:, None] % 200
    return t, widths


def timeline(t, chip, armed=None, holding=None, commands=None):
    armed = np.ones(len(t), bool) if armed is None else armed
    holding = np.zeros(len(t), bool) if holding is None else holding
    commands = chip if commands is None else commands
    return Timeline(t, chip, t - 0.003, commands, t, armed, holding)


def test_pulses_outside_limits_ignores_limp_channels_and_tolerates_half_a_tick():
    widths = np.full((4, 12), 1500.0)
    widths[1, 3] = 0.0              # limp: no pulses, allowed
    widths[2, 0] = 2500.0 + 0.4 * TICK  # quantisation
    widths[3, 5] = 2600.0
    assert pulses_outside_limits(widths, MIN_US, MAX_US, TICK).tolist() == [False, False, False, True]
    widths[0, 0] = np.nan
    assert pulses_outside_limits(widths, MIN_US, MAX_US, TICK)[0]


def test_motion_rows_counts_moves_of_driven_channels_only():
    widths = np.full((4, 12), 1500.0)
    widths[1, 0] = 1500.0 + 0.4 * TICK  # below half a tick: no motion
    widths[2, 0] = 1600.0               # motion
    widths[3, :] = 0.0                  # going limp is not motion
    assert motion_rows(widths, TICK).tolist() == [False, False, True, False]


def test_safe_rows_hold_limp_or_controller_holding():
    t, widths = stroking(6)
    widths[3] = widths[2]        # held by the chip
    widths[4] = 0.0              # limp
    holding = np.zeros(6, bool)
    holding[5] = True            # the controller says it holds
    safe = safe_rows(timeline(t, widths, holding=holding), TICK)
    assert safe.tolist() == [True, False, False, True, True, True]


def test_tracking_needs_an_armed_stroking_controller_and_the_chip_on_its_commands():
    t, widths = stroking(5)
    armed = np.array([True, True, False, True, True])
    commands = widths.copy()
    commands[4] += 5 * TICK      # the chip does not produce what was commanded
    line = Timeline(t, widths, t - 0.003, commands, t, armed, np.zeros(5, bool))
    # row 4 matches none of the last three commands (the stroke moved on)
    assert tracking_rows(line, TICK).tolist() == [True, True, False, True, False]
    commands[4] = widths[3]  # the chip one command behind: still tracking
    widths[4] = widths[3]
    line = Timeline(t, widths, t - 0.003, commands, t, armed, np.zeros(5, bool))
    assert tracking_rows(line, TICK)[4]
    stale = Timeline(t, widths, t - 0.003, widths, t - 1.0, armed, np.zeros(5, bool))
    assert not tracking_rows(stale, TICK).any()  # telemetry older than 50 ms


def test_judge_a_controller_kill_held_by_the_watchdog_and_rearmed():
    t, widths = stroking(600)
    kill, back = 1.0, 4.0
    frozen = (t >= kill + 0.02) & (t < back + 0.05)  # commands in flight land, then nothing moves the chip
    widths[frozen] = widths[np.searchsorted(t, kill + 0.02) - 1]
    alive = ~((t >= kill) & (t < back))  # a dead controller publishes no telemetry
    line = Timeline(t, widths, t - 0.003, widths, t[alive], np.ones(alive.sum(), bool), np.zeros(alive.sum(), bool))
    record = FaultRecord("kill_attitude_controller", kill, back, "safe", unarmed=[(kill + 0.05, back)])
    result = judge_injection(line, record, MIN_US, MAX_US, FREQ)
    assert result.time_to_safe == pytest.approx(0.02, abs=DT + 1e-9)
    assert result.moved_unarmed == 0 and result.pulses_outside == 0
    assert result.time_to_recovery == pytest.approx(0.0, abs=DT + 1e-9)


def test_judge_counts_motion_while_unarmed_and_never_safe():
    t, widths = stroking(300)
    armed = ~((t >= 1.0) & (t < 2.0))  # disarmed, yet the legs keep moving
    record = FaultRecord("kill_attitude_controller", 1.0, 2.0, "safe", unarmed=[(1.0, 2.0)])
    result = judge_injection(timeline(t, widths, armed=armed), record, MIN_US, MAX_US, FREQ)
    assert result.moved_unarmed > 90
    # disarmed counts as safe for the controller, so the time to safe is 0 here; a robot that keeps
    # stroking while armed is never safe:
    result = judge_injection(timeline(t, widths), FaultRecord("imu_link_1", 1.0, 2.0, "safe"), MIN_US, MAX_US, FREQ)
    assert result.time_to_safe is None
    assert result.tracking_fraction == 1.0


def test_judge_no_recovery_when_the_chip_stays_limp():
    t, widths = stroking(800)
    widths[t >= 1.0] = 0.0
    record = FaultRecord("pca9685_power", 1.0, 2.0, "safe")
    result = judge_injection(timeline(t, widths, commands=stroking(800)[1]), record, MIN_US, MAX_US, FREQ)
    assert result.time_to_safe == 0.0 or result.time_to_safe < DT + 1e-9
    assert result.time_to_recovery is None


def test_judge_an_estop_on_the_limp_rows_only():
    t, widths = stroking(600)
    stop, armed_again = 1.0, 3.0
    held = (t >= stop) & (t < stop + 0.03)
    widths[held] = widths[np.searchsorted(t, stop) - 1]  # held 30 ms (the chip's last pulses), then limp
    widths[(t >= stop + 0.03) & (t < armed_again + 0.02)] = 0.0  # limp until the first command after the arm
    armed = ~((t >= stop + 0.01) & (t < armed_again))
    line = timeline(t, widths, armed=armed)
    estop = FaultRecord("estop", stop, armed_again, "stop", unarmed=[(stop + 0.15, armed_again)], limp=True)
    assert limp_rows(line).sum() == np.count_nonzero((t >= stop + 0.03) & (t < armed_again + 0.02))
    result = judge_injection(line, estop, MIN_US, MAX_US, FREQ)
    assert result.time_to_safe == pytest.approx(0.03, abs=DT + 1e-9)  # a held chip is not an e-stop
    assert result.moved_unarmed == 0 and result.time_to_recovery == pytest.approx(0.0, abs=DT + 1e-9)
    kept_pulses = timeline(t, stroking(600)[1], armed=armed)  # disarmed, the chip never limp
    assert judge_injection(kept_pulses, estop, MIN_US, MAX_US, FREQ).time_to_safe is None


def test_a_command_sent_while_armed_may_land_after_the_disarm():
    t, widths = stroking(300)
    disarm = 1.0
    armed = t < disarm
    commands = widths.copy()
    late = np.searchsorted(t, disarm + 0.04)
    widths[np.searchsorted(t, disarm):late] = widths[np.searchsorted(t, disarm) - 2]
    widths[late:] = commands[np.searchsorted(t, disarm) - 1]  # the last armed command lands 40 ms late
    line = Timeline(t, widths, t, commands, t, armed, np.zeros(len(t), bool))
    record = FaultRecord("heartbeat_lost", disarm, 2.5, "stop", unarmed=[(disarm + 0.15, 2.5)])
    assert judge_injection(line, record, MIN_US, MAX_US, FREQ).moved_unarmed == 0
    widths[late + 10:] += 5 * TICK  # a later move matches no command sent while armed
    assert judge_injection(line, record, MIN_US, MAX_US, FREQ).moved_unarmed == 1


def test_a_stop_that_tracks_again_before_the_operator_arms_is_never_safe():
    t, widths = stroking(600)
    lost, armed_again = 1.0, 4.0
    back = (t >= lost) & (t < 2.0)
    widths[back] = widths[np.searchsorted(t, lost) - 1]  # disarmed and held ...
    armed = ~back                                          # ... then armed again by itself at 2 s
    record = FaultRecord("heartbeat_lost", lost, armed_again, "stop", unarmed=[(lost + 0.15, armed_again)])
    result = judge_injection(timeline(t, widths, armed=armed), record, MIN_US, MAX_US, FREQ)
    assert result.time_to_safe is None
    assert kind_summary([result], "stop")["never_safe"] == 1
    assert result.moved_unarmed > 150  # from 2 s to the arm at 4 s, the legs moved without an arm command


def test_lost_messages_and_summary():
    received = np.arange(0.0, 10.0, 0.005)
    recorded = np.delete(received, [100, 101, 1500])
    assert lost_messages(received, stamp_keys(recorded), 0.0, 5.0) == 2
    assert lost_messages(received, stamp_keys(received), 0.0, 10.0) == 0
    rows = [InjectionResult("x", 0.0, 0.05, 0.3, 0.0, 0, 0, 0), InjectionResult("x", 5.0, 0.08, 1.1, 0.0, 0, 0, 2),
            InjectionResult("x", 9.0, None, None, 0.0, 1, 3, None)]
    summary = kind_summary(rows, "safe")
    assert summary["injections"] == 3 and summary["never_safe"] == 1
    assert summary["time_to_safe_max"] == 0.08
    assert summary["recovered"] == 2 and summary["time_to_recovery_median"] == pytest.approx(0.7)
    assert summary["pulses_outside"] == 1 and summary["moved_unarmed"] == 3
    assert summary["lost_before"] == 2 and summary["lost_measured"] == 2


def test_timeline_refuses_mismatched_series():
    with pytest.raises(ValueError):
        Timeline(np.zeros(3), np.zeros((2, 12)), np.zeros(0), np.zeros((0, 12)), np.zeros(0), np.zeros(0),
                 np.zeros(0))
