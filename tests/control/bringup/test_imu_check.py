"""The IMU mount check: a level and two guided tilts find a rotated IMU, and tolerate an operator's hold."""
from __future__ import annotations

import numpy as np
import pytest

from quadruped_control.bringup.imu_check import check_imu_mount, stand_readings
from quadruped_control.studies.bringup_faults import draw_fault, operator_readings
from quadruped_drivers.hardware_faults import HardwareFaults


@pytest.mark.parametrize("mount", [(0, 0, 90), (0, 0, -20), (180, 0, 0), (0, 15, 0), (10, 0, 0), (30, -40, 170)])
def test_a_rotated_imu_is_found(mount):
    result = check_imu_mount(stand_readings(mount, noise=0.02, rng=np.random.default_rng(1)))
    assert not result.passed and "register 26" in result.problems[0]


@pytest.mark.parametrize("mount", [(0, 0, 0), (2, -2, 0), (0, 0, 5)])
def test_a_small_mount_error_passes(mount):
    assert check_imu_mount(stand_readings(mount, noise=0.02, rng=np.random.default_rng(2))).passed


def test_an_operator_who_did_not_tilt_is_not_a_pass():
    result = check_imu_mount(stand_readings((0, 0, 0), tilt_deg=5.0))
    assert not result.passed and "tilt further" in result.problems[0]


@pytest.mark.parametrize("readings", [[[0, 0, 9.81]], [[0, 0, 9.81], [0, 0, float("nan")], [0, 0, 9.81]]])
def test_bad_readings_are_refused(readings):
    assert not check_imu_mount(readings).passed


def test_gravity_off_scale_is_reported():
    assert "gravity reads" in check_imu_mount(stand_readings((0, 0, 0)) * 1.2).problems[0]


def test_rough_holds_never_alarm_and_rotations_past_15_deg_are_always_found():
    for seed in range(200):
        rng = np.random.default_rng(seed)
        assert check_imu_mount(operator_readings(HardwareFaults(), rng)).passed
        faults, _ = draw_fault(rng, "imu_rotated", 3.0)
        assert not check_imu_mount(operator_readings(faults, rng)).passed
