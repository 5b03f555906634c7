"""ServoFeedbackArray against the fake mux + ADS1115s: register traffic, volts/angles, faults, staleness,
physical-rate plausibility."""
import math

import numpy as np
import pytest

from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.i2c.fake_devices import ADS_REG_CONFIG, build_fake_hardware
from quadruped_drivers.servo_feedback import ServoFeedbackArray, ads1115_continuous_config

LSB = 4.096 / 32768


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def build_rig(max_joint_speed=None):
    """Configuration, calibration, fake hardware, clock and a feedback array on them."""
    hw = load_hardware_config()
    cal = load_servo_calibration()
    fake = build_fake_hardware(hw, require_lock=True)
    clock = Clock()
    return hw, cal, fake, clock, ServoFeedbackArray(fake.bus, hw, cal, clock=clock, max_joint_speed=max_joint_speed)


@pytest.fixture
def rig():
    hw, cal, fake, clock, feedback = build_rig()
    volts = np.linspace(0.5, 2.9, 12)
    fake.set_joint_voltages(volts)
    assert feedback.start() == []
    return hw, cal, fake, clock, feedback, volts


def test_config_word_continuous_860sps_fsr4096():
    assert ads1115_continuous_config(0, 4.096, 860) == 0b0100_0010_1110_0011
    assert ads1115_continuous_config(3, 4.096, 860) >> 12 == 0b111
    with pytest.raises(ValueError):
        ads1115_continuous_config(4, 4.096, 860)


def test_start_configures_each_adc_once_and_leaves_pointer_on_conversion(rig):
    hw, _, fake, _, _, _ = rig
    for joint in hw.joints:
        adc = fake.adcs[joint.index]
        assert adc.config_writes == 1 and adc.continuous and adc.data_rate == 860
        assert adc.full_scale_v == 4.096 and adc.mux == (joint.adc_input, None) and adc.pointer == 0


def test_read_returns_volts_and_angles_through_the_mux_with_minimal_traffic(rig):
    hw, cal, fake, clock, feedback, volts = rig
    fake.bus.clear_log()
    reading = feedback.read()
    assert reading.valid.all() and reading.stale == [] and reading.failed == []
    assert np.max(np.abs(reading.volts - volts)) <= LSB / 2 + 1e-12
    np.testing.assert_allclose(reading.angles, cal.volts_to_angles(reading.volts))
    np.testing.assert_allclose(reading.held_angles, reading.angles)
    log = fake.bus.log
    adc_reads = [t for t in log if t.kind == "read" and t.address != hw.mux_address]
    mux_writes = [t for t in log if t.address == hw.mux_address and t.kind == "write"]
    mux_reads = [t for t in log if t.address == hw.mux_address and t.kind == "read"]
    checks = [t for t in log if t.kind == "write_read"]
    # 11 plain conversion reads; joint 0's ADC has its config read back this cycle (rotating), then its
    # conversion is read with the pointer byte (which also puts the pointer back)
    assert len(adc_reads) == 11 and all(len(t.read) == 2 and t.written == b"" for t in adc_reads)
    assert [(t.address, t.written) for t in checks] == [(0x48, b"\x01"), (0x48, b"\x00")]
    # ch2 is still selected from start(): the cycle starts there, only ch0 and ch1 are written, each read back
    assert [t.written for t in mux_writes] == [b"\x01", b"\x02"]
    assert [t.read for t in mux_reads] == [b"\x01", b"\x02"]
    assert len(log) == 17 and not fake.bus.locked
    fake.bus.clear_log()
    feedback.read()  # starts on ch1 (still selected): again only two switches
    assert [t.written for t in fake.bus.log if t.address == hw.mux_address and t.kind == "write"] == [b"\x04", b"\x01"]
    assert all(adc.config_writes == 1 for adc in fake.adcs.values())  # config written once


