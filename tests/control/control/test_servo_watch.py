"""The servo tracking watch (quadruped_control/control/servo_watch.py) on servos simulated beside it."""
import math

import numpy as np
import pytest

from quadruped_common.robot import JOINT_NAMES
from quadruped_control.control.servo_watch import ERROR, OK, WARN, ServoTrackingWatch, TrackingSettings
from quadruped_control.model.servo import rate_limited_lag_step

SETTINGS = TrackingSettings()
DT = 0.01


def commands(seconds, seed=0):
    """Strokes: every 0.3 s each joint jumps to a new target within +-0.4 rad (faster than the servos)."""
    rng = np.random.default_rng(seed)
    out, target = [], np.zeros(12)
    for k in range(int(round(seconds / DT))):
        if k % 30 == 0:
            target = rng.uniform(-0.4, 0.4, 12)
        out.append(target.copy())
    return np.array(out)


def servo(cmds, speed=SETTINGS.max_speed, tau=SETTINGS.time_constant, reverse=(), stuck=(), delay=1):
    """Shaft angles of servos following ``cmds`` (the command of tick k acts from tick k + ``delay``)."""
    q = np.zeros(12)
    out = []
    for k in range(len(cmds)):
        c = cmds[k - delay].copy() if k >= delay else np.zeros(12)
        for i in reverse:
            c[i] = -c[i]
        q = np.array([rate_limited_lag_step(a, b, speed, tau, DT) for a, b in zip(q, c)])
        for i in stuck:
            q[i] = 0.0
        out.append(q.copy())
    return np.array(out)


def watch(cmds, shaft, noise=0.0, seed=1, settings=SETTINGS):
    """Run the watch: command at t_k, the reading of t_k (stamped then) right after; levels each tick."""
    rng = np.random.default_rng(seed)
    w = ServoTrackingWatch(settings, JOINT_NAMES)
    w.start(0.0, np.zeros(12))
    levels = []
    for k in range(len(cmds)):
        t = DT * (k + 1)
        w.command(t, cmds[k])
        w.feedback(t, shaft[k] + noise * rng.standard_normal(12))
        levels.append(w.levels(t))
    return w, levels


def first(levels, joint, level):
    """Seconds until ``joint`` first reaches ``level`` (None: never)."""
    for k, row in enumerate(levels):
        if row[joint][1] >= level:
            return DT * (k + 1)
    return None


def test_healthy_servos_with_latency_and_noise_are_never_reported():
    cmds = commands(20.0)
    w, levels = watch(cmds, servo(cmds), noise=math.radians(0.3))
    assert all(level == OK for row in levels for _, level, _ in row)
    assert np.max(w.largest_rms) < SETTINGS.bound / 2


@pytest.mark.parametrize("fault", ["reversed", "stuck", "half speed"])
def test_a_faulty_servo_is_reported_by_name_within_two_seconds(fault):
    cmds = commands(3.0)
    joint = 7
    shaft = {"reversed": servo(cmds, reverse=(joint,)), "stuck": servo(cmds, stuck=(joint,)),
             "half speed": servo(cmds, speed=SETTINGS.max_speed / 2, tau=2 * SETTINGS.time_constant)}[fault]
    if fault == "half speed":  # only that joint is slow
        healthy = servo(cmds)
        healthy[:, joint] = shaft[:, joint]
        shaft = healthy
    # A slowed servo lags by less than the shipped 0.03 s latency band in most moves: only a tight band (a robot
    # whose command-to-reading latency is known and steady) finds it (docs/faults.md).
    tight = TrackingSettings(latency=0.01, bound=0.026, warn_after=0.0)
    _, levels = watch(cmds, shaft, noise=math.radians(0.3), settings=tight if fault == "half speed" else SETTINGS)
    warned, failed = first(levels, joint, WARN), first(levels, joint, ERROR)
    assert warned is not None and warned < 2.0, fault
    if fault != "half speed":  # a slowed servo lags in the fast moves only: WARN, held for report_hold
        assert failed is not None and failed < 1.5, fault
    else:
        assert all(row[joint][1] >= WARN for row in levels[int(round(warned / DT)):])  # reported from then on
    assert levels[-1][joint][0] == JOINT_NAMES[joint]
    others = [i for i in range(12) if i != joint]
    assert all(row[i][1] == OK for row in levels for i in others)


def test_a_stopped_watch_judges_nothing_and_bad_settings_are_refused():
    cmds = commands(2.0)
    w, _ = watch(cmds, servo(cmds, stuck=(0,)))
    w.stop()
    assert w.feedback(3.0, np.full(12, 1.0)) is None
    assert all(level == OK for _, level, _ in w.levels(3.0))
    with pytest.raises(ValueError, match="bound"):
        TrackingSettings(bound=0.0)
    with pytest.raises(ValueError, match="warn_after <= error_after"):
        TrackingSettings(warn_after=1.0, error_after=0.5)
