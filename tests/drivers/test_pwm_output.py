"""ServoPwmOutput against the fake PCA9685: start-up registers, exact pulses, clamping, watchdog,
failsafe, enable/disable, shutdown, write errors; and the whole stack through the socket bus bridge."""
import math
import os
import tempfile

import numpy as np
import pytest
from hypothesis import given, strategies as st

from quadruped_drivers.bus_bridge import BridgedI2CBus, BusBridgeServer
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config, pca9685_prescale
from quadruped_drivers.i2c.fake_devices import build_fake_hardware
from quadruped_drivers.pwm_output import EStopLatched, PwmOutputError, ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray

HW = load_hardware_config()
TICK_US = 1e6 * (121 + 1) / 25e6  # 4.88 us per tick at PRE_SCALE 121


class Clock:
    def __init__(self):
        self.t = 10.0

    def __call__(self):
        return self.t


def make(hw=HW, start=True):
    fake = build_fake_hardware(hw, require_lock=True)
    clock = Clock()
    pwm = ServoPwmOutput(fake.bus, hw, clock=clock, sleep=lambda s: None)
    if start:
        pwm.start()
    return fake, clock, pwm


def with_failsafe(actions):
    joints = tuple(type(j)(**{**j.__dict__, "failsafe": a}) for j, a in zip(HW.joints, actions))
    return type(HW)(**{**HW.__dict__, "joints": joints})


def test_prescale_formula_and_actual_frequency():
    assert pca9685_prescale(50.0) == 121 == round(25e6 / (4096 * 50)) - 1
    assert HW.prescale == 121
    assert HW.actual_pwm_frequency_hz == pytest.approx(25e6 / (4096 * 122))
    with pytest.raises(ValueError):
        pca9685_prescale(2000.0)


def test_start_sets_registers_and_leaves_outputs_off():
    fake, _, pwm = make()
    pca = fake.pca
    assert pca.prescale == 121 and not pca.asleep and pca.auto_increment
    assert pca.registers[0x01] == 0x04 and pca.mode1 & 0x80 == 0
    assert pca.frequency_hz() == pytest.approx(pwm.frequency_hz)
    assert np.all(fake.pulse_widths_us() == 0.0) and pwm.enabled
    assert not fake.bus.locked


def test_start_from_a_running_chip_still_takes_the_prescale():
    fake, _, pwm = make()
    pwm.command(np.full(12, 1500.0))
    pwm.start()  # a restarted node: chip awake with outputs running
    assert fake.pca.prescale == 121 and np.all(fake.pulse_widths_us() == 0.0)


def test_start_raises_on_absent_chip_and_on_readback_mismatch():
    fake, _, pwm = make(start=False)
    fake.bus.inject_fault(HW.pca_address, "nack", count=None)
    with pytest.raises(PwmOutputError, match="did not answer"):
        pwm.start()
    assert not fake.bus.locked
    fake.bus.clear_faults()
    # a chip that takes a different prescale than written (e.g. a glitch on the bus)
    fake.pca.write = lambda data, _w=fake.pca.write: _w(b"\xfe\x1e" if data[:1] == b"\xfe" and len(data) == 2 else data)
    with pytest.raises(PwmOutputError, match="PRE_SCALE = 30"):
        pwm.start()
    with pytest.raises(RuntimeError):
        ServoPwmOutput(fake.bus, HW).command(np.full(12, 1500.0))


def test_commanded_angle_gives_the_exact_pulse_in_the_chip():
    fake, _, pwm = make()
    cal = load_servo_calibration()
    angles = np.radians([-140.0, -40.0, 90.0, -100.0, 0.0, 30.0, -200.0, -120.0, 170.0, -60.0, 45.0, 5.0])
    pulses = cal.angles_to_pulses(angles)
    fake.bus.clear_log()
    applied = pwm.command(pulses)
    log = fake.bus.log
    assert len(log) == 1 and log[0].written[0] == 0x06 and len(log[0].written) == 1 + 4 * 12
    expected_ticks = np.round(pulses * pwm.frequency_hz * 4096 / 1e6)
    np.testing.assert_allclose(fake.pulse_widths_us(), expected_ticks * TICK_US, rtol=0, atol=1e-9)
    np.testing.assert_allclose(applied, fake.pulse_widths_us(), rtol=0, atol=1e-9)
    assert np.max(np.abs(applied - pulses)) <= TICK_US / 2 + 1e-9
    # leg1 motor1 at its neutral angle -140 deg -> 1500 us -> 307 ticks
    assert fake.pca.pulse_width_us(0) == pytest.approx(307 * TICK_US)


