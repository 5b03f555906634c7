"""Calibration maps, config loaders and the calibrate CLI end-to-end on the simulated servo rig."""
import math
import os
import tempfile

import numpy as np
import pytest
import yaml
from hypothesis import given, strategies as st

from quadruped_common.config import ParameterError, config_path
from quadruped_common.robot import JOINT_NAMES
from quadruped_control.model.params import load_robot_params
from quadruped_drivers import calibrate
from quadruped_drivers.calibration import (calibration_to_yaml, load_servo_calibration, save_servo_calibration,
                                           servo_calibration_from_dict)
from quadruped_drivers.hardware_config import hardware_config_from_dict, load_hardware_config

CAL = load_servo_calibration()
HW = load_hardware_config()


def hardware_tree():
    with open(config_path("hardware.yaml")) as stream:
        return yaml.safe_load(stream)


def test_joint_ranges_map_into_500_2500_us():
    limits = load_robot_params().joint_limits.as_array()
    for bound in (0, 1):
        angles = np.array([limits[i % 3, bound] for i in range(12)])
        pulses = CAL.angles_to_pulses(angles)
        np.testing.assert_allclose(pulses, 500.0 if bound == 0 else 2500.0, atol=1e-6)
    mid = np.radians([-140.0, -40.0, 90.0] * 4)
    np.testing.assert_allclose(CAL.angles_to_pulses(mid), 1500.0)


@given(st.lists(st.floats(-4.0, 4.0), min_size=12, max_size=12))
def test_maps_round_trip(angles):
    q = np.array(angles)
    np.testing.assert_allclose(CAL.pulses_to_angles(CAL.angles_to_pulses(q)), q, atol=1e-9)
    np.testing.assert_allclose(CAL.volts_to_angles(CAL.angles_to_volts(q)), q, atol=1e-9)


def test_nan_and_shape_raise():
    q = np.zeros(12)
    q[4] = np.nan
    for function in (CAL.angles_to_pulses, CAL.pulses_to_angles, CAL.volts_to_angles, CAL.angles_to_volts):
        with pytest.raises(ValueError, match="leg2_motor2"):
            function(q)
        with pytest.raises(ValueError):
            function(np.zeros(11))


def test_calibration_file_round_trip_and_errors():
    tree = yaml.safe_load(calibration_to_yaml(CAL))
    again = servo_calibration_from_dict(tree)
    q = np.radians([-150.0, -20.0, 60.0] * 4)
    np.testing.assert_allclose(again.angles_to_pulses(q), CAL.angles_to_pulses(q))
    np.testing.assert_allclose(again.volts_to_angles(np.full(12, 1.2)), CAL.volts_to_angles(np.full(12, 1.2)))
    bad = yaml.safe_load(calibration_to_yaml(CAL))
    bad["joints"]["leg3_hip"]["direction"] = 2
    with pytest.raises(ParameterError, match="leg3_hip.direction"):
        servo_calibration_from_dict(bad)
    bad = yaml.safe_load(calibration_to_yaml(CAL))
    del bad["joints"]["leg1_motor1"]["us_per_deg"]
    with pytest.raises(ParameterError, match="leg1_motor1.us_per_deg"):
        servo_calibration_from_dict(bad)
    with pytest.raises(ParameterError, match="cannot read"):
        load_servo_calibration("/nonexistent/servo_calibration.yaml")


def test_hardware_config_values():
    assert HW.mux_address == 0x71 and HW.pca_address == 0x40 and HW.pwm_frequency_hz == 50.0
    assert HW.adc_full_scale_v == 4.096 and HW.adc_data_rate == 860
    assert [j.name for j in HW.joints] == list(JOINT_NAMES)
    assert sorted({(j.mux_channel, j.adc_address) for j in HW.joints}) == sorted(
        (c, a) for c in range(3) for a in range(0x48, 0x4C))