def test_nack_marks_joint_stale_then_failed_others_continue_and_reconfigures(rig):
    hw, _, fake, clock, feedback, volts = rig
    joint = hw.joints[5]
    channel_bus = fake.mux.channel_bus(joint.mux_channel)
    assert feedback.read().valid.all()
    channel_bus.inject_fault(joint.adc_address, "nack", count=None)
    clock.t += 0.01
    reading = feedback.read()
    assert reading.stale == [5] and reading.failed == [] and not reading.valid[5]
    assert np.isnan(reading.angles[5]) and np.isnan(reading.volts[5])
    assert not np.isnan(reading.held_angles[5])  # within stale_after the last good value stands in
    assert reading.valid.sum() == 11 and reading.error_counts[5] == 1
    clock.t += hw.stale_after + 0.001
    reading = feedback.read()
    assert np.isnan(reading.held_angles[5]) and reading.stale == [5]
    clock.t += hw.failed_after
    reading = feedback.read()
    assert reading.failed == [5] and reading.stale == [] and reading.error_counts[5] == 3
    # the chip power-cycles back to its defaults and answers again: re-configured, then read
    fake.adcs[5].power_cycle()
    channel_bus.clear_faults()
    clock.t += 0.01
    reading = feedback.read()
    assert fake.adcs[5].continuous and fake.adcs[5].config_writes == 1
    assert not reading.valid[5] and reading.failed == [5]  # first conversion not trusted yet
    clock.t += 0.01
    reading = feedback.read()
    assert reading.valid.all() and abs(reading.volts[5] - volts[5]) <= LSB
    assert reading.age[5] == 0.0


def test_oserror_on_mux_select_marks_channel_stale_and_is_counted(rig):
    hw, _, fake, clock, feedback, _ = rig
    fake.bus.inject_fault(hw.mux_address, "oserror", count=1)
    clock.t += 0.01
    reading = feedback.read()  # ch2 is cached (no write), the ch0 select fails, ch1 works
    assert reading.stale == [0, 1, 2, 3] and reading.mux_errors == 1
    assert reading.error_counts.sum() == 0
    assert not fake.bus.locked
    reading = feedback.read()
    assert reading.valid.all()


def test_failing_deselect_never_hangs_or_leaves_the_bus_locked():
    hw = load_hardware_config()
    hw = type(hw)(**{**hw.__dict__, "mux_deselect_after_read": True})
    cal = load_servo_calibration()
    fake = build_fake_hardware(hw, require_lock=True)
    fake.set_joint_voltages(np.full(12, 1.0))
    feedback = ServoFeedbackArray(fake.bus, hw, cal, clock=Clock())
    feedback.start()
    assert fake.mux.control == 0
    fake.mux.inject_deselect_failure(count=None)
    for _ in range(3):
        reading = feedback.read()
        assert reading.valid.all() and not fake.bus.locked
    assert reading.mux_errors == 3
    fake.mux.clear_deselect_failure()
    feedback.read()
    assert fake.mux.control == 0 and not fake.bus.locked


def test_bus_locked_elsewhere_skips_the_cycle_without_raising(rig):
    _, _, fake, _, feedback, _ = rig
    assert fake.bus.try_lock()
    reading = feedback.read()
    assert not reading.valid.any() and feedback.lock_timeouts == 1
    fake.bus.unlock()
    assert feedback.read().valid.all()


def test_start_with_absent_adc_reports_it_and_recovers():
    hw = load_hardware_config()
    fake = build_fake_hardware(hw)
    fake.mux.channel_bus(2).inject_fault(0x4B, "nack", count=1)
    fake.set_joint_voltages(np.full(12, 1.7))
    feedback = ServoFeedbackArray(fake.bus, hw, load_servo_calibration(), clock=Clock())
    assert feedback.start() == [11]
    feedback.read()
    assert feedback.read().valid.all()


def test_read_before_start_is_an_error():
    hw = load_hardware_config()
    fake = build_fake_hardware(hw)
    with pytest.raises(RuntimeError):
        ServoFeedbackArray(fake.bus, hw, load_servo_calibration()).read()


def test_never_answering_joint_fails_after_failed_after_since_start():
    hw = load_hardware_config()
    fake = build_fake_hardware(hw)
    fake.mux.channel_bus(0).inject_fault(0x48, "nack", count=None)
    fake.set_joint_voltages(np.full(12, 1.7))
    clock = Clock()
    feedback = ServoFeedbackArray(fake.bus, hw, load_servo_calibration(), clock=clock)
    feedback.start()
    assert feedback.read().stale == [0]
    clock.t += hw.failed_after + 0.01
    assert feedback.read().failed == [0]


