"""SO(3) utilities (quadruped_common.so3): properties of hat/vee, exp/log, quaternions, RPY, errors."""
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from quadruped_common import so3
from quadruped_common.so3 import (attitude_error, exp_so3, geodesic_angle, hat, is_rotation, log_so3,
                                   orthonormalize, quat_conjugate, quat_multiply, quat_normalize,
                                   quat_to_rot, quaternions_to_rotations, rot_to_quat, rot_to_rpy, rot_x, rot_y,
                                   rot_z, rpy_to_rot, vee)

finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
vectors = st.tuples(finite, finite, finite).map(np.array)
unit_axes = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).map(np.array).filter(
    lambda v: np.linalg.norm(v) > 0.1).map(lambda v: v / np.linalg.norm(v))
angles = st.floats(-math.pi, math.pi)
quats = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).map(
    np.array).filter(lambda q: np.linalg.norm(q) > 0.1)
rotations = quats.map(quat_to_rot)

SETTINGS = settings(max_examples=150, deadline=None)


@SETTINGS
@given(vectors, vectors)
def test_hat_is_cross_product_and_vee_inverts_it(w, v):
    np.testing.assert_allclose(hat(w) @ v, np.cross(w, v), atol=1e-12)
    np.testing.assert_array_equal(vee(hat(w)), w)
    np.testing.assert_array_equal(hat(w), -hat(w).T)


@SETTINGS
@given(rotations)
def test_quat_to_rot_gives_rotation(R):
    assert is_rotation(R, 1e-12)


@SETTINGS
@given(quats)
def test_quaternion_round_trip_up_to_sign(q):
    R = quat_to_rot(q)
    q_back = rot_to_quat(R)
    qn = q / np.linalg.norm(q)
    assert q_back[3] >= 0.0
    assert np.allclose(q_back, qn, atol=1e-9) or np.allclose(q_back, -qn, atol=1e-9)
    np.testing.assert_allclose(quat_to_rot(-q), R, atol=1e-12)
    np.testing.assert_allclose(quat_to_rot(q_back), R, atol=1e-12)


@SETTINGS
@given(quats, quats)
def test_quat_multiply_composes_rotations_and_conjugate_inverts(q1, q2):
    q1, q2 = quat_normalize(q1), quat_normalize(q2)
    np.testing.assert_allclose(quat_to_rot(quat_multiply(q1, q2)), quat_to_rot(q1) @ quat_to_rot(q2),
                               atol=1e-12)
    np.testing.assert_allclose(quat_to_rot(quat_conjugate(q1)), quat_to_rot(q1).T, atol=1e-12)
    np.testing.assert_allclose(quat_multiply(q1, quat_conjugate(q1)), [0, 0, 0, 1], atol=1e-12)


