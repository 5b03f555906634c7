"""VN-100 (FRD w.r.t. NED) <-> ROS (FLU w.r.t. ENU, REP-103/145) conversions on known attitudes."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from quadruped_common.so3 import quat_to_rot, rot_to_rpy, rot_x, rot_y, rot_z, rot_to_quat
from quadruped_drivers.vn100.conversions import ros_to_vn, vn_to_ros

G = 9.80665
R_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
R_FRD_FLU = np.diag([1.0, -1.0, -1.0])


def vn_quaternion(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """VN attitude from its 3-2-1 yaw/pitch/roll (UM001 Sec. 4.4.3): R_NED_FRD = Rz Ry Rx."""
    return rot_to_quat(rot_z(yaw) @ rot_y(pitch) @ rot_x(roll))


def same_rotation(q1, q2, tol=1e-9) -> bool:
    return abs(abs(float(np.dot(q1, q2))) - 1.0) < tol


def test_level_facing_north():
    reading = vn_to_ros([0, 0, 0, 1], [0, 0, 0], [0, 0, -G])
    roll, pitch, yaw = rot_to_rpy(quat_to_rot(reading.orientation_xyzw))
    assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert yaw == pytest.approx(math.pi / 2)  # North is ENU +y
    # REP-145: specific force, +g on z for a level, upright IMU.
    np.testing.assert_allclose(reading.linear_acceleration, [0, 0, G])
    assert reading.orientation_xyzw[3] >= 0.0


def test_heading_east_is_ros_yaw_zero():
    reading = vn_to_ros(vn_quaternion(math.pi / 2, 0, 0), [0, 0, 0], [0, 0, -G])
    assert same_rotation(reading.orientation_xyzw, [0, 0, 0, 1])


def test_heading_west_is_ros_yaw_pi():
    reading = vn_to_ros(vn_quaternion(-math.pi / 2, 0, 0), [0, 0, 0], [0, 0, -G])
    assert same_rotation(reading.orientation_xyzw, [0, 0, 1, 0])


def test_nose_up_pitch_keeps_sign_and_gravity_direction():
    pitch = math.radians(30)
    # Nose up 30 deg: the upward support force has a component along the raised nose (+x).
    accel_frd = [G * math.sin(pitch), 0.0, -G * math.cos(pitch)]
    np.testing.assert_allclose(accel_frd, rot_y(pitch).T @ np.array([0, 0, -G]), atol=1e-12)
    reading = vn_to_ros(vn_quaternion(math.pi / 2, pitch, 0), [0, 0, 0], accel_frd)
    roll, ros_pitch, yaw = rot_to_rpy(quat_to_rot(reading.orientation_xyzw))
    # ROS pitch is about +y = left, so nose up is negative pitch (right-hand rule).
    assert ros_pitch == pytest.approx(-pitch)
    assert (roll, yaw) == pytest.approx((0.0, 0.0), abs=1e-12)
    # The ROS orientation maps the measured specific force to +g up in ENU.
    world = quat_to_rot(reading.orientation_xyzw) @ reading.linear_acceleration
    np.testing.assert_allclose(world, [0, 0, G], atol=1e-12)
    assert reading.linear_acceleration[0] == pytest.approx(G * math.sin(pitch))


def test_roll_right_and_rates_flip_y_z():
    reading = vn_to_ros(vn_quaternion(math.pi / 2, 0, math.radians(20)), [0.1, 0.2, 0.3],
                        [1.0, 2.0, 3.0])
    roll, _, _ = rot_to_rpy(quat_to_rot(reading.orientation_xyzw))
    assert roll == pytest.approx(math.radians(20))  # right wing down = +roll about x in both
    np.testing.assert_allclose(reading.angular_velocity, [0.1, -0.2, -0.3])
    np.testing.assert_allclose(reading.linear_acceleration, [1.0, -2.0, -3.0])


def test_yaw_rate_sign():
    # Turning right (clockwise seen from above) is +r about Down and -wz about Up.
    reading = vn_to_ros([0, 0, 0, 1], [0, 0, 0.5], [0, 0, -G])
    assert reading.angular_velocity[2] == pytest.approx(-0.5)


unit = st.tuples(*[st.floats(-1, 1)] * 4).filter(lambda v: np.linalg.norm(v) > 0.1)
vec = st.tuples(*[st.floats(-100, 100)] * 3)
rate = st.tuples(*[st.floats(-30, 30)] * 3)  # inside the gyro range (+-2000 deg/s)


@given(unit, rate, vec)
def test_round_trip_and_matrix_identity(q, w, a):
    q = np.array(q) / np.linalg.norm(q)
    reading = vn_to_ros(q, w, a)
    expected = R_ENU_NED @ quat_to_rot(q) @ R_FRD_FLU
    np.testing.assert_allclose(quat_to_rot(reading.orientation_xyzw), expected, atol=1e-9)
    q_back, w_back, a_back = ros_to_vn(reading.orientation_xyzw, reading.angular_velocity,
                                       reading.linear_acceleration)
    assert same_rotation(q_back, q)
    np.testing.assert_allclose(w_back, w, atol=1e-12)
    np.testing.assert_allclose(a_back, a, atol=1e-12)
    # Physical vectors are frame-independent: rotate both into the world and compare.
    world_enu = quat_to_rot(reading.orientation_xyzw) @ reading.angular_velocity
    world_ned = quat_to_rot(q) @ np.array(w)
    np.testing.assert_allclose(R_ENU_NED @ world_ned, world_enu, atol=1e-9)


@pytest.mark.parametrize("q, w, a", [
    ([0, 0, 0, float("nan")], [0, 0, 0], [0, 0, 0]),
    ([0, 0, 0, 1], [0, float("inf"), 0], [0, 0, 0]),
    ([0, 0, 0, 1], [0, 0, 0], [0, 0, float("nan")]),
    ([0, 0, 0, 2], [0, 0, 0], [0, 0, 0]),
    ([0, 0, 0, 0], [0, 0, 0], [0, 0, 0]),
    ([0, 0, 1], [0, 0, 0], [0, 0, 0]),
    ([0, 0, 0, 1], [0, 0], [0, 0, 0]),
])
def test_invalid_input_raises(q, w, a):
    with pytest.raises(ValueError):
        vn_to_ros(q, w, a)
    with pytest.raises(ValueError):
        ros_to_vn(q, w, a)


def test_float32_quaternion_accepted():
    q = np.array(vn_quaternion(0.3, 0.2, 0.1), dtype=np.float32)
    reading = vn_to_ros(q, [0, 0, 0], [0, 0, -G])
    assert np.linalg.norm(reading.orientation_xyzw) == pytest.approx(1.0)
