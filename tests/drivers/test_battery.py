"""The LiPo packs: configuration (hardware.yaml ``batteries``), levels with hysteresis and health/battery, and
their reads on the feedback ADCs' spare inputs, interleaved with the joint reads (against the fakes)."""
import dataclasses
import math

import numpy as np
import pytest
import yaml

from quadruped_common.config import ParameterError, config_path
from quadruped_common.health import ERROR, OK, WARN
from quadruped_drivers.battery import (LIPO_CURVE, BatteryMonitor, PackMonitor, lipo_charge,
                                       lipo_open_circuit_voltage)
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import hardware_config_from_dict, load_hardware_config, with_batteries_fitted
from quadruped_drivers.i2c.fake_devices import build_fake_hardware
from quadruped_drivers.servo_feedback import ServoFeedbackArray, SpareInput

SHIPPED = load_hardware_config()
HW = with_batteries_fitted(SHIPPED)  # the simulated robot's: both packs
MOTORS, ELECTRONICS = HW.batteries.packs


def hardware_tree():
    with open(config_path("hardware.yaml")) as stream:
        return yaml.safe_load(stream)


# --- configuration ---------------------------------------------------------------------------------
def test_shipped_batteries_section():
    assert SHIPPED.batteries.fitted == ()  # the paper's robot has no dividers
    assert [pack.name for pack in HW.batteries.fitted] == ["motors", "electronics"]
    assert (MOTORS.cells, MOTORS.divider_ratio, MOTORS.mux_channel, MOTORS.adc_address, MOTORS.adc_input) == (
        2, 3.0, 0, 0x48, 1)
    assert (ELECTRONICS.cells, ELECTRONICS.divider_ratio, ELECTRONICS.mux_channel) == (4, 6.0, 1)
    assert HW.batteries.rate_hz == 2.0 and HW.batteries.stale_after_s == 2.0 and HW.batteries.confirm_readings == 2


@pytest.mark.parametrize("pack, key, value, message", [
    ("motors", "adc_address", 0x4C, "batteries.packs.motors.adc_address"),
    ("motors", "mux_channel", 5, "no joint's ADS1115 at 0x48 on mux channel 5"),
    ("motors", "adc_input", 0, "is leg1_motor1's feedback input"),
    ("electronics", "mux_channel", 0, "already the motors pack's"),
    ("electronics", "divider_ratio", 4.0, "a full 4S pack \\(17.40 V\\) gives 4.35 V at the ADC"),
    ("motors", "critical_cell_v", 3.7, "must be below warn_cell_v"),
    ("motors", "cells", 0, "batteries.packs.motors.cells"),
    ("motors", "fitted", "maybe", "batteries.packs.motors.fitted"),
])
def test_bad_pack_configuration_is_refused_naming_the_key(pack, key, value, message):
    tree = hardware_tree()
    tree["batteries"]["packs"][pack][key] = value
    with pytest.raises(ParameterError, match=message):
        hardware_config_from_dict(tree)


def test_section_errors_and_unfitted_packs():
    tree = hardware_tree()
    tree["batteries"]["stale_after_s"] = 0.5
    with pytest.raises(ParameterError, match="at least 2 / batteries.rate_hz"):
        hardware_config_from_dict(tree)
    tree = hardware_tree()
    del tree["batteries"]["packs"]["electronics"]
    with pytest.raises(ParameterError, match="missing hardware parameter 'batteries.packs.electronics'"):
        hardware_config_from_dict(tree)
    tree = hardware_tree()
    tree["batteries"]["packs"]["electronics"].update(fitted=False, mux_channel=0, adc_input=1)  # checked, fitted or not
    with pytest.raises(ParameterError, match="already the motors pack's"):
        hardware_config_from_dict(tree)
    tree = hardware_tree()
    tree["batteries"]["packs"]["motors"]["fitted"] = True
    assert [pack.name for pack in hardware_config_from_dict(tree).batteries.fitted] == ["motors"]


# --- LiPo curve and levels -----------------------------------------------------------------------------
def test_lipo_curve():
    assert lipo_charge(4.2) == 1.0 and lipo_charge(4.3) == 1.0 and lipo_charge(3.0) == 0.0
    assert lipo_charge(3.84) == pytest.approx(0.5) and math.isnan(lipo_charge(math.nan))
    volts = [v for v, _ in LIPO_CURVE]
    assert volts == sorted(volts)
    for charge in np.linspace(0.0, 1.0, 41):
        assert lipo_charge(lipo_open_circuit_voltage(charge)) == pytest.approx(charge, abs=1e-9)