@pytest.mark.parametrize("path, value, message", [
    (("mux", "address"), 0x70, "all-call"),
    (("joints", "leg1_hip", "pwm_channel"), 0, "already used by leg1_motor1"),
    (("joints", "leg1_hip", "adc_address"), 0x48, "one ADC per joint"),
    (("joints", "leg2_hip", "min_us"), 2600, "must be below max_us"),
    (("joints", "leg2_hip", "failsafe"), "explode", "failsafe"),
    (("adc", "full_scale_v"), 3.3, "not an ADS1115 range"),
    (("adc", "data_rate_sps"), 100, "not an ADS1115 rate"),
    (("adc", "failed_after_s"), 0.01, "must exceed"),
    (("adc", "jump_confirm_readings"), 0, "adc.jump_confirm_readings"),
    (("adc", "jump_margin_deg"), -1.0, "adc.jump_margin_deg"),
    (("pca9685", "frequency_hz"), "fifty", "must be a number"),
    (("i2c", "bus"), -1, "outside"),
])
def test_hardware_config_errors(path, value, message):
    tree = hardware_tree()
    node = tree
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(ParameterError, match=message):
        hardware_config_from_dict(tree)


def test_hardware_config_missing_joint():
    tree = hardware_tree()
    del tree["joints"]["leg4_hip"]
    with pytest.raises(ParameterError, match="joints.leg4_hip"):
        hardware_config_from_dict(tree)


def test_fit_feedback_rejects_a_joint_that_does_not_move_or_fits_poorly():
    angles = np.linspace(-1.0, 1.0, 7)
    slope, offset, rms, r = calibrate.fit_feedback("j", angles, (angles - 0.2) / 1.3)
    assert slope == pytest.approx(1.3) and offset == pytest.approx(0.2) and rms < 1e-9 and r > 0.999
    with pytest.raises(calibrate.CalibrationError, match="does not move"):
        calibrate.fit_feedback("j", angles, np.full(7, 1.65) + 0.001 * np.arange(7))
    with pytest.raises(calibrate.CalibrationError, match="poor fit"):
        calibrate.fit_feedback("j", angles, np.array([0.5, 2.5, 0.7, 2.2, 0.9, 2.9, 1.0]))


def test_calibrate_cli_end_to_end_on_the_fake_rig(capsys):
    directory = tempfile.mkdtemp(prefix="uqcal")
    out = os.path.join(directory, "cal.yaml")
    code = calibrate.main(["--fake", "--out", out, "--joints", "leg1_motor1", "leg3_hip", "--points", "5",
                           "--settle", "0.2", "--seed", "3"])
    assert code == 0, capsys.readouterr().err
    result = load_servo_calibration(out)
    rig = calibrate.SimulatedServoRig(HW, CAL)  # the same known map the CLI's rig uses
    for index in (0, 8):
        joint = result.joints[index]
        assert joint.feedback_fitted
        assert joint.feedback_slope == pytest.approx(rig.true_slope[index], rel=0.01)
        assert joint.feedback_offset == pytest.approx(rig.true_offset[index], abs=math.radians(1.0))
    untouched = result.joints[1]
    assert not untouched.feedback_fitted and untouched.feedback_slope == CAL.joints[1].feedback_slope
    q = np.radians([-150.0, -20.0, 60.0] * 4)
    np.testing.assert_allclose(result.angles_to_pulses(q), CAL.angles_to_pulses(q))  # pulse maps kept
    os.unlink(out)
    os.rmdir(directory)


def test_calibrate_reports_a_dead_feedback_and_writes_nothing(monkeypatch, capsys):
    original = calibrate.SimulatedServoRig._feed

    def dead_feed(self):
        original(self)
        self.hardware.adcs[2].set_input_voltage(0, 1.0)  # leg1_hip feedback stuck

    monkeypatch.setattr(calibrate.SimulatedServoRig, "_feed", dead_feed)
    out = os.path.join(tempfile.mkdtemp(prefix="uqcal"), "cal.yaml")
    code = calibrate.main(["--fake", "--out", out, "--joints", "leg1_hip", "--points", "4", "--settle", "0.1"])
    assert code == 1 and not os.path.exists(out)
    assert "does not move" in capsys.readouterr().err


def test_calibrate_cli_argument_errors():
    with pytest.raises(SystemExit):
        calibrate.main(["--fake", "--joints", "leg9_hip"])
    with pytest.raises(SystemExit):
        calibrate.main(["--fake", "--points", "2"])


def test_save_is_atomic_and_loadable():
    directory = tempfile.mkdtemp(prefix="uqcal")
    path = os.path.join(directory, "c.yaml")
    save_servo_calibration(CAL.with_feedback(3, 1.1, -2.0, 0.001), path, note="test")
    loaded = load_servo_calibration(path)
    assert loaded.joints[3].feedback_fitted and loaded.joints[3].feedback_slope == pytest.approx(1.1)
    assert os.listdir(directory) == ["c.yaml"]
    os.unlink(path)
    os.rmdir(directory)