def test_quaternion_convention_is_scalar_last():
    # 90 degrees about z: (x, y, z, w) = (0, 0, sin 45, cos 45)
    s = math.sqrt(0.5)
    np.testing.assert_allclose(quat_to_rot([0, 0, s, s]), rot_z(math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(rot_to_quat(rot_x(math.pi)), [1, 0, 0, 0], atol=1e-15)


@pytest.mark.parametrize("bad", [[0, 0, 0, 0], [1e-12, 0, 0, 0], [math.nan, 0, 0, 1], [math.inf, 0, 0, 1],
                                 [0, 0, 1]])
def test_bad_quaternions_are_rejected(bad):
    with pytest.raises(ValueError):
        quat_to_rot(bad)


@SETTINGS
@given(st.lists(quats, min_size=1, max_size=8))
def test_quaternions_to_rotations_is_quat_to_rot_row_by_row(rows):
    many = quaternions_to_rotations(np.array(rows) * 3.0)  # not unit: each row is normalised first
    assert many.shape == (len(rows), 3, 3)
    for q, R in zip(rows, many):
        np.testing.assert_allclose(R, quat_to_rot(q), rtol=0.0, atol=1e-15)


@pytest.mark.parametrize("bad", [[[0, 0, 0, 1], [0, 0, 0, 0]], [[0, 0, 0, 1], [math.nan, 0, 0, 1]], [[0, 0, 1]],
                                 [0, 0, 0, 1]])
def test_quaternions_to_rotations_rejects_a_bad_row_or_shape(bad):
    with pytest.raises(ValueError):
        quaternions_to_rotations(bad)


def test_quaternions_to_rotations_of_none_is_empty():
    assert quaternions_to_rotations(np.empty((0, 4))).shape == (0, 3, 3)


def test_rot_to_quat_rejects_non_finite():
    with pytest.raises(ValueError):
        rot_to_quat(np.full((3, 3), math.nan))


@SETTINGS
@given(angles, st.floats(-1.55, 1.55), angles)
def test_rpy_round_trip_away_from_gimbal_lock(roll, pitch, yaw):
    R = rpy_to_rot(roll, pitch, yaw)
    np.testing.assert_allclose(R, rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), atol=1e-14)
    r2, p2, y2 = rot_to_rpy(R)
    np.testing.assert_allclose(rpy_to_rot(r2, p2, y2), R, atol=1e-12)
    assert abs(p2 - pitch) < 1e-9
    # roll and yaw are unique modulo 2 pi away from gimbal lock
    assert abs(math.remainder(r2 - roll, 2 * math.pi)) < 1e-9
    assert abs(math.remainder(y2 - yaw, 2 * math.pi)) < 1e-9


@SETTINGS
@given(angles, st.sampled_from([math.pi / 2, -math.pi / 2]), angles,
       st.floats(-1e-10, 1e-10))
def test_rpy_at_gimbal_lock_still_reproduces_rotation(roll, pitch, yaw, nudge):
    R = rpy_to_rot(roll, pitch + nudge, yaw)
    result = rot_to_rpy(R)
    assert all(math.isfinite(a) for a in result)
    np.testing.assert_allclose(rpy_to_rot(*result), R, atol=1e-8)


def test_rpy_rejects_non_finite():
    with pytest.raises(ValueError):
        rpy_to_rot(math.nan, 0.0, 0.0)


@SETTINGS
@given(vectors)
def test_exp_log_round_trip(w):
    R = exp_so3(w)
    assert is_rotation(R, 1e-12)
    w_back = log_so3(R)
    assert np.linalg.norm(w_back) <= math.pi + 1e-12
    np.testing.assert_allclose(exp_so3(w_back), R, atol=1e-10)


@SETTINGS
@given(unit_axes, st.floats(0.0, math.pi - 1e-6))
def test_log_recovers_rotation_vector(n, angle):
    np.testing.assert_allclose(log_so3(exp_so3(angle * n)), angle * n, atol=1e-9)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-8, 1e-5, 1e-3, math.pi - 1e-3, math.pi - 1e-6,
                                   math.pi - 1e-8, math.pi])
def test_exp_log_at_awkward_angles(angle):
    n = np.array([0.3, -0.4, 0.5])
    n /= np.linalg.norm(n)
    R = exp_so3(angle * n)
    assert is_rotation(R, 1e-12)
    w = log_so3(R)
    assert abs(np.linalg.norm(w) - angle) < 1e-9
    if angle < math.pi:
        np.testing.assert_allclose(w, angle * n, atol=1e-7)
    np.testing.assert_allclose(exp_so3(w), R, atol=1e-12)


def test_exp_matches_elementary_rotation():
    np.testing.assert_allclose(exp_so3([0.7, 0, 0]), rot_x(0.7), atol=1e-15)
    np.testing.assert_allclose(exp_so3([0, 0, -2.0]), rot_z(-2.0), atol=1e-15)


def test_exp_rejects_non_finite():
    with pytest.raises(ValueError):
        exp_so3([math.inf, 0, 0])


@SETTINGS
@given(rotations, unit_axes, st.floats(-math.pi, math.pi))
def test_attitude_error_is_sin_angle_axis_in_body_frame(R_d, n, a):
    R = R_d @ exp_so3(a * n)
    np.testing.assert_allclose(attitude_error(R_d, R), math.sin(a) * n, atol=1e-12)


@SETTINGS
@given(rotations, rotations)
def test_attitude_error_zero_iff_equal(R_d, R):
    err = attitude_error(R_d, R)
    angle = geodesic_angle(R_d, R)
    # e_R vanishes only at angle 0 and at angle pi (the known antipodal critical point of eq. error).
    assert np.linalg.norm(err) == pytest.approx(abs(math.sin(angle)), abs=1e-12)
    assume(angle < math.pi - 1e-3)
    assert (np.linalg.norm(err) < 1e-9) == (angle < 1e-9)
    np.testing.assert_allclose(attitude_error(R_d, R_d), np.zeros(3), atol=1e-15)