def pack_monitor(**changes):
    return PackMonitor(dataclasses.replace(MOTORS, **changes), full_scale_v=4.096, confirm_readings=2,
                       stale_after=2.0)


def feed(monitor, cell_volts, t0=0.0, period=0.5):
    """Feed mean cell voltages (as ADC volts through the divider); the levels after each."""
    levels = []
    for i, cell in enumerate(cell_volts):
        status = monitor.update(t0 + i * period, cell * monitor.pack.cells / monitor.pack.divider_ratio)
        levels.append((status.level, status.reason))
    return levels


def test_levels_need_confirmation_and_hysteresis():
    monitor = pack_monitor()
    assert monitor.status(0.0)[:2] == (ERROR, "no_reading")
    levels = feed(monitor, [3.9, 3.59, 3.9, 3.59, 3.58, 3.62, 3.69, 3.71, 3.39, 3.38, 3.45, 3.51, 3.75])
    assert levels == [(OK, ""),
                      (OK, ""), (OK, ""),                 # one reading below warn is a sag, not a flat pack
                      (OK, ""), (WARN, "low"),            # two in a row: WARN
                      (WARN, "low"), (WARN, "low"),       # 3.62, 3.69: within the 0.1 V hysteresis of 3.6
                      (OK, ""),                           # 3.71 >= 3.6 + 0.1
                      (OK, ""), (ERROR, "critical"),      # two below critical: ERROR at once from OK
                      (ERROR, "critical"),                # 3.45 < 3.4 + 0.1
                      (WARN, "low"), (OK, "")]
    status = monitor.last
    assert status.voltage == pytest.approx(7.5) and status.cell_voltage == pytest.approx(3.75)
    assert status.charge == pytest.approx(lipo_charge(3.75)) and status.present


def test_hovering_at_a_threshold_does_not_flicker():
    monitor = pack_monitor()
    levels = feed(monitor, [3.8] + [3.58, 3.58] + [3.61, 3.59] * 20)
    assert [level for level, _ in levels[3:]] == [WARN] * 40


def test_absent_implausible_stale_and_failed_reads():
    monitor = pack_monitor()
    assert feed(monitor, [0.0]) == [(ERROR, "absent")] and not monitor.last.present
    assert "no pack" in monitor.status(0.1)[2]
    assert feed(monitor, [3.9], t0=1.0) == [(OK, "")]  # plugged in: OK at once
    assert feed(monitor, [4.5], t0=2.0) == [(ERROR, "implausible")]  # 2S read as 9 V: cells or divider wrong
    assert monitor.update(3.0, 4.096).reason == "implausible"  # the ADC saturated
    assert monitor.update(4.0, None) is None and monitor.update(4.5, math.nan) is None
    assert monitor.counts == {"readings": 4, "read_errors": 2, "absent": 1, "implausible": 2}
    assert monitor.status(3.0 + 2.01)[:2] == (ERROR, "stale")


def test_health_is_the_worst_pack():
    monitor = BatteryMonitor(HW.batteries, HW.adc_full_scale_v)
    health = monitor.health(0.0)
    assert health.level == ERROR and health.reason == "motors:no_reading,electronics:no_reading"
    monitor.update("motors", 0.0, 3.9 * 2 / 3.0)
    monitor.update("electronics", 0.0, 3.9 * 4 / 6.0)
    health = monitor.health(0.1)
    assert health.level == OK and health.reason == "" and "motors: 7.80 V (3.90 V/cell" in health.message
    for t in (0.5, 1.0):
        monitor.update("electronics", t, 3.5 * 4 / 6.0)
    health = monitor.health(1.1)
    assert health.level == WARN and health.reason == "electronics:low"
    assert dict(health.values)["electronics level"] == "WARN"
    assert monitor.health(2.5).reason == "motors:stale"  # motors' last reading 2.5 s old
    unfitted = dataclasses.replace(HW.batteries, packs=tuple(dataclasses.replace(p, fitted=False)
                                                             for p in HW.batteries.packs))
    assert BatteryMonitor(unfitted, 4.096).health(0.0).reason == "not_fitted"