def test_register_config_value_on_the_wire(rig):
    hw, _, fake, _, _, _ = rig
    fake.bus.clear_log()
    feedback = ServoFeedbackArray(fake.bus, hw, load_servo_calibration(), clock=Clock())
    feedback.start()
    config_writes = [t for t in fake.bus.log if t.address != hw.mux_address and t.written[:1] == bytes([ADS_REG_CONFIG])]
    assert len(config_writes) == 12
    assert all(t.written == bytes([0x01, 0x42, 0xE3]) for t in config_writes)


# --- wrong data is never reported fresh -------------------------------------------------------------
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


def assert_fresh_is_true(reading, cal, volts):
    """Every joint reported valid shows its own servo's voltage (within an LSB)."""
    for index in np.flatnonzero(reading.valid):
        assert abs(reading.volts[index] - volts[index]) <= LSB, (index, reading.volts[index], volts[index])
    assert np.all(np.isnan(reading.angles[~reading.valid]))


def test_mux_write_acked_but_not_applied_is_caught(rig):
    hw, cal, fake, clock, feedback, volts = rig
    feedback.read()
    fake.mux.inject_ignored_writes(1)  # the next switch (ch1 -> ch2) is ACKed, the mux stays on ch1
    clock.t += 0.01
    reading = feedback.read()
    assert reading.stale == [8, 9, 10, 11] and feedback.mux_mismatches == 1
    assert_fresh_is_true(reading, cal, volts)
    clock.t += 0.01
    assert feedback.read().valid.all()


def test_browned_out_adc_is_stale_detected_and_reconfigured(rig):
    hw, cal, fake, clock, feedback, volts = rig
    feedback.read()
    fake.adcs[6].power_cycle()  # no NACK: single-shot defaults, the conversion register reads 0 V
    clock.t += 0.01
    reading = feedback.read()
    assert 6 in reading.implausible and not reading.valid[6]  # 0 V = far outside the joint's range
    for _ in range(2):
        clock.t += 0.01
        reading = feedback.read()
    assert feedback.config_losses[6] == 1 and fake.adcs[6].continuous
    assert reading.valid.all() and abs(reading.volts[6] - volts[6]) <= LSB


def test_lost_config_with_a_plausible_reading_is_found_within_twelve_cycles(rig):
    hw, cal, fake, clock, feedback, volts = rig
    adc = fake.adcs[9]
    adc.config = (adc.config & ~0x00E0) | (4 << 5)  # e.g. a glitch rewrote the data rate: still converts
    for _ in range(13):
        clock.t += 0.01
        feedback.read()
    assert feedback.config_losses[9] == 1 and adc.data_rate == 860


def test_garbage_codes_are_stale(rig):
    hw, cal, fake, clock, feedback, volts = rig
    fake.adcs[2].inject_codes([-22600])  # -2.83 V: -374 deg on a motor joint, way off any servo
    clock.t += 0.01
    reading = feedback.read()
    assert reading.implausible == [2] and not reading.valid[2] and feedback.implausible_counts[2] == 1
    assert_fresh_is_true(reading, cal, volts)


def test_plausible_range_is_the_pulse_range_plus_margin():
    hw = load_hardware_config()
    cal = load_servo_calibration()
    low, high = ServoFeedbackArray(build_fake_hardware(hw).bus, hw, cal).plausible_range
    np.testing.assert_allclose(np.degrees(low[:3]), [-230 - 15, -130 - 15, 0 - 15], atol=1e-9)
    np.testing.assert_allclose(np.degrees(high[:3]), [-50 + 15, 50 + 15, 180 + 15], atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["none", "ignore_mux", "brownout", "garbage", "nack", "mux_error"]),
                          st.integers(0, 11), st.integers(-32768, 32767)), min_size=5, max_size=40))
def test_no_fault_sequence_reports_a_wrong_value_fresh(faults):
    hw = load_hardware_config()
    cal = load_servo_calibration()
    fake = build_fake_hardware(hw)
    clock = Clock()
    feedback = ServoFeedbackArray(fake.bus, hw, cal, clock=clock)
    volts = np.linspace(0.6, 2.8, 12)
    fake.set_joint_voltages(volts)
    feedback.start()
    for kind, index, code in faults:
        joint = hw.joints[index]
        if kind == "ignore_mux":
            fake.mux.inject_ignored_writes(1)
        elif kind == "brownout":
            fake.adcs[index].power_cycle()
        elif kind == "garbage":
            volts_read = code * 4.096 / 32768
            angle = cal.volts_to_angles(np.where(np.arange(12) == index, volts_read, volts))[index]
            low, high = feedback.plausible_range
            if low[index] - 1e-3 <= angle <= high[index] + 1e-3:
                continue  # a plausible wrong code cannot be told from a real one: not injected
            fake.adcs[index].inject_codes([code])
        elif kind == "nack":
            fake.mux.channel_bus(joint.mux_channel).inject_fault(joint.adc_address, "nack", count=1)
        elif kind == "mux_error":
            fake.bus.inject_fault(hw.mux_address, "oserror", count=1)
        clock.t += 0.01
        assert_fresh_is_true(feedback.read(), cal, volts)
    for _ in range(14):  # everything heals once the faults stop
        clock.t += 0.01
        reading = feedback.read()
    assert reading.valid.all()


