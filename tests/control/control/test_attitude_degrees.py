"""The operator's attitude in degrees (quadruped_control.control.attitude_degrees): REP-103 angles of the measured
and commanded attitude, and their difference wrapped to [-180, 180)."""
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from quadruped_common.so3 import rot_to_quat, rot_z, rpy_to_rot
from quadruped_control.control.attitude_degrees import attitude_degrees, rpy_degrees, wrap_degrees
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.control.supervisor import ControlSupervisor
from quadruped_control.model.params import load_robot_params

angles = st.floats(-1e4, 1e4, allow_nan=False)


@given(angles)
def test_wrapping_lands_in_the_half_open_circle_and_keeps_the_angle(angle):
    wrapped = wrap_degrees(angle)
    assert -180.0 <= wrapped < 180.0
    assert math.isclose(math.cos(math.radians(wrapped)), math.cos(math.radians(angle)), abs_tol=1e-9)
    assert math.isclose(math.sin(math.radians(wrapped)), math.sin(math.radians(angle)), abs_tol=1e-9)


def test_wrapping_edges():
    assert wrap_degrees(180.0) == -180.0 and wrap_degrees(-180.0) == -180.0 and wrap_degrees(190.0) == -170.0
    assert math.isnan(wrap_degrees(math.nan))


def test_rep103_angles_in_degrees():
    assert rpy_degrees(rpy_to_rot(math.radians(30), math.radians(-20), math.radians(100))) == pytest.approx(
        (30.0, -20.0, 100.0))
    # x roll, y pitch, z yaw: a pure yaw of the world ENU frame is z
    assert rpy_degrees(rot_z(math.radians(90))) == pytest.approx((0.0, 0.0, 90.0))


def test_the_error_is_setpoint_minus_measured_wrapped_across_the_yaw_seam():
    R = rpy_to_rot(math.radians(10), 0.0, math.radians(170))
    R_d = rpy_to_rot(math.radians(30), math.radians(5), math.radians(-170))
    view = attitude_degrees(R, R_d)
    assert view.rpy == pytest.approx((10.0, 0.0, 170.0))
    assert view.setpoint == pytest.approx((30.0, 5.0, -170.0))
    assert view.error == pytest.approx((20.0, 5.0, 20.0))  # -170 - 170 = -340 -> +20: the short way round


def test_without_a_measured_attitude_only_the_setpoint_is_known():
    view = attitude_degrees(None, np.eye(3))
    assert view.setpoint == pytest.approx((0.0, 0.0, 0.0))
    assert all(math.isnan(v) for v in view.rpy + view.error)


def test_the_supervisor_gives_the_attitude_of_its_latest_plausible_imu_sample():
    sup = ControlSupervisor(AttitudeController(load_robot_params(), load_controller_config(gain_set="simulation")),
                            lambda q: np.asarray(q))
    assert sup.attitude() is None
    R = rpy_to_rot(0.3, -0.2, 1.0)
    sup.set_imu(rot_to_quat(R), (0.0, 0.0, 0.0), 0.0)
    assert np.allclose(sup.attitude(), R)
    assert sup.set_imu((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01)  # dropped: the last plausible one stays
    assert np.allclose(sup.attitude(), R)
