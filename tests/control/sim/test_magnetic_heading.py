"""The heading a tilt-compensating AHRS reports with a residual field at the IMU (sim/magnetic_heading.py)."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.so3 import rotations_to_rpy, rpy_to_rot
from quadruped_control.sim.magnetic_heading import heading_error, reported_rotation, true_rotation

angles = st.floats(-math.pi, math.pi, allow_nan=False)
tilts = st.floats(-1.3, 1.3, allow_nan=False)  # away from pitch +-90 deg, where the heading is undefined
fields = st.floats(-0.9, 0.9, allow_nan=False)


def test_no_residual_reports_the_true_heading():
    R = np.array([rpy_to_rot(0.4, -0.7, 2.9), rpy_to_rot(-2.0, 0.3, -1.0)])
    assert np.allclose(heading_error(R, np.zeros((2, 3))), 0.0, atol=1e-15)
    np.testing.assert_allclose(reported_rotation(R, np.zeros(3)), R, rtol=0, atol=1e-15)


def test_a_vertical_residual_turns_the_heading_only_when_tilted_across_north():
    """Rolled by phi with a residual b_z (units of H): the levelled residual is (0, -b_z sin phi) in the heading
    frame. Facing east (psi = 0) it lies along north and changes nothing; facing north (psi = 90 deg) it
    is across it: psi_m = atan2(1, -b_z sin phi)."""
    b = np.array([0.0, 0.0, 0.3])
    level = rpy_to_rot(0.0, 0.0, math.radians(90.0))
    assert heading_error(level, b) == pytest.approx(0.0, abs=1e-15)
    rolled_east = rpy_to_rot(math.radians(45.0), 0.0, 0.0)
    assert heading_error(rolled_east, b) == pytest.approx(0.0, abs=1e-15)
    rolled_north = rpy_to_rot(math.radians(45.0), 0.0, math.radians(90.0))
    expected = math.atan2(1.0, -0.3 * math.sin(math.radians(45.0))) - math.radians(90.0)
    assert heading_error(rolled_north, b) == pytest.approx(expected, abs=1e-12)
    assert math.degrees(expected) == pytest.approx(11.98, abs=0.01)


def test_a_level_horizontal_residual_gives_the_one_cycle_heading_error():
    """Level, b = (0, b_y): psi_m = atan2(sin psi, cos psi + b_y), the classic hard-iron curve: none facing
    along the residual or against it, largest (asin b_y) where the field and the residual are at right
    angles in the sum."""
    b_y = 0.5
    for psi_deg in (0.0, 180.0):
        assert heading_error(rpy_to_rot(0.0, 0.0, math.radians(psi_deg)), (0.0, b_y, 0.0)) == pytest.approx(0.0, abs=1e-12)
    psi = np.radians(np.linspace(-179.0, 179.0, 359))
    errors = heading_error(np.array([rpy_to_rot(0.0, 0.0, p) for p in psi]), np.tile((0.0, b_y, 0.0), (psi.size, 1)))
    np.testing.assert_allclose(errors, np.arctan2(np.sin(psi), np.cos(psi) + b_y) - psi, atol=1e-12)
    assert np.max(np.abs(errors)) == pytest.approx(math.asin(b_y), abs=2e-3)


@settings(max_examples=200, deadline=None)
@given(angles, tilts, angles, fields, fields, fields)
def test_the_reported_attitude_keeps_the_tilt_and_turns_only_the_heading(roll, pitch, yaw, bx, by, bz):
    R = rpy_to_rot(roll, pitch, yaw)
    reported = reported_rotation(R, (bx, by, bz))
    np.testing.assert_allclose(reported @ reported.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(reported[2], R[2], rtol=0, atol=0)  # the tilt's row, exactly
    true_rpy, seen_rpy = rotations_to_rpy(np.array([R, reported]))
    np.testing.assert_allclose(seen_rpy[:2], true_rpy[:2], atol=1e-9)
    turn = math.remainder(seen_rpy[2] - true_rpy[2], 2.0 * math.pi)
    assert turn == pytest.approx(float(heading_error(R, (bx, by, bz))), abs=1e-9)


def test_one_attitude_and_a_stack_round_alike():
    """The per-trial engine turns one attitude at a time, the batch a stack: the same bits."""
    rng = np.random.default_rng(3)
    R = np.array([rpy_to_rot(*rng.uniform(-1.2, 1.2, 3)) for _ in range(64)])
    b = rng.uniform(-0.8, 0.8, (64, 3))
    stacked = reported_rotation(R, b)
    for i in range(64):
        assert np.array_equal(reported_rotation(R[i], b[i]), stacked[i])


@settings(max_examples=200, deadline=None)
@given(angles, tilts, angles, fields, fields, fields)
def test_the_true_attitude_of_a_reported_one_reports_it_back(roll, pitch, yaw, bx, by, bz):
    """Below the horizontal field (|b| < 1) every reported attitude has one true attitude, with the same tilt."""
    b = np.array([bx, by, bz])
    if np.linalg.norm(b) >= 0.99:
        b = b * (0.98 / np.linalg.norm(b))
    reported = rpy_to_rot(roll, pitch, yaw)
    true = true_rotation(reported, b)
    np.testing.assert_allclose(true[2], reported[2], rtol=0, atol=0)
    np.testing.assert_allclose(reported_rotation(true, b), reported, atol=1e-9)
    np.testing.assert_allclose(true_rotation(reported_rotation(reported, b), b), reported, atol=1e-9)


def test_a_residual_as_strong_as_the_earths_field_has_headings_without_a_true_one():
    with pytest.raises(ValueError, match="horizontal field"):
        true_rotation(np.eye(3), (0.0, 1.0, 0.0))