# ---- physical-rate plausibility: a servo cannot move faster than its no-load speed ----------------

NO_LOAD_SPEED = math.radians(95.0 * 6.0)  # 95 rpm in rad/s (config/robot.yaml)


@pytest.fixture
def rated():
    """The rig with the rate check on, at the robot's no-load speed, starting from mid-range angles."""
    hw, cal, fake, clock, feedback = build_rig(NO_LOAD_SPEED)
    low, high = feedback.plausible_range
    angles = 0.5 * (low + high)

    def show(new_angles, dt=0.01):
        clock.t += dt
        fake.set_joint_voltages(cal.angles_to_volts(new_angles))
        return feedback.read()

    fake.set_joint_voltages(cal.angles_to_volts(angles))
    assert feedback.start() == []
    assert feedback.read().valid.all()
    return hw, feedback, angles, show


def test_a_jump_no_servo_can_make_is_stale_not_fresh(rated):
    hw, feedback, angles, show = rated
    jumped = angles.copy()
    jumped[4] += math.radians(60.0)  # inside the joint's range, 10x what 95 rpm allows in 10 ms
    reading = show(jumped)
    assert not reading.valid[4] and np.isnan(reading.angles[4]) and 4 in reading.implausible
    assert reading.valid[np.arange(12) != 4].all()
    assert feedback.jump_counts[4] == 1 and feedback.jump_counts.sum() == 1
    np.testing.assert_allclose(reading.held_angles[4], angles[4], atol=1e-3)  # the last good angle stands in


def test_motion_at_the_servos_speed_stays_fresh(rated):
    _, feedback, angles, show = rated
    step = NO_LOAD_SPEED * 0.01 * 0.95
    for k in range(1, 20):
        reading = show(angles + k * step * np.where(np.arange(12) % 2 == 0, 1.0, -1.0))
        assert reading.valid.all(), k
    assert feedback.jump_counts.sum() == 0


def test_a_single_spike_is_dropped_and_the_next_good_reading_is_fresh(rated):
    _, feedback, angles, show = rated
    spiked = angles.copy()
    spiked[0] -= math.radians(45.0)
    assert not show(spiked).valid[0]
    reading = show(angles)
    assert reading.valid.all() and feedback.jumps_accepted.sum() == 0


def test_agreeing_readings_at_a_new_angle_are_accepted(rated):
    hw, feedback, angles, show = rated
    moved = angles.copy()
    moved[7] += math.radians(40.0)  # e.g. turned by hand while the servo was unpowered
    confirm = hw.adc_jump_confirm_readings
    for _ in range(confirm - 1):
        assert not show(moved).valid[7]
    reading = show(moved)
    assert reading.valid[7] and reading.angles[7] == pytest.approx(moved[7], abs=1e-3)
    assert feedback.jumps_accepted[7] == 1 and feedback.jump_counts[7] == confirm - 1
    assert show(moved).valid.all()


def test_a_long_gap_allows_the_travel_the_servo_could_make(rated):
    _, feedback, angles, show = rated
    moved = angles + math.radians(30.0) * np.where(np.arange(12) < 6, 1.0, -1.0)
    reading = show(moved, dt=0.2)  # 30 deg in 0.2 s: within 95 rpm (114 deg)
    assert reading.valid.all() and feedback.jump_counts.sum() == 0


def test_the_rate_check_needs_a_positive_speed():
    hw = load_hardware_config()
    fake = build_fake_hardware(hw)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="max_joint_speed"):
            ServoFeedbackArray(fake.bus, hw, load_servo_calibration(), max_joint_speed=bad)
