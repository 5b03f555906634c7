"""Register-level fakes (FakeI2CBus, TCA9548A, ADS1115, PCA9685), cross-checked with the unchanged
adafruit CircuitPython drivers, plus import hygiene (no Blinka/board at import time)."""
import errno
import subprocess
import sys
import threading

import numpy as np
import pytest
from hypothesis import given, strategies as st

from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.i2c import BusLockTimeout, bus_locked
from quadruped_drivers.i2c.fake_bus import FakeI2CBus, Transaction, bits_on_wire, transaction_bits
from quadruped_drivers.i2c.fake_devices import (PCA_AI, PCA_ALLCALL, PCA_LED0_ON_L, PCA_MODE1, FakeAds1115,
                                                FakePca9685, FakeTca9548a, ads1115_code, build_fake_hardware)


class Register8:
    """Tiny device: pointer + 256 registers, for bus-level tests."""

    def __init__(self):
        self.regs = bytearray(256)
        self.pointer = 0

    def write(self, data):
        if data:
            self.pointer = data[0]
            for i, b in enumerate(data[1:]):
                self.regs[(self.pointer + i) & 0xFF] = b

    def read(self, n):
        return bytes(self.regs[(self.pointer + i) & 0xFF] for i in range(n))


def test_absent_address_nacks_with_enxio_and_is_logged():
    bus = FakeI2CBus()
    with pytest.raises(OSError) as info:
        bus.writeto(0x22, b"\x01")
    assert info.value.errno == errno.ENXIO
    assert bus.log == [Transaction("write", 0x22, b"\x01", b"", ok=False)]


def test_routing_slices_and_log():
    bus = FakeI2CBus()
    dev = bus.attach(0x40, Register8())
    bus.writeto(0x40, b"\xff\x05\x07\x09\xff", start=1, end=4)
    assert dev.regs[5:7] == b"\x07\x09"
    out = bytearray(4)
    bus.writeto_then_readfrom(0x40, b"\x05", out, in_start=1, in_end=3)
    assert out == bytearray(b"\x00\x07\x09\x00")
    buf = bytearray(2)
    bus.readfrom_into(0x40, buf)
    assert buf == b"\x07\x09"
    assert [t.kind for t in bus.log] == ["write", "write_read", "read"]
    assert bus.log[1].written == b"\x05" and bus.log[1].read == b"\x07\x09"
    assert bus.scan() == [0x40]
    with pytest.raises(ValueError):
        bus.attach(0x40, Register8())
    with pytest.raises(ValueError):
        bus.writeto(0x80, b"")


def test_bits_on_wire_counts_start_address_data_restart_stop():
    assert transaction_bits(Transaction("write", 0x40, b"\x01\x02")) == 1 + 9 + 18 + 1
    assert transaction_bits(Transaction("read", 0x48, b"", b"\x01\x02")) == 1 + 9 + 18 + 1
    assert transaction_bits(Transaction("write_read", 0x48, b"\x00", b"\x01\x02")) == 1 + 9 + 9 + 1 + 9 + 18 + 1
    assert transaction_bits(Transaction("read", 0x48, b"", b"", ok=False)) == 11
    assert bits_on_wire([Transaction("write", 1, b"\x00")] * 3) == 3 * 20


def test_fault_injection_counts_and_permanent():
    bus = FakeI2CBus()
    bus.attach(0x40, Register8())
    bus.inject_fault(0x40, "nack", count=2)
    for _ in range(2):
        with pytest.raises(OSError) as info:
            bus.writeto(0x40, b"\x00")
        assert info.value.errno == errno.ENXIO
    bus.writeto(0x40, b"\x00")
    bus.inject_fault(0x40, "oserror", count=None)
    for _ in range(5):
        with pytest.raises(OSError) as info:
            bus.readfrom_into(0x40, bytearray(1))
        assert info.value.errno == errno.EIO
    assert 0x40 not in bus.scan()
    bus.clear_faults()
    bus.readfrom_into(0x40, bytearray(1))
    with pytest.raises(ValueError):
        bus.inject_fault(0x40, "bogus")


def test_lock_is_blinka_like_and_bus_locked_is_bounded():
    bus = FakeI2CBus(require_lock=True)
    bus.attach(0x40, Register8())
    with pytest.raises(RuntimeError):
        bus.writeto(0x40, b"\x00")
    assert bus.try_lock() and not bus.try_lock()  # not reentrant, like busio.I2C
    bus.writeto(0x40, b"\x00")
    bus.unlock()
    assert not bus.locked
    with bus_locked(bus):
        assert bus.locked
    assert not bus.locked
    with pytest.raises(ZeroDivisionError):
        with bus_locked(bus):
            1 / 0
    assert not bus.locked
    bus.try_lock()
    with pytest.raises(BusLockTimeout) as info:
        with bus_locked(bus, timeout=0.005):
            pass
    assert info.value.errno == errno.EBUSY
    bus.unlock()


