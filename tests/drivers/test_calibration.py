"""Calibration maps and the hardware and calibration loaders (the calibration procedure: tests/control/bringup)."""
import os
import tempfile

import numpy as np
import pytest
import yaml
from hypothesis import given, strategies as st

from quadruped_common.config import ParameterError, config_path
from quadruped_common.robot import JOINT_NAMES
from quadruped_control.model.params import load_robot_params
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


def test_save_is_atomic_and_loadable():
    directory = tempfile.mkdtemp(prefix="uqcal")
    path = os.path.join(directory, "c.yaml")
    save_servo_calibration(CAL.with_feedback(3, 1.1, -2.0, 0.001), path, note="test")
    loaded = load_servo_calibration(path)
    assert loaded.joints[3].feedback_fitted and loaded.joints[3].feedback_slope == pytest.approx(1.1)
    assert os.listdir(directory) == ["c.yaml"]
    os.unlink(path)
    os.rmdir(directory)