@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e4, 1e4)),
                min_size=12, max_size=12))
def test_clamping_never_exceeds_the_limits(values):
    fake, _, pwm = make()
    pwm.command(np.full(12, 1500.0))
    applied = pwm.command(values)
    widths = fake.pulse_widths_us()
    np.testing.assert_allclose(applied, widths, atol=1e-9)
    assert np.all(widths >= HW.min_us - 1e-9) and np.all(widths <= HW.max_us + 1e-9)


def test_clamp_and_nan_counting_and_keep_last():
    fake, _, pwm = make()
    pwm.command(np.full(12, 1500.0))
    cmd = np.full(12, 1600.0)
    cmd[0], cmd[1], cmd[2] = 9000.0, -5.0, np.nan
    applied = pwm.command(cmd)
    assert pwm.clamp_count == 2 and pwm.invalid_count == 1
    assert applied[0] <= 2500.0 and applied[0] > 2495.0 and applied[1] >= 500.0 and applied[1] < 505.0
    assert applied[2] == pytest.approx(307 * TICK_US)  # NaN keeps the last applied width
    with pytest.raises(ValueError):
        pwm.command(np.full(11, 1500.0))


def test_nan_before_any_command_never_moves_a_servo():
    fake, _, pwm = make(with_failsafe(["neutral", "off", "hold"] * 4))
    applied = pwm.command(np.full(12, np.nan))
    assert np.all(applied == 0.0) and np.all(fake.pulse_widths_us() == 0.0)  # 'neutral' too: never commanded


def test_watchdog_trips_once_applies_failsafe_and_clears_on_command():
    fake, clock, pwm = make(with_failsafe(["hold", "neutral", "off"] * 4))
    pwm.command(np.full(12, 2000.0))
    clock.t += HW.watchdog_timeout * 0.99
    assert not pwm.update()
    clock.t += HW.watchdog_timeout * 0.02
    fake.bus.clear_log()
    assert pwm.update() and pwm.watchdog_tripped
    widths = fake.pulse_widths_us()
    assert widths[0] == pytest.approx(410 * TICK_US)  # hold 2000 us
    assert widths[1] == pytest.approx(307 * TICK_US)  # neutral 1500 us
    assert widths[2] == 0.0  # off
    led_writes = lambda: [t for t in fake.bus.log if t.kind == "write"]  # noqa: E731 (MODE1 checks are reads)
    assert len(led_writes()) == 1
    clock.t += 1.0
    pwm.update()
    assert len(led_writes()) == 1 and pwm.watchdog_trips == 1  # applied once
    pwm.command(np.full(12, 1000.0))
    assert not pwm.watchdog_tripped and np.all(fake.pulse_widths_us() > 0)


def test_disable_turns_outputs_off_and_records_commands():
    fake, clock, pwm = make()
    pwm.command(np.full(12, 1500.0))
    pwm.disable()
    assert not pwm.enabled and np.all(fake.pulse_widths_us() == 0.0)
    applied = pwm.command(np.full(12, 1800.0))
    assert np.all(applied == 0.0) and np.all(fake.pulse_widths_us() == 0.0)
    assert np.all(pwm.requested_us == 1800.0)
    clock.t += 5.0
    assert not pwm.update()  # no watchdog while disabled
    pwm.enable()
    assert np.all(fake.pulse_widths_us() == 0.0)  # no jump to an old command
    pwm.command(np.full(12, 1800.0))
    assert np.all(fake.pulse_widths_us() > 1790.0)


def test_shutdown_turns_outputs_off_and_sleeps():
    fake, _, pwm = make()
    pwm.command(np.full(12, 1500.0))
    assert pwm.shutdown()
    assert fake.pca.asleep and not any(fake.pca.outputs_active(ch) for ch in range(16))
    fake.pca.write(bytes([0x00, 0x20]))  # even woken again, the outputs stay off (ALL_LED full-off)
    assert not any(fake.pca.outputs_active(ch) for ch in range(16))


def test_write_error_is_counted_and_retried():
    fake, clock, pwm = make()
    pwm.command(np.full(12, 1500.0))
    fake.bus.inject_fault(HW.pca_address, "oserror", count=1)
    applied = pwm.command(np.full(12, 1600.0))  # retried at once
    assert pwm.write_errors == 1 and pwm.write_retries == 1
    assert applied[0] == pytest.approx(round(1600 / TICK_US) * TICK_US)
    fake.bus.inject_fault(HW.pca_address, "oserror", count=pwm.write_attempts)
    applied = pwm.command(np.full(12, 1700.0))  # every attempt of this call fails: pending
    assert pwm.write_errors == 1 + pwm.write_attempts and applied[0] == pytest.approx(round(1600 / TICK_US) * TICK_US)
    assert not fake.bus.locked
    pwm.update()
    assert fake.pca.pulse_width_us(0) == pytest.approx(round(1700 / TICK_US) * TICK_US)


