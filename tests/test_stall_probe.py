"""quadruped_common.stall_probe: late wake-ups become stalls; stalls are matched to holds."""
import pytest

from quadruped_common.stall_probe import Stall, format_stall, read_stalls, stall_before, watch


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


def test_a_hold_is_matched_to_the_longest_stall_in_its_window():
    stalls = [Stall(9.80, 9.85), Stall(9.95, 9.97), Stall(9.96, 10.01), Stall(10.2, 10.3)]
    assert stall_before(10.0, stalls, 0.06) == Stall(9.96, 10.01)  # overlaps the onset
    assert stall_before(10.0, stalls[:2], 0.06) == Stall(9.95, 9.97)
    assert stall_before(10.0, stalls[:1], 0.06) is None  # ended before the window
    assert stall_before(10.0, stalls[3:], 0.06) is None  # after the hold began
