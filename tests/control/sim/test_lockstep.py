"""Lock-step bookkeeping: simulated clock, answered steps, trajectory comparison."""
import threading
import time

import numpy as np
import pytest

from quadruped_control.sim.lockstep import (AnswerTracker, SimClock, compare_trajectories, main, missing_links,
                                            widths_match)


def test_sim_clock_is_exact_multiples():
    clock = SimClock(1.0, 0.01)
    assert clock.time(0) == 1.0
    assert clock.time(300) == 1.0 + 300 * 0.01
    with pytest.raises(ValueError):
        SimClock(0.0, 0.01)
    with pytest.raises(ValueError):
        SimClock(1.0, float("nan"))


def test_widths_match_within_half_a_tick_and_ignores_nan_commands():
    chip = np.full(12, 1500.0)
    command = chip + 2.0
    assert widths_match(chip, command, 2.5)
    command[3] = 1510.0
    assert not widths_match(chip, command, 2.5)
    command[3] = np.nan
    assert widths_match(chip, command, 2.5)
    with pytest.raises(ValueError):
        widths_match(chip, command[:11], 2.5)


def test_unarmed_step_is_answered_by_the_controller_state():
    tracker = AnswerTracker(2.5)
    chip = np.zeros(12)
    assert not tracker.answered(1.01, chip)
    tracker.on_state(1.0, armed=False)  # an older step
    assert not tracker.answered(1.01, chip)
    tracker.on_state(1.01, armed=False)
    assert tracker.answered(1.01, chip)


def test_armed_step_needs_its_command_on_the_chip():
    tracker = AnswerTracker(2.5)
    command = np.full(12, 1600.0)
    tracker.on_state(1.01, armed=True)  # the state overtook its command
    assert not tracker.answered(1.01, np.full(12, 1600.0))
    tracker.on_command(command)
    assert not tracker.answered(1.01, np.full(12, 1500.0))  # pwm_node has not written it yet
    assert tracker.answered(1.01, np.full(12, 1601.0))


def test_wait_returns_when_answered_from_another_thread_or_times_out():
    tracker = AnswerTracker(2.5)
    chip = np.zeros(12)
    assert not tracker.wait(2.0, lambda: chip, timeout=0.02)
    threading.Timer(0.02, tracker.on_state, args=(2.0, False)).start()
    started = time.monotonic()
    assert tracker.wait(2.0, lambda: chip, timeout=2.0)
    assert time.monotonic() - started < 1.0


def test_compare_trajectories_on_common_stamps(tmp_path):
    stamps = np.arange(1000, 3000, 10, dtype=np.int64)
    q = np.column_stack([np.sin(stamps * 1e-3), np.zeros((len(stamps), 2)), np.cos(stamps * 1e-3)])
    other = q.copy()
    other[50, 0] += 5e-7
    result = compare_trajectories(stamps, q, stamps[5:], other[5:])
    assert result.common == len(stamps) - 5 and result.only_first == 5 and result.only_second == 0
    assert result.max_difference == pytest.approx(5e-7)
    assert result.same(1e-6, 100) and not result.same(1e-7, 100) and not result.same(1e-6, 1000)
    np.savez(tmp_path / "a.npz", stamp_ns=stamps, quaternion=q)
    np.savez(tmp_path / "b.npz", stamp_ns=stamps, quaternion=other)
    assert main([str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--min-samples", "100"]) == 0
    assert main([str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--tolerance", "1e-7",
                 "--min-samples", "100"]) == 1
    assert compare_trajectories([], [], stamps, q).same(1.0, 0) is False


def _bus(*entries):
    """getBusInfo rows: (id, endpoint, direction, transport, topic, connected, info)."""
    return [(i, endpoint, direction, "TCPROS", topic, connected, "")
            for i, (endpoint, direction, topic, connected) in enumerate(entries)]


def test_missing_links_needs_both_ends_of_each_link():
    links = [("/vn100_node", "/imu/data", "/attitude_controller")]
    subscriber_only = {"/attitude_controller": _bus(("http://vn100:1", "i", "/imu/data", True)),
                       "/vn100_node": _bus()}
    # The subscriber already shows the connection, the publisher has not listed it yet: rospy would
    # drop a message published now, so the link is not up.
    assert missing_links(links, subscriber_only.get) == [
        "/vn100_node does not publish /imu/data to /attitude_controller yet"]
    both = dict(subscriber_only, **{"/vn100_node": _bus(("/attitude_controller", "o", "/imu/data", True))})
    assert missing_links(links, both.get) == []
    # An outbound connection to another node, or on another topic, does not count.
    other = dict(subscriber_only, **{"/vn100_node": _bus(("/rosbag", "o", "/imu/data", True),
                                                         ("/attitude_controller", "o", "/imu/raw", True))})
    assert len(missing_links(links, other.get)) == 1


def test_missing_links_reports_nodes_that_are_down_once():
    links = [("/sim_node", "/clock", "/pwm_node"), ("/attitude_controller", "/servo_command", "/pwm_node")]
    up = {"/sim_node": _bus(("/pwm_node", "o", "/clock", True)),
          "/attitude_controller": _bus(("/pwm_node", "o", "/servo_command", True))}
    assert missing_links(links, up.get) == ["/pwm_node not up"]
    disconnected = dict(up, **{"/pwm_node": _bus(("http://sim:1", "i", "/clock", False),
                                                 ("http://ctl:1", "i", "/servo_command", True))})
    assert missing_links(links, disconnected.get) == ["/pwm_node not connected to /clock"]