def test_whole_stack_through_the_socket_bridge():
    hw = HW
    cal = load_servo_calibration()
    fake = build_fake_hardware(hw)
    directory = tempfile.mkdtemp(prefix="uqpwm")
    path = os.path.join(directory, "i2c.sock")
    server = BusBridgeServer(fake.bus, path, lock=fake.bus.lock)
    client = BridgedI2CBus(path)
    try:
        feedback = ServoFeedbackArray(client, hw, cal, clock=Clock())
        pwm = ServoPwmOutput(client, hw, clock=Clock(), sleep=lambda s: None)
        pwm.start()
        angles = np.radians([-120.0, -30.0, 100.0] * 4)
        fake.set_joint_voltages(cal.angles_to_volts(angles))
        assert feedback.start() == []
        reading = feedback.read()
        assert reading.valid.all()
        np.testing.assert_allclose(reading.angles, angles, atol=math.radians(0.02))
        pwm.command(cal.angles_to_pulses(angles))
        np.testing.assert_allclose(cal.pulses_to_angles(fake.pulse_widths_us()), angles, atol=math.radians(0.3))
        fake.mux.channel_bus(0).inject_fault(0x49, "nack")
        assert feedback.read().stale == [1]
        assert pwm.shutdown() and np.all(fake.pulse_widths_us() == 0.0)
    finally:
        client.deinit()
        server.close()
        os.rmdir(directory)


# --- faults the chip and the bus can make --------------------------------------------------------------

from hypothesis import settings  # noqa: E402


def narrow(min_us, max_us):
    joints = tuple(type(j)(**{**j.__dict__, "min_us": min_us, "max_us": max_us, "neutral_us": (min_us + max_us) / 2})
                   for j in HW.joints)
    return type(HW)(**{**HW.__dict__, "joints": joints})


def assert_chip_in_limits(fake, hw):
    widths = fake.pulse_widths_us()
    on = widths > 0.0
    assert np.all(widths[on] >= hw.min_us[on] - 1e-9), widths
    assert np.all(widths[on] <= hw.max_us[on] + 1e-9), widths


def test_the_torn_write_of_issue_10_cannot_happen():
    # 2,500 us (512 ticks = 0x200) then 2,495 us (511 = 0x1FF): a new OFF_L with the old OFF_H was 3,743 us.
    for keep in range(1, 1 + 4 * 12):
        fake, _, pwm = make()
        pwm.command(np.full(12, 2500.0))
        fake.bus.inject_fault(HW.pca_address, "abort", count=pwm.write_attempts, keep=keep)
        pwm.command(np.full(12, 2495.0))
        assert_chip_in_limits(fake, HW)
        pwm.update()
        np.testing.assert_allclose(fake.pulse_widths_us(), np.round(2495.0 / TICK_US) * TICK_US, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from([HW, narrow(800.0, 2200.0), narrow(1000.0, 1900.0), narrow(520.0, 2480.0)]),
       st.lists(st.tuples(st.lists(st.floats(0.0, 3000.0), min_size=12, max_size=12), st.integers(0, 60),
                          st.integers(0, 3)), min_size=1, max_size=25))
def test_aborted_writes_never_put_a_pulse_outside_the_limits(hw, steps):
    fake, clock, pwm = make(hw)
    for widths, keep, failures in steps:
        if failures:
            fake.bus.inject_fault(hw.pca_address, "abort", count=failures, keep=keep)
        pwm.command(widths)
        assert_chip_in_limits(fake, hw)
        clock.t += 0.01
        pwm.update()
        assert_chip_in_limits(fake, hw)
        fake.bus.clear_faults()
    pwm.update()
    np.testing.assert_allclose(fake.pulse_widths_us(), pwm.applied_us, atol=1e-9)


def test_disable_with_torn_all_off_write_keeps_pulses_in_limits():
    fake, _, pwm = make()
    pwm.command(np.full(12, 2000.0))
    fake.bus.inject_fault(HW.pca_address, "abort", count=1, keep=1)
    with pytest.raises(PwmOutputError):
        pwm.disable()
    assert_chip_in_limits(fake, HW)


