"""quadruped_control.ros.visualization: passive five-bar angles, joint-state assembly, markers, throttling."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.robot import JOINT_NAMES, LEGS, joint_index
from quadruped_common.so3 import wrap_angle
from quadruped_control.model.params import FiveBar, load_robot_params
from quadruped_control.ros.visualization import (LEG_COLOURS, PASSIVE_JOINT_NAMES, VISUAL_JOINT_NAMES, SphereMarker,
                                             Throttle, VisualizationError, foot_target_spheres, imu_orientation,
                                             knee_angles, unit_quaternion, visual_joint_state)

PARAMS = load_robot_params()
GEOMETRY = PARAMS.five_bar
LIMITS = PARAMS.joint_limits.as_array()


def link_tips(theta1, theta2, knees, g=GEOMETRY):
    """Ends of the two open chains drawn by the URDF: a1 then a3, and (c, 0) + a2 then a4."""
    knee1, knee2 = knees
    b = np.array([g.a1 * math.cos(theta1), g.a1 * math.sin(theta1)])
    d = np.array([g.c + g.a2 * math.cos(theta2), g.a2 * math.sin(theta2)])
    inner = b + g.a3 * np.array([math.cos(theta1 + knee1), math.sin(theta1 + knee1)])
    outer = d + g.a4 * np.array([math.cos(theta2 + knee2), math.sin(theta2 + knee2)])
    return inner, outer


def nominal_actuated():
    """Joint angles of the nominal foot position by the paper's IK (eq. ik_theta3 .. ik_theta1245)."""
    x_d, y_d, z_d = PARAMS.nominal_foot_leg
    g = GEOMETRY
    theta3 = math.atan2(z_d, y_d) - math.acos(PARAMS.l_z / math.hypot(y_d, z_d)) - math.pi / 2
    y_p = y_d * math.cos(theta3) + z_d * math.sin(theta3) - PARAMS.l_y
    d13, d24 = math.hypot(x_d, y_p), math.hypot(x_d - g.c, y_p)
    alpha1 = math.acos((d13 ** 2 + g.a1 ** 2 - g.a3 ** 2) / (2 * g.a1 * d13))
    alpha2 = math.acos((d24 ** 2 + g.a2 ** 2 - g.a4 ** 2) / (2 * g.a2 * d24))
    theta1 = math.atan2(y_p, x_d) - alpha1
    theta2 = math.atan2(y_p, x_d - g.c) + alpha2
    theta4 = math.acos((d13 ** 2 - g.a1 ** 2 - g.a3 ** 2) / (2 * g.a1 * g.a3))
    theta5 = -math.acos((d24 ** 2 - g.a2 ** 2 - g.a4 ** 2) / (2 * g.a2 * g.a4))
    return theta1, theta2, wrap_angle(theta3), theta4, theta5


def test_joint_name_tables():
    assert PASSIVE_JOINT_NAMES == ("leg1_knee1", "leg1_knee2", "leg2_knee1", "leg2_knee2",
                                   "leg3_knee1", "leg3_knee2", "leg4_knee1", "leg4_knee2")
    assert VISUAL_JOINT_NAMES[:12] == JOINT_NAMES
    assert VISUAL_JOINT_NAMES[12:] == PASSIVE_JOINT_NAMES


@settings(max_examples=200, deadline=None)
@given(st.floats(LIMITS[0, 0], LIMITS[0, 1]), st.floats(LIMITS[1, 0], LIMITS[1, 1]))
def test_knee_angles_close_the_loop(theta1, theta2):
    try:
        knees = knee_angles(theta1, theta2, GEOMETRY)
    except VisualizationError:
        return  # singular pose: refused, covered by test_singular_five_bar_is_refused
    inner, outer = link_tips(theta1, theta2, knees)
    assert np.allclose(inner, outer, atol=1e-12)
    assert all(-math.pi < k <= math.pi for k in knees)


def test_knee_angles_are_the_papers_theta4_theta5_at_the_nominal_pose():
    theta1, theta2, _, theta4, theta5 = nominal_actuated()
    knee1, knee2 = knee_angles(theta1, theta2, GEOMETRY)
    assert knee1 == pytest.approx(theta4, abs=1e-9)
    assert knee2 == pytest.approx(theta5, abs=1e-9)


def test_open_five_bar_is_refused():
    # Long actuated links pointing apart: the tips are 0.43 m apart, the passive links reach 0.1 m.
    geometry = FiveBar(a1=0.2, a2=0.2, a3=0.05, a4=0.05, c=0.03)
    with pytest.raises(VisualizationError, match="does not close"):
        knee_angles(math.pi, 0.0, geometry)


def test_singular_five_bar_is_refused():
    # Link tips B and D coincide (cos theta1 - cos theta2 = c / a1, theta2 = pi - theta1): phi undefined.
    theta1 = math.acos(GEOMETRY.c / (2 * GEOMETRY.a1))
    with pytest.raises(VisualizationError, match="does not close"):
        knee_angles(-theta1, -(math.pi - theta1), GEOMETRY)


@pytest.mark.parametrize("theta1, theta2", [(float("nan"), 0.0), (0.0, float("inf"))])
def test_non_finite_five_bar_angles_are_refused(theta1, theta2):
    with pytest.raises(VisualizationError, match="finite"):
        knee_angles(theta1, theta2, GEOMETRY)


def nominal_state():
    theta1, theta2, theta3, _, _ = nominal_actuated()
    return [theta1, theta2, theta3] * len(LEGS)


