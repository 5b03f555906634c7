"""The URDF tells the truth: xacro output, joint names, dimensions from robot.yaml, and paw positions.

The paw positions are computed by chaining the URDF's own joint transforms (a small FK over the parsed
XML, written here with numpy) for in-range actuated angles plus the passive knee angles of
quadruped_control.ros.visualization, and compared with quadruped_control.model.kinematics.foot_position
(eq. ee_body, fk_T, fk_planar) to 1e-9 m. No ROS master needed.
"""
import math
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from typing import Dict, Tuple

import numpy as np
import pytest
import yaml

from quadruped_common.config import config_path
from quadruped_common.robot import JOINT_NAMES, LEGS, joint_index
from quadruped_control.model.kinematics import foot_position, joint_angles
from quadruped_control.model.params import load_robot_params
from quadruped_control.ros.visualization import (PASSIVE_JOINT_NAMES, VISUAL_JOINT_NAMES, VisualizationError,
                                             visual_joint_state)
from tests.repo import REPO_ROOT as ROOT

XACRO_FILE = os.path.join(ROOT, "urdf", "underwater_quadruped.urdf.xacro")


def requirements_file() -> str:
    """The pinned requirements of this platform (scripts/setup.sh): the Jetson's Python 3.8 or the rest."""
    return "requirements-jetson.txt" if sys.version_info < (3, 9) else "requirements.txt"


def xacro_executable() -> str:
    sibling = os.path.join(os.path.dirname(sys.executable), "xacro")
    found = sibling if os.path.exists(sibling) else shutil.which("xacro")
    if found is None:
        pytest.fail("xacro is not installed beside %s or on PATH (%s pins it: pip install -r %s)"
                    % (sys.executable, requirements_file(), requirements_file()))
    return found


def run_xacro(*args: str) -> ET.Element:
    result = subprocess.run([xacro_executable(), XACRO_FILE] + list(args), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, universal_newlines=True, timeout=60)
    assert result.returncode == 0, result.stderr
    return ET.fromstring(result.stdout)


@pytest.fixture(scope="module")
def urdf() -> ET.Element:
    return run_xacro()


@pytest.fixture(scope="module")
def params():
    return load_robot_params()


# --- a minimal URDF forward kinematics -------------------------------------------------------------

def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF rpy: fixed-axis roll about x, then pitch about y, then yaw about z: R = Rz Ry Rx."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation about the unit ``axis``."""
    k = axis / np.linalg.norm(axis)
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * skew + (1 - math.cos(angle)) * skew @ skew


