"""Every VN-100 sample is checked against the sensor's range before /imu/data."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_drivers.vn100.conversions import (ACCEL_RANGE_M_S2, GYRO_RANGE_RAD_S, ImplausibleSample,
                                                 SensorLimits, vn_to_ros)
from quadruped_drivers.vn100.protocol import Vn100Sample
from quadruped_drivers.vn100.sample_gate import DROP_REASONS, TIME_ANOMALY, SampleGate, backdate_seconds

LEVEL = (0.0, 0.0, 0.0, 1.0)
GRAVITY = (0.0, 0.0, -9.81)
LIMITS = SensorLimits(max_angular_rate=36.652, max_acceleration=164.75)


def good(ns: int = 0, rate=(0.1, 0.0, 0.0)) -> Vn100Sample:
    return Vn100Sample(time_startup_ns=ns, quaternion_xyzw=LEVEL, angular_rate=rate, acceleration=GRAVITY)


def test_datasheet_ranges():
    assert GYRO_RANGE_RAD_S == pytest.approx(math.radians(2000))
    assert ACCEL_RANGE_M_S2 == pytest.approx(16 * 9.80665)


@pytest.mark.parametrize("rate, accel, reason", [
    ((1e3, 0, 0), GRAVITY, "angular rate range"),
    ((0, 0, -3.4e38), GRAVITY, "angular rate range"),
    ((0, 1e154, 0), GRAVITY, "angular rate range"),
    ((0, 0, 0), (0, 0, -200.0), "acceleration range"),
    ((0, float("nan"), 0), GRAVITY, "non-finite"),
])
def test_out_of_range_sample_is_implausible(rate, accel, reason):
    with pytest.raises(ImplausibleSample) as info:
        vn_to_ros(LEVEL, rate, accel, LIMITS)
    assert info.value.reason == reason


def test_at_the_range_is_accepted():
    reading = vn_to_ros(LEVEL, (36.652, -36.652, 0), (164.75, 0, -164.75), LIMITS)
    assert reading.angular_velocity[1] == pytest.approx(36.652)


def test_limits_reject_nonsense():
    for bad in (float("nan"), float("inf"), 0.0, -1.0, True, "1"):
        with pytest.raises(ValueError):
            SensorLimits(max_angular_rate=bad)


float32 = st.floats(width=32)


@settings(max_examples=300, deadline=None)
@given(st.tuples(*[float32] * 4), st.tuples(*[float32] * 3), st.tuples(*[float32] * 3))
def test_any_float32_sample_is_in_range_or_rejected(q, w, a):
    try:
        reading = vn_to_ros(q, w, a, LIMITS)
    except ImplausibleSample as exc:
        assert exc.reason in DROP_REASONS
        return
    assert np.all(np.isfinite(reading.orientation_xyzw))
    assert np.all(np.abs(reading.angular_velocity) <= LIMITS.max_angular_rate)
    assert np.all(np.abs(reading.linear_acceleration) <= LIMITS.max_acceleration)
    assert abs(np.linalg.norm(reading.orientation_xyzw) - 1.0) < 1e-9


def test_backdate_handles_absurd_stamps():
    assert backdate_seconds(10_000_000, 5_000_000, 0.1) == pytest.approx(0.005)
    assert backdate_seconds(10**19, 5_000_000, 0.1) is None  # a colliding packet seen in the fuzz campaign
    assert backdate_seconds(5_000_000, 10**19, 0.1) is None
    assert backdate_seconds(None, 5, 0.1) is None
    assert backdate_seconds(float("nan"), 5, 0.1) is None
    assert backdate_seconds(True, 0, 0.1) is None


def test_gate_drops_counts_and_keeps_the_stream():
    gate = SampleGate(LIMITS, max_backdate=0.1)
    burst = [good(0), good(5_000_000, rate=(1e6, 0, 0)), Vn100Sample(time_startup_ns=7), good(10_000_000)]
    out = gate.process(burst)
    assert len(out) == 2
    assert [offset for _, offset in out] == pytest.approx([0.01, 0.0])
    assert gate.counts["angular rate range"] == 1 and gate.counts["missing field"] == 1
    assert gate.dropped == 2 and gate.accepted == 2
    assert gate.last_drop.startswith("missing field")


def test_gate_publishes_good_samples_of_a_burst_ending_in_a_bad_stamp():
    gate = SampleGate(LIMITS, max_backdate=0.1)
    out = gate.process([good(5_000_000), good(10**19)])
    assert [offset for _, offset in out] == [0.0, 0.0]
    assert gate.counts[TIME_ANOMALY] == 1


class _Weird:
    """An object a decoding bug might hand over: attributes of the wrong type."""

    time_startup_ns = "x"
    quaternion_xyzw = ("a", 0, 0, 1)
    angular_rate = (0, 0, 0)
    acceleration = (0, 0, 0)


def test_gate_never_raises():
    gate = SampleGate(LIMITS)
    assert gate.process([_Weird(), good(1)]) != []  # the good sample still passes
    assert gate.counts["internal error"] == 1


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(min_size=48, max_size=48), min_size=1, max_size=8))
def test_gate_on_random_payloads(payloads):
    gate = SampleGate(LIMITS, max_backdate=0.1)
    samples = []
    for payload in payloads:
        ns, *values = struct.unpack("<Q10f", payload)
        samples.append(Vn100Sample(ns, tuple(values[:4]), tuple(values[4:7]), tuple(values[7:])))
    for reading, offset in gate.process(samples):
        assert 0.0 <= offset <= 0.1
        assert np.all(np.abs(reading.angular_velocity) <= LIMITS.max_angular_rate)
        assert np.all(np.abs(reading.linear_acceleration) <= LIMITS.max_acceleration)
    assert gate.accepted + gate.dropped == len(samples)


def test_colliding_packet_with_huge_stamp_does_not_stop_the_stream():
    from quadruped_drivers.vn100 import protocol as vp
    parser = vp.BinaryPacketParser(groups_fields={1: vp.DEFAULT_GROUP1_FIELDS})
    stream = b"".join(vp.encode_binary_packet(s, vp.DEFAULT_GROUP1_FIELDS)
                      for s in (good(5_000_000), good(10**19), good(15_000_000, rate=(3.4e38, 0, 0)),
                                good(20_000_000)))
    gate = SampleGate(LIMITS, max_backdate=0.1)
    out = gate.process(parser.feed(stream))
    assert len(out) == 3 and gate.counts["angular rate range"] == 1
    assert all(0.0 <= offset <= 0.1 for _, offset in out)


def test_a_rate_spike_inside_the_range_is_dropped_when_samples_are_dated():
    """Physical rate: 12 rad/s for one 5 ms sample is inside the gyro's range but no body can do it."""
    gate = SampleGate(LIMITS)
    burst = [good(0), good(5_000_000, rate=(0.1, 12.0, 0.0)), good(10_000_000)]
    out = gate.process(burst, arrival=100.0)
    assert len(out) == 2 and gate.counts["angular acceleration"] == 1
    assert "angular acceleration" in gate.last_drop
    assert [offset for _, offset in out] == pytest.approx([0.01, 0.0])
    # without an arrival time (no dating) the stream is not judged across samples
    assert len(SampleGate(LIMITS).process(burst)) == 3
