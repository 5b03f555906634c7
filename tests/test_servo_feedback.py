"""ServoFeedbackArray against the fake mux + ADS1115s: register traffic, volts/angles, faults, staleness."""
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


@pytest.fixture
def rig():
    hw = load_hardware_config()
    cal = load_servo_calibration()
    fake = build_fake_hardware(hw, require_lock=True)
    clock = Clock()
    feedback = ServoFeedbackArray(fake.bus, hw, cal, clock=clock)
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
    reads = [t for t in log if t.kind == "read"]
    mux_writes = [t for t in log if t.address == hw.mux_address]
    assert len(reads) == 12 and all(len(t.read) == 2 and t.written == b"" for t in reads)
    # ch2 is still selected from start(): the cycle starts there, only ch0 and ch1 are written
    assert [t.written for t in mux_writes] == [b"\x01", b"\x02"]
    assert len(log) == 14 and not fake.bus.locked
    fake.bus.clear_log()
    feedback.read()  # starts on ch1 (still selected): again only two switches
    assert [t.written for t in fake.bus.log if t.address == hw.mux_address] == [b"\x04", b"\x01"]
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