def homogeneous(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def floats(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def joints_by_child(urdf: ET.Element) -> Dict[str, ET.Element]:
    return {joint.find("child").get("link"): joint for joint in urdf.findall("joint")}


def link_pose(urdf: ET.Element, link: str, positions: Dict[str, float]) -> np.ndarray:
    """4x4 pose of ``link`` in the root link's frame for the joint ``positions`` (URDF semantics)."""
    by_child = joints_by_child(urdf)
    chain = []
    while link in by_child:
        joint = by_child[link]
        chain.append(joint)
        link = joint.find("parent").get("link")
    pose = np.eye(4)
    for joint in reversed(chain):
        origin = joint.find("origin")
        xyz = floats(origin.get("xyz", "0 0 0")) if origin is not None else np.zeros(3)
        rpy = floats(origin.get("rpy", "0 0 0")) if origin is not None else np.zeros(3)
        pose = pose @ homogeneous(rpy_matrix(*rpy), xyz)
        if joint.get("type") in ("revolute", "continuous"):
            axis = floats(joint.find("axis").get("xyz"))
            pose = pose @ homogeneous(axis_angle_matrix(axis, positions[joint.get("name")]), np.zeros(3))
        else:
            assert joint.get("type") == "fixed", "unexpected joint type %s" % joint.get("type")
    return pose


def test_fk_helper_matches_known_transforms():
    # rpy convention: yaw of pi/2 maps x to y; Rodrigues about -z by a equals about z by -a.
    assert np.allclose(rpy_matrix(0, 0, math.pi / 2) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(rpy_matrix(math.pi / 2, 0, 0) @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(axis_angle_matrix(np.array([0, 0, -1.0]), 0.3), axis_angle_matrix(np.array([0, 0, 1.0]), -0.3))


# --- structure ----------------------------------------------------------------------------------------

def test_actuated_joints_are_exactly_joint_names(urdf):
    revolute = [j.get("name") for j in urdf.findall("joint") if j.get("type") == "revolute"]
    assert sorted(revolute) == sorted(JOINT_NAMES)
    continuous = [j.get("name") for j in urdf.findall("joint") if j.get("type") == "continuous"]
    assert sorted(continuous) == sorted(PASSIVE_JOINT_NAMES)
    movable = [j.get("name") for j in urdf.findall("joint") if j.get("type") != "fixed"]
    assert sorted(movable) == sorted(VISUAL_JOINT_NAMES)
    assert len(set(movable)) == len(movable) == 20


def test_links_form_one_tree_rooted_at_base_link(urdf):
    links = [link.get("name") for link in urdf.findall("link")]
    assert len(set(links)) == len(links)
    children = [j.find("child").get("link") for j in urdf.findall("joint")]
    assert len(set(children)) == len(children), "a link has two parents"
    roots = set(links) - set(children)
    assert roots == {"base_link"}
    assert all(j.find("parent").get("link") in links for j in urdf.findall("joint"))
    assert {"leg%d_paw" % leg for leg in LEGS} | {"imu_link"} <= set(links)


def test_imu_link_is_fixed_to_base_link_at_the_configured_mount(tmp_path, urdf, params):
    """/imu/data's frame (config/vn100.yaml) is a link of the URDF, so the TF tree has it."""
    with open(config_path("vn100.yaml")) as stream:
        vn100 = yaml.safe_load(stream)
    joint = next(j for j in urdf.findall("joint") if j.find("child").get("link") == vn100["frame_id"])
    assert joint.get("type") == "fixed" and joint.find("parent").get("link") == "base_link"
    assert np.allclose(floats(joint.find("origin").get("xyz")), params.imu_mount_xyz)
    assert np.allclose(floats(joint.find("origin").get("rpy")), 0.0)
    with open(config_path("robot.yaml")) as stream:
        tree = yaml.safe_load(stream)
    tree["imu"]["mount_xyz"] = [0.05, -0.02, 0.03]
    moved = tmp_path / "robot.yaml"
    moved.write_text(yaml.safe_dump(tree))
    origin = run_xacro("robot_yaml:=%s" % moved).find("joint[@name='imu_joint']/origin")
    assert np.allclose(floats(origin.get("xyz")), [0.05, -0.02, 0.03])


def test_limits_and_dimensions_come_from_robot_yaml(urdf, params):
    limits = params.joint_limits.as_array()
    for name in JOINT_NAMES:
        joint = urdf.find("joint[@name='%s']" % name)
        limit = joint.find("limit")
        row = ("motor1", "motor2", "hip").index(name.split("_")[1])
        assert float(limit.get("lower")) == pytest.approx(limits[row, 0], abs=1e-12)
        assert float(limit.get("upper")) == pytest.approx(limits[row, 1], abs=1e-12)
        assert float(limit.get("effort")) == pytest.approx(params.servo_stall_torque)
        assert float(limit.get("velocity")) == pytest.approx(params.servo_no_load_speed)
    body_box = urdf.find("link[@name='base_link']/visual/geometry/box")
    assert np.allclose(floats(body_box.get("size")), params.body_dimensions)
    for leg in LEGS:
        sphere = urdf.find("link[@name='leg%d_paw']/visual/geometry/sphere" % leg)
        assert float(sphere.get("radius")) == pytest.approx(0.5 * params.paw_diameter)


def test_robot_yaml_argument_changes_the_drawing(tmp_path, params):
    with open(config_path("robot.yaml")) as stream:
        tree = yaml.safe_load(stream)
    tree["five_bar"]["a3"] = tree["five_bar"]["a4"] = 0.125
    tree["leg_origins"]["3"] = [0.25, 0.15, -0.03]
    changed = tmp_path / "robot.yaml"
    changed.write_text(yaml.safe_dump(tree))
    urdf = run_xacro("robot_yaml:=%s" % changed)
    tip = urdf.find("joint[@name='leg2_paw_joint']/origin")
    assert np.allclose(floats(tip.get("xyz")), [0.125, 0, 0])
    base = urdf.find("joint[@name='leg3_base_joint']/origin")
    assert np.allclose(floats(base.get("xyz")), [0.25, 0.15, -0.03])


def test_missing_robot_yaml_fails_loudly(tmp_path):
    result = subprocess.run([xacro_executable(), XACRO_FILE, "robot_yaml:=%s" % (tmp_path / "none.yaml")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=60)
    assert result.returncode != 0
    assert "none.yaml" in result.stderr


# --- the drawing matches the kinematics -------------------------------------------------------------

def sample_poses(params, count: int, seed: int) -> Tuple[np.ndarray, ...]:
    """``count`` in-range 12-joint poses (uniform within the servo limits) whose five-bars close."""
    rng = np.random.RandomState(seed)
    limits = params.joint_limits.as_array()
    poses = []
    attempts = 0
    while len(poses) < count:
        attempts += 1
        assert attempts < 100 * count, "servo ranges hardly ever give a closed five-bar"
        q = np.concatenate([rng.uniform(limits[:, 0], limits[:, 1]) for _ in LEGS])
        try:
            visual_joint_state(JOINT_NAMES, q, params)
        except VisualizationError:
            continue
        poses.append(q)
    return tuple(poses)


def test_sampled_poses_cover_the_joint_ranges(params):
    poses = np.array(sample_poses(params, 60, seed=7))
    limits = params.joint_limits.as_array()
    spread = poses.reshape(-1, 4, 3).max(axis=(0, 1)) - poses.reshape(-1, 4, 3).min(axis=(0, 1))
    assert np.all(spread > 0.5 * (limits[:, 1] - limits[:, 0]))


def test_urdf_paw_lands_on_kinematics_foot_position(urdf, params):
    for q in sample_poses(params, 60, seed=1):
        names, positions = visual_joint_state(JOINT_NAMES, q, params)
        state = dict(zip(names, positions))
        for leg in LEGS:
            q_leg = q[joint_index(leg, 1):joint_index(leg, 3) + 1]
            expected = foot_position(q_leg, leg, params)
            paw = link_pose(urdf, "leg%d_paw" % leg, state)[:3, 3]
            assert np.allclose(paw, expected, rtol=0.0, atol=1e-9), (leg, q_leg, paw, expected)


def test_drawn_five_bar_closes(urdf, params):
    # The tip of link a3 (inner chain) meets the paw (outer chain): the passive angles close the loop.
    for q in sample_poses(params, 40, seed=2):
        names, positions = visual_joint_state(JOINT_NAMES, q, params)
        state = dict(zip(names, positions))
        for leg in LEGS:
            tip = link_pose(urdf, "leg%d_link3_tip" % leg, state)[:3, 3]
            paw = link_pose(urdf, "leg%d_paw" % leg, state)[:3, 3]
            assert np.allclose(tip, paw, rtol=0.0, atol=1e-9)


def test_nominal_pose_paw_is_the_nominal_foot(urdf, params):
    q = np.concatenate([joint_angles(params.nominal_foot_body(leg), leg, params) for leg in LEGS])
    names, positions = visual_joint_state(JOINT_NAMES, q, params)
    state = dict(zip(names, positions))
    for leg in LEGS:
        paw = link_pose(urdf, "leg%d_paw" % leg, state)[:3, 3]
        assert np.allclose(paw, params.nominal_foot_body(leg), atol=1e-9)
        # Mirror symmetry of eq. (M_legs): every paw sits outboard and below its hip.
        origin = params.leg_origins[leg]
        assert np.sign(paw[1]) == np.sign(origin[1]) and abs(paw[1]) > abs(origin[1])
        assert paw[2] < origin[2]