# --- reads on the spare inputs, between the joint reads ------------------------------------------------
class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def spare_rig():
    cal = load_servo_calibration()
    fake = build_fake_hardware(HW, require_lock=True)
    clock = Clock()
    spares = [SpareInput(p.name, p.mux_channel, p.adc_address, p.adc_input) for p in HW.batteries.fitted]
    feedback = ServoFeedbackArray(fake.bus, HW, cal, clock=clock, spare_inputs=spares, spare_period=0.5)
    volts = np.linspace(0.5, 2.9, 12)
    fake.set_joint_voltages(volts)
    fake.set_spare_voltage(0, 0x48, 1, 7.6 / 3.0)
    fake.set_spare_voltage(1, 0x48, 1, 15.0 / 6.0)
    assert feedback.start() == []
    return fake, clock, feedback, volts


def test_spare_inputs_are_read_at_their_rate_and_the_joints_barely_notice():
    fake, clock, feedback, volts = spare_rig()
    valid = np.zeros(12)
    lent = np.zeros(12)
    samples = []
    cycles = 1000  # 10 s at 100 Hz
    for _ in range(cycles):
        clock.t += 0.01
        reading = feedback.read()
        assert reading.stale == [] and reading.failed == [] and reading.implausible == []
        valid += reading.valid
        lent[reading.lent] += 1
        assert np.all(np.isfinite(reading.held_angles))  # what the node publishes for a lent joint
        assert np.allclose(reading.volts[reading.valid], volts[reading.valid], atol=2 * 4.096 / 32768)
        samples += feedback.take_spare_samples()
    names = [sample.name for sample in samples]
    assert names.count("motors") == names.count("electronics") == 20  # 2 Hz each, on a grid
    for sample in samples:
        expected = 7.6 / 3.0 if sample.name == "motors" else 15.0 / 6.0
        assert sample.volts == pytest.approx(expected, abs=4.096 / 32768)
    hosts = [HW.joint("leg1_motor1").index, HW.joint("leg2_motor2").index]
    # each host joint lends its ADC once per read of its pack (2 Hz): 98 % of its samples are its own
    assert list(np.flatnonzero(lent)) == hosts and np.all(lent[hosts] == pytest.approx(20, abs=1))
    assert np.all(valid[hosts] >= cycles - 21) and np.all(np.delete(valid, hosts) == cycles)
    assert feedback.config_losses.sum() == 0 and feedback.spare_errors == {"motors": 0, "electronics": 0}
    # and every joint's ADC is back on its own input
    for joint in HW.joints:
        assert fake.adcs[joint.index].mux == (joint.adc_input, None)


def test_a_failed_spare_read_is_a_nan_sample_and_the_joint_recovers():
    fake, clock, feedback, volts = spare_rig()
    clock.t += 0.01
    feedback.read()  # the motors read starts: its ADC switched to the battery input
    host = HW.joint("leg1_motor1")
    fake.mux.channel_bus(0).inject_fault(host.adc_address, "nack")
    clock.t += 0.01
    feedback.read()
    samples = feedback.take_spare_samples()
    assert [(s.name, math.isnan(s.volts)) for s in samples] == [("motors", True)]
    assert feedback.spare_errors["motors"] == 1
    for _ in range(3):
        clock.t += 0.01
        reading = feedback.read()
    assert reading.valid[host.index] and fake.adcs[host.index].mux == (host.adc_input, None)


def test_a_switch_that_did_not_take_is_never_read_as_the_battery():
    fake, clock, feedback, volts = spare_rig()
    host = HW.joint("leg1_motor1")
    clock.t += 0.01
    feedback.read()  # the motors read starts
    fake.adcs[host.index].power_cycle()  # brown-out: back to its defaults, the switch lost
    clock.t += 0.01
    feedback.read()
    assert [(s.name, math.isnan(s.volts)) for s in feedback.take_spare_samples()] == [("motors", True)]
    assert feedback.config_losses[host.index] == 1 and feedback.spare_errors["motors"] == 1
    clock.t += 0.01
    assert feedback.read().valid[host.index]


def test_spare_input_must_be_free_on_a_joints_adc():
    cal = load_servo_calibration()
    fake = build_fake_hardware(HW)
    with pytest.raises(ValueError, match="no joint's ADS1115"):
        ServoFeedbackArray(fake.bus, HW, cal, spare_inputs=[SpareInput("x", 0, 0x48, 0)])