def test_chip_reset_is_detected_reported_and_restored():
    fake, clock, pwm = make()
    pwm.command(np.full(12, 1700.0))
    fake.pca.power_cycle()  # brown-out: asleep, outputs off, still ACKs writes
    assert np.all(fake.pulse_widths_us() == 0.0)
    for _ in range(3):
        clock.t += 0.05
        pwm.command(np.full(12, 1700.0))
        pwm.update()
    assert pwm.chip_resets == 1 and "lost its configuration" in pwm.last_fault
    np.testing.assert_allclose(fake.pulse_widths_us(), np.round(1700.0 / TICK_US) * TICK_US, atol=1e-9)
    assert fake.pca.prescale == HW.prescale and not fake.pca.asleep


def test_neutral_failsafe_never_moves_an_uncommanded_servo():
    fake, clock, pwm = make(with_failsafe(["neutral"] * 12))
    clock.t += 1.0
    assert pwm.update()  # the watchdog trips after start without a command ...
    assert np.all(fake.pulse_widths_us() == 0.0)  # ... but nothing moves
    widths = np.full(12, np.nan)
    widths[3] = 1800.0
    pwm.command(widths)
    pwm.disable()
    pwm.enable()
    pwm.command(widths)  # only joint 3 commanded since enable
    clock.t += 1.0
    pwm.update()
    out = fake.pulse_widths_us()
    assert out[3] == pytest.approx(round(1500 / TICK_US) * TICK_US) and np.all(np.delete(out, 3) == 0.0)


@pytest.mark.parametrize("failsafe", ["neutral", "off", "hold"])
def test_watchdog_fires_within_its_timeout_even_with_bus_errors(failsafe):
    from quadruped_drivers.fault_scenarios import failsafe_latency
    latencies = [failsafe_latency(HW, failsafe, rate, seed) for rate in (0.0, 0.1, 0.3, 0.5) for seed in range(25)]
    assert max(latencies) <= HW.watchdog_timeout + 0.01 + 1e-9, max(latencies)
    without_errors = [failsafe_latency(HW, failsafe, 0.0, seed) for seed in range(10)]
    assert max(without_errors) <= HW.watchdog_timeout  # the trip itself is never late


def test_estop_turns_every_output_off_at_once_and_latches():
    fake, clock, pwm = make()
    pwm.command(np.full(12, 1600.0))
    assert np.all(fake.pulse_widths_us() > 0.0)
    assert pwm.estop("test") and np.all(fake.pulse_widths_us() == 0.0)
    pwm.command(np.full(12, 1500.0))  # recorded, not applied
    clock.t += 0.05
    pwm.update()
    assert np.all(fake.pulse_widths_us() == 0.0) and pwm.estop_reason == "test"
    with pytest.raises(EStopLatched, match="reset it first"):
        pwm.enable()
    pwm.reset_estop()
    assert np.all(fake.pulse_widths_us() == 0.0)  # reset alone moves nothing
    pwm.enable()
    pwm.command(np.full(12, 1500.0))
    assert np.all(fake.pulse_widths_us() > 0.0)


def test_estop_whose_write_fails_is_repeated_until_the_outputs_are_off():
    fake, clock, pwm = make()
    pwm.command(np.full(12, 1600.0))
    fake.bus.inject_fault(HW.pca_address, "oserror", count=1)
    assert not pwm.estop("bus glitch")
    clock.t += 0.01
    pwm.update()
    assert np.all(fake.pulse_widths_us() == 0.0) and pwm.estop_reason == "bus glitch"


def test_not_ready_names_why_the_outputs_cannot_take_commands():
    fake, clock, pwm = make(start=False)
    assert pwm.not_ready == "the PCA9685 is not set up yet"
    pwm.start()
    assert pwm.not_ready == ""
    pwm.disable()
    assert pwm.not_ready.startswith("outputs disabled")
    pwm.enable()
    pwm.command(np.full(12, 1500.0))
    fake.bus.inject_fault(HW.pca_address, "oserror", count=pwm.write_attempts)
    pwm.command(np.full(12, 1600.0))  # every attempt fails: the chip does not answer
    assert pwm.not_ready.startswith("the PCA9685 does not answer: LED write failed")
    clock.t += 0.01
    pwm.update()  # the pending write goes through: answering again
    assert pwm.not_ready == ""
    fake.bus.inject_fault(HW.pca_address, "oserror", count=1 + pwm.write_attempts)
    clock.t += 0.2
    pwm.update()  # the MODE1 check and the watchdog's failsafe write fail
    assert pwm.not_ready.startswith("the PCA9685 does not answer: ")
    clock.t += 0.2
    pwm.update()
    assert pwm.not_ready == ""
    pwm.estop("test")
    assert pwm.not_ready == "e-stop latched (test)"