def test_bus_is_thread_safe():
    bus = FakeI2CBus()
    dev = bus.attach(0x40, Register8())

    def worker(value):
        for _ in range(200):
            bus.writeto(0x40, bytes([0x10, value, value]))
            out = bytearray(2)
            bus.writeto_then_readfrom(0x40, b"\x10", out)
            assert out[0] == out[1]

    threads = [threading.Thread(target=worker, args=(v,)) for v in (1, 2, 3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(bus.log) == 1200 and dev.regs[0x10] in (1, 2, 3)


def test_mux_routes_only_selected_channels_and_faults_downstream():
    bus = FakeI2CBus()
    mux = bus.attach(0x71, FakeTca9548a())
    a = mux.channel_bus(0).attach(0x48, Register8())
    b = mux.channel_bus(1).attach(0x48, Register8())
    with pytest.raises(OSError):
        bus.writeto(0x48, b"\x01\x05")  # nothing selected
    bus.writeto(0x71, b"\x01")
    bus.writeto(0x48, b"\x01\x05")
    assert a.regs[1] == 5 and b.regs[1] == 0
    out = bytearray(1)
    bus.readfrom_into(0x71, out)
    assert out[0] == 0x01 and mux.selected_channels == [0]
    bus.writeto(0x71, b"\x03")  # both: writes reach both, reads are wired-AND
    bus.writeto(0x48, b"\x01\x0f")
    assert a.regs[1] == 0x0f and b.regs[1] == 0x0f
    mux.channel_bus(1).inject_fault(0x48, "nack")
    with pytest.raises(OSError):
        bus.writeto(0x48, b"\x01\x00")
    assert 0x48 in bus.scan()
    mux.inject_deselect_failure(count=1)
    with pytest.raises(OSError):
        bus.writeto(0x71, b"\x00")
    assert mux.selected_channels == [0, 1]
    bus.writeto(0x71, b"\x00")
    assert mux.selected_channels == []
    with pytest.raises(ValueError):
        mux.channel_bus(8)


def test_ads1115_registers_conversion_and_single_shot():
    adc = FakeAds1115()
    assert adc.config == 0x8583 and not adc.continuous and adc.full_scale_v == 2.048
    adc.set_input_voltage(2, 1.5)
    # continuous, AIN2 vs GND, +-4.096 V, 860 SPS, comparator off
    adc.write(bytes([0x01, 0b01100010, 0b11100011]))
    assert adc.continuous and adc.mux == (2, None) and adc.full_scale_v == 4.096 and adc.data_rate == 860
    adc.write(b"\x00")
    code = int.from_bytes(adc.read(2), "big", signed=True)
    assert code == round(1.5 / 4.096 * 32768) == ads1115_code(1.5, 4.096)
    adc.write(b"\x01")
    assert int.from_bytes(adc.read(2), "big") & 0x8000 == 0  # OS reads 0: converting continuously
    adc.set_input_voltage(2, 9.0)
    adc.write(b"\x00")
    assert int.from_bytes(adc.read(2), "big", signed=True) == 32767  # clamped
    # single-shot, differential AIN0-AIN1 at +-2.048 V: result held until the next OS=1
    adc.set_input_voltage(0, 0.2)
    adc.set_input_voltage(1, 0.7)
    adc.write(bytes([0x01, 0x85, 0x83]))
    adc.write(b"\x00")
    assert int.from_bytes(adc.read(2), "big", signed=True) == round(-0.5 / 2.048 * 32768)
    adc.set_input_voltage(0, 0.0)
    assert int.from_bytes(adc.read(2), "big", signed=True) == round(-0.5 / 2.048 * 32768)
    with pytest.raises(ValueError):
        adc.set_input_voltage(4, 0.0)
    with pytest.raises(ValueError):
        adc.set_input_voltage(0, float("nan"))


@given(st.floats(-5.0, 5.0, allow_nan=False))
def test_ads1115_code_is_clamped_round(volts):
    code = ads1115_code(volts, 4.096)
    assert -32768 <= code <= 32767
    if abs(volts) < 4.0:
        assert abs(code * 4.096 / 32768 - volts) <= 0.5 * 4.096 / 32768 + 1e-12


def test_pca9685_prescale_only_while_asleep_and_restart():
    pca = FakePca9685()
    assert pca.asleep and pca.prescale == 30 and pca.pulse_width_us(0) == 0.0
    pca.write(bytes([0xFE, 121]))
    assert pca.prescale == 121  # asleep at power-up: accepted
    pca.write(bytes([0x00, 0x20]))  # wake, AI
    pca.write(bytes([0xFE, 50]))
    assert pca.prescale == 121  # ignored while awake, like the chip
    pca.write(bytes([0x06, 0, 0, 0x33, 0x01]))  # LED0 on 0, off 307
    assert pca.pulse_width_us(0) == pytest.approx(307 * 122 / 25.0)
    assert pca.frequency_hz() == pytest.approx(25e6 / 4096 / 122)
    pca.write(bytes([0x00, 0x30]))  # sleep with an output running -> RESTART pending
    pca.write(b"\x00")
    assert pca.read(1)[0] & 0x80 and pca.pulse_width_us(0) == 0.0
    pca.write(bytes([0x00, 0x20]))
    assert not pca.outputs_active(0)  # awake but halted until RESTART
    pca.write(bytes([0x00, 0xA0]))
    pca.write(b"\x00")
    assert pca.outputs_active(0) and pca.read(1)[0] & 0x80 == 0


def test_pca9685_auto_increment_full_bits_and_all_led():
    pca = FakePca9685()
    pca.write(bytes([0x00, 0x00]))  # awake, AI off: bytes overwrite the same register
    pca.write(bytes([0x06, 1, 2, 3]))
    assert pca.registers[0x06] == 3 and pca.registers[0x07] == 0
    pca.write(bytes([0x00, 0x20]))
    pca.write(bytes([0x42, 0, 0, 0xCD, 0x00, 0xAA]))  # LED15 then wraps to MODE1 (0x45 -> 0x00)
    assert pca.registers[0x45] == 0x00 and pca.registers[0x44] == 0xCD
    assert pca.registers[0x00] == 0xAA & 0x7F  # the byte after LED15_OFF_H landed in MODE1
    pca.write(bytes([0x00, 0x20]))
    assert pca.pulse_width_us(15) == pytest.approx(0xCD * 1e6 * 31 / 25e6)  # PRE_SCALE still 30
    pca.write(bytes([0x00, 0x20]))
    pca.write(bytes([0x0A, 0, 0x10, 0, 0]))  # LED1 full on
    assert pca.pulse_width_us(1) == pytest.approx(1e6 / pca.frequency_hz())
    pca.write(bytes([0x0A, 0, 0x10, 0, 0x10]))  # full off wins
    assert pca.pulse_width_us(1) == 0.0
    pca.write(bytes([0x06, 0x00, 0x0F, 0x40, 0x00]))  # on 3840, off 64: wraps over the period end
    assert pca.pulse_width_us(0) == pytest.approx(320 * 1e6 * 31 / 25e6)
    pca.write(bytes([0xFA, 0, 0, 0, 0x10]))  # ALL_LED full off
    assert not any(pca.outputs_active(ch) for ch in range(16))
    pca.write(b"\xfa")
    assert pca.read(4) == b"\x00\x00\x00\x00"  # ALL_LED registers read as 0


def test_allcall_makes_a_mux_at_0x70_also_write_the_pca9685():
    bus = FakeI2CBus()
    mux = bus.attach(0x70, FakeTca9548a())
    pca = bus.attach(0x40, FakePca9685())
    bus.writeto(0x70, b"\x04")  # meant for the mux: the PCA9685 takes it as its register pointer
    assert mux.control == 0x04 and pca.pointer == 0x04


def test_adafruit_drivers_run_unchanged_against_the_fakes():
    import adafruit_pca9685
    from adafruit_ads1x15 import ads1115
    from adafruit_ads1x15.analog_in import AnalogIn
    bus = FakeI2CBus(require_lock=True)
    pca = bus.attach(0x40, FakePca9685())
    driver = adafruit_pca9685.PCA9685(bus, address=0x40)
    driver.frequency = 50
    assert pca.prescale == 121 and not pca.asleep and pca.auto_increment
    assert driver.frequency == pytest.approx(pca.frequency_hz())
    driver.channels[3].duty_cycle = 0x1000
    assert pca.pulse_width_us(3) == pytest.approx((0x1000 >> 4) * 1e6 * 122 / 25e6)
    adc = bus.attach(0x48, FakeAds1115())
    adc.set_input_voltage(1, 1.234)
    reader = ads1115.ADS1115(bus, gain=1, address=0x48)
    chan = AnalogIn(reader, 1)
    assert chan.value == pytest.approx(ads1115_code(1.234, 4.096), abs=2)
    assert chan.voltage == pytest.approx(1.234, abs=0.001)
    assert not bus.locked


def test_adafruit_tca9548a_deselect_failure_leaves_the_bus_locked():
    """The library defect our feedback driver avoids (docs/hardware_libraries.md) (see test_servo_feedback)."""
    import adafruit_tca9548a
    bus = FakeI2CBus()
    mux = bus.attach(0x71, FakeTca9548a())
    channel = adafruit_tca9548a.TCA9548A(bus, address=0x71)[0]
    assert channel.try_lock()
    mux.inject_deselect_failure()
    with pytest.raises(OSError):
        channel.unlock()
    assert bus.locked  # stuck: every later I2CDevice would spin forever


def test_build_fake_hardware_maps_joints():
    hw = load_hardware_config()
    fake = build_fake_hardware(hw)
    assert len(fake.adcs) == 12 and len({id(a) for a in fake.adcs.values()}) == 12
    volts = np.linspace(0.5, 2.9, 12)
    fake.set_joint_voltages(volts)
    for joint in hw.joints:
        assert fake.adcs[joint.index].inputs[joint.adc_input] == volts[joint.index]
        assert fake.mux.channel_bus(joint.mux_channel).device_at(joint.adc_address) is fake.adcs[joint.index]
    assert np.all(fake.pulse_widths_us() == 0.0)
    with pytest.raises(ValueError):
        fake.set_joint_voltages(volts[:3])
    with pytest.raises(ValueError):
        fake.set_joint_voltages(np.full(12, np.nan))


def test_package_imports_without_blinka():
    code = ("import sys\n"
            "import quadruped_drivers.i2c, quadruped_drivers.i2c.fake_bus, quadruped_drivers.i2c.fake_devices\n"
            "import quadruped_drivers.i2c.real_bus, quadruped_drivers.hardware_config\n"
            "import quadruped_drivers.calibration, quadruped_drivers.servo_feedback\n"
            "import quadruped_drivers.pwm_output, quadruped_drivers.servo_rig\n"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('busio', 'board', 'adafruit_blinka', "
            "'adafruit_platformdetect', 'adafruit_pca9685', 'adafruit_ads1x15', 'adafruit_tca9548a', "
            "'adafruit_extended_bus', 'rospy')]\n"
            "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_open_real_bus_fails_clearly_without_the_device():
    from quadruped_drivers.i2c.real_bus import I2CBackendError, open_i2c_bus
    with pytest.raises(I2CBackendError, match="i2c"):
        open_i2c_bus(250)
    with pytest.raises(ValueError):
        open_i2c_bus(-1)


def test_fake_hardware_for_a_long_running_server_keeps_no_log():
    # sim_node serves the drivers for hours: a log of every transaction grew its heap without bound
    # and its full garbage collections stalled the simulated robot (docs/sim_timing.md).
    hw = load_hardware_config()
    fake = build_fake_hardware(hw, log_transactions=False)
    fake.bus.writeto(hw.pca_address, bytes([0x00]))
    fake.bus.writeto(hw.mux_address, bytes([0x01]))
    assert fake.bus.log == []
    logged = build_fake_hardware(hw)
    logged.bus.writeto(hw.pca_address, bytes([0x00]))
    assert len(logged.bus.log) == 1


def test_pca9685_power_loss_leaves_the_bus_gives_no_pulses_and_comes_back_reset():
    hardware = load_hardware_config(None)
    fake = build_fake_hardware(hardware)
    pca = fake.pca
    address = hardware.pca_address
    # configure one channel as a driver would: awake, 1500 us on channel 0
    fake.bus.writeto(address, bytes([PCA_MODE1, PCA_AI | PCA_ALLCALL]))
    fake.bus.writeto(address, bytes([PCA_LED0_ON_L, 0, 0, 0x33, 0x01]))
    assert pca.pulse_width_us(0) > 0
    fake.set_pca_power(False)
    assert not fake.pca_powered
    assert (fake.pulse_widths_us() == 0).all()  # servos limp
    with pytest.raises(OSError) as info:
        fake.bus.writeto(address, bytes([PCA_MODE1, 0]))
    assert info.value.errno == errno.ENXIO
    fake.set_pca_power(False)  # idempotent
    fake.set_pca_power(True)
    assert fake.pca_powered and pca.asleep and (fake.pulse_widths_us() == 0).all()  # power-on reset
    fake.bus.writeto(address, bytes([PCA_MODE1, PCA_AI | PCA_ALLCALL]))  # ACKs again
