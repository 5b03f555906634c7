"""quadruped_common.stall_probe: late wake-ups become stalls; stalls are matched to holds."""
import pytest

from quadruped_common.stall_probe import Stall, format_stall, read_stalls, stalled_time, watch


class FakeTime:
    """A clock that advances by each sleep plus a scripted extra delay."""

    def __init__(self, delays):
        self.now = 1000.0
        self.delays = list(delays)

    def sleep(self, seconds):
        self.now += seconds + (self.delays.pop(0) if self.delays else 0.0)

    def clock(self):
        return self.now

    def running(self):
        return bool(self.delays)


def test_only_late_wake_ups_beyond_the_threshold_are_stalls():
    fake = FakeTime([0.0, 0.004, 0.0, 0.055, 0.0, 0.0102])
    stalls = list(watch(period=0.002, threshold=0.010, keep_running=fake.running, monotonic=fake.clock,
                        wall=fake.clock, sleep=fake.sleep))
    assert [round(s.duration, 4) for s in stalls] == [0.055, 0.0102]
    assert stalls[0].end == pytest.approx(1000.0 + 4 * 0.002 + 0.004 + 0.055)


def test_stalls_round_trip_through_the_probe_file():
    stalls = [Stall(1.5, 1.56), Stall(10.0, 10.02)]
    lines = ["# header"] + [format_stall(s) for s in stalls] + [""]
    assert read_stalls(lines) == stalls


def test_stalled_time_adds_up_the_parts_of_a_stall_inside_the_window():
    # The hold of set A, run 1 in docs/sim_timing.md: one freeze the probe saw as three stalls.
    parts = [Stall(0.638, 0.6516), Stall(0.6526, 0.6635), Stall(0.6645, 0.7027)]
    assert stalled_time(parts, 0.6445, 0.7045) == pytest.approx(0.0071 + 0.0109 + 0.0382)
    assert stalled_time(parts, 0.0, 1.0) == pytest.approx(0.0136 + 0.0109 + 0.0382)
    assert stalled_time(parts, 0.71, 0.80) == 0.0
    assert stalled_time([Stall(0.0, 0.5), Stall(0.2, 0.3)], 0.0, 1.0) == pytest.approx(0.5)  # overlaps count once