@SETTINGS
@given(rotations, unit_axes, st.floats(0.0, math.pi))
def test_geodesic_angle_equals_rotation_angle_and_is_symmetric(R_d, n, a):
    R = R_d @ exp_so3(a * n)
    assert geodesic_angle(R_d, R) == pytest.approx(a, abs=1e-12)
    assert geodesic_angle(R, R_d) == pytest.approx(geodesic_angle(R_d, R), abs=1e-12)
    assert 0.0 <= geodesic_angle(R_d, R) <= math.pi


@pytest.mark.parametrize("angle", [1e-12, 1e-8, 1e-4, 1.0, math.pi - 1e-4, math.pi - 1e-8, math.pi])
def test_geodesic_angle_is_accurate_near_zero_and_pi(angle):
    n = np.array([1.0, 2.0, -2.0]) / 3.0
    R_d = rpy_to_rot(0.3, -0.5, 2.0)
    R = R_d @ exp_so3(angle * n)
    # arccos((tr - 1) / 2) would give ~1e-8 error here near 0 and pi; atan2 keeps ~1e-15.
    assert abs(geodesic_angle(R_d, R) - angle) < 1e-14 * max(1.0, angle) + 1e-15
    assert abs(geodesic_angle(R, R_d) - angle) < 1e-14 * max(1.0, angle) + 1e-15


@SETTINGS
@given(rotations, st.lists(st.floats(-1e-3, 1e-3), min_size=9, max_size=9))
def test_orthonormalize_returns_nearby_rotation(R, noise):
    noisy = R + np.reshape(noise, (3, 3))
    fixed = orthonormalize(noisy)
    assert is_rotation(fixed, 1e-12)
    assert np.max(np.abs(fixed - R)) < 1e-2
    np.testing.assert_allclose(orthonormalize(R), R, atol=1e-12)


def test_orthonormalize_never_returns_a_reflection_and_rejects_nan():
    assert is_rotation(orthonormalize(np.diag([1.0, 1.0, -1.0])), 1e-12)
    with pytest.raises(ValueError):
        orthonormalize(np.full((3, 3), math.nan))


def test_is_rotation_rejects_non_rotations():
    assert is_rotation(np.eye(3))
    assert not is_rotation(np.diag([1.0, 1.0, -1.0]))
    assert not is_rotation(2.0 * np.eye(3))
    assert not is_rotation(np.full((3, 3), math.nan))
    assert not is_rotation(np.eye(2))


@given(st.floats(-1e3, 1e3))
def test_wrap_angle_is_in_range_and_keeps_the_direction(angle):
    wrapped = so3.wrap_angle(angle)
    assert isinstance(wrapped, float)
    assert -math.pi <= wrapped < math.pi
    assert math.cos(wrapped) == pytest.approx(math.cos(angle), abs=1e-9)
    assert math.sin(wrapped) == pytest.approx(math.sin(angle), abs=1e-9)
    assert float(so3.wrap_angle(np.array([angle]))[0]) == wrapped  # the array form agrees exactly


def test_wrap_angle_convention_is_half_open_at_pi():
    assert so3.wrap_angle(math.pi) == -math.pi
    assert so3.wrap_angle(-math.pi) == -math.pi
    np.testing.assert_allclose(so3.wrap_angle([3 * math.pi, -0.5 * math.pi - 4 * math.pi]), [-math.pi, -0.5 * math.pi])



def test_vectorised_angles_are_the_scalar_functions_bits():
    """geodesic_angles and rotations_to_rpy give exactly what geodesic_f and rpy_f give (the per-trial and
    the batched simulators record the same bits), on any CPU: no numpy SIMD atan2 (AVX-512 differs)."""
    from quadruped_common.so3 import atan2_elementwise, geodesic_angles, geodesic_f, rotations_to_rpy, rpy_f
    rng = np.random.default_rng(7)
    R = np.array([rpy_to_rot(*rng.uniform(-3.0, 3.0, 3)) for _ in range(400)])
    setpoint = rpy_to_rot(0.3, -0.2, 0.1)
    expected = [geodesic_f(tuple(setpoint.ravel()), tuple(r.ravel())) for r in R]
    np.testing.assert_array_equal(geodesic_angles(setpoint, R), expected)
    expected_rpy = [rpy_f(r[0, 0], r[0, 1], r[0, 2], r[1, 0], r[2, 0], r[2, 1], r[2, 2]) for r in R]
    np.testing.assert_array_equal(rotations_to_rpy(R), expected_rpy)
    y, x = rng.uniform(-1, 1, 1000), rng.uniform(-1, 1, 1000)
    np.testing.assert_array_equal(atan2_elementwise(y, x), [math.atan2(a, b) for a, b in zip(y, x)])