def test_visual_joint_state_appends_knees_in_order():
    names, positions = visual_joint_state(JOINT_NAMES, nominal_state(), PARAMS)
    assert tuple(names) == VISUAL_JOINT_NAMES
    assert positions[:12] == pytest.approx(nominal_state())
    _, _, _, theta4, theta5 = nominal_actuated()
    assert positions[12:] == pytest.approx([theta4, theta5] * len(LEGS), abs=1e-9)


def test_visual_joint_state_is_independent_of_input_order_and_keeps_extra_joints():
    rng = np.random.RandomState(3)
    q = np.array(nominal_state()) + rng.uniform(-0.1, 0.1, 12)
    order = rng.permutation(12)
    names = [JOINT_NAMES[i] for i in order] + ["camera_tilt"]
    positions = [q[i] for i in order] + [0.25]
    out_names, out_positions = visual_joint_state(names, positions, PARAMS)
    reference = visual_joint_state(JOINT_NAMES, q, PARAMS)
    assert out_names == list(reference[0]) + ["camera_tilt"]
    assert out_positions[:20] == pytest.approx(reference[1], abs=1e-15)
    assert out_positions[20] == 0.25


def test_each_leg_uses_its_own_angles():
    q = nominal_state()
    q[joint_index(3, 1)] += 0.2
    _, positions = visual_joint_state(JOINT_NAMES, q, PARAMS)
    knees = dict(zip(PASSIVE_JOINT_NAMES, positions[12:]))
    assert knees["leg3_knee1"] != pytest.approx(knees["leg1_knee1"])
    assert knees["leg2_knee1"] == pytest.approx(knees["leg1_knee1"])
    assert (knees["leg3_knee1"], knees["leg3_knee2"]) == pytest.approx(
        knee_angles(q[joint_index(3, 1)], q[joint_index(3, 2)], GEOMETRY))


def test_visual_joint_state_rejects_bad_input():
    q = nominal_state()
    with pytest.raises(VisualizationError, match="12 names but 11 positions"):
        visual_joint_state(JOINT_NAMES, q[:11], PARAMS)
    with pytest.raises(VisualizationError, match="lacks actuated joints leg4_hip"):
        visual_joint_state(JOINT_NAMES[:11], q[:11], PARAMS)
    with pytest.raises(VisualizationError, match="repeats joints leg1_hip"):
        visual_joint_state(list(JOINT_NAMES) + ["leg1_hip"], q + [0.0], PARAMS)
    bad = list(q)
    bad[joint_index(2, 3)] = float("nan")
    with pytest.raises(VisualizationError, match="non-finite positions for leg2_hip"):
        visual_joint_state(JOINT_NAMES, bad, PARAMS)
    singular = list(q)
    theta1 = math.acos(GEOMETRY.c / (2 * GEOMETRY.a1))
    singular[joint_index(4, 1)], singular[joint_index(4, 2)] = -theta1, -(math.pi - theta1)
    with pytest.raises(VisualizationError, match="leg 4: five-bar does not close"):
        visual_joint_state(JOINT_NAMES, singular, PARAMS)


def test_unit_quaternion_normalises_and_rejects_non_rotations():
    assert unit_quaternion([0, 0, 0, 2.0]) == pytest.approx([0, 0, 0, 1])
    q = unit_quaternion([0.1, -0.2, 0.3, 0.9])
    assert float(np.linalg.norm(q)) == pytest.approx(1.0)
    with pytest.raises(VisualizationError, match="zero norm"):
        unit_quaternion([0, 0, 0, 0])
    with pytest.raises(VisualizationError, match="4 finite numbers"):
        unit_quaternion([0, 0, float("nan"), 1])
    with pytest.raises(VisualizationError, match="4 finite numbers"):
        unit_quaternion([0, 0, 1])


def test_imu_orientation_follows_rep_145():
    covariance = [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01]
    assert imu_orientation([0, 0, 0.6, 0.8], covariance) == pytest.approx([0, 0, 0.6, 0.8])
    assert imu_orientation([0, 0, 0, 0], [-1.0] + [0.0] * 8) is None
    with pytest.raises(VisualizationError):
        imu_orientation([0, 0, 0, 0], covariance)


def test_foot_target_spheres():
    points = [PARAMS.nominal_foot_body(leg) for leg in LEGS]
    spheres = foot_target_spheres(points, PARAMS.paw_diameter)
    assert [s.leg for s in spheres] == list(LEGS)
    assert spheres[2] == SphereMarker(leg=3, position=tuple(points[2]), diameter=PARAMS.paw_diameter,
                                      rgba=LEG_COLOURS[3])
    with pytest.raises(VisualizationError, match="expected 4 foot targets"):
        foot_target_spheres(points[:3], 0.05)
    with pytest.raises(VisualizationError, match="leg 2"):
        foot_target_spheres([points[0], [0.0, float("inf"), 0.0]] + points[2:], 0.05)
    with pytest.raises(VisualizationError, match="leg 1"):
        foot_target_spheres([[0.0, 0.0]] + points[1:], 0.05)
    with pytest.raises(VisualizationError, match="diameter"):
        foot_target_spheres(points, 0.0)


def test_throttle():
    throttle = Throttle(0.05)
    assert [throttle.ready(t) for t in (10.0, 10.01, 10.049, 10.05, 10.06, 10.11)] == [
        True, False, False, True, False, True]
    # A clock jumping back (sim time reset, bag loop) re-arms the throttle.
    assert throttle.ready(1.0)
    assert not throttle.ready(1.01)
    assert all(Throttle(0.0).ready(t) for t in (0.0, 0.0, 0.0))
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            Throttle(bad)
