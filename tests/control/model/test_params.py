"""Loading and validation of config/robot.yaml (quadruped_control.model.params)."""
import copy
import math
import os

import numpy as np
import pytest

from quadruped_common import config as common
from quadruped_common.config import ParameterError, load_yaml, config_path
from quadruped_common.robot import LEGS
from quadruped_control.model.params import load_robot_params, robot_params_from_dict


@pytest.fixture(scope="module")
def raw():
    return load_yaml(config_path("robot.yaml"))


def test_paper_values_are_loaded():
    p = load_robot_params()
    assert p.mass == 4.9
    assert p.five_bar.a1 == p.five_bar.a2 == 0.080
    assert p.five_bar.a3 == p.five_bar.a4 == 0.110
    assert p.five_bar.c == 0.030
    assert p.paw_diameter == 0.075 and p.drag_coefficient == 0.64
    np.testing.assert_allclose(p.body_dimensions, [0.5899, 0.3444, 0.1533])
    # k = 1/2 rho C_D A with A the sphere's cross-section (eq. drag)
    assert p.drag_constant == pytest.approx(0.5 * 1000.0 * 0.64 * math.pi * 0.0375 ** 2)
    assert p.servo_no_load_speed == pytest.approx(95.0 * 2.0 * math.pi / 60.0)


def test_mirroring_matrices_are_the_papers():
    p = load_robot_params()
    np.testing.assert_array_equal(np.diag(p.mirror[1]), [-1, 1, 1])
    np.testing.assert_array_equal(np.diag(p.mirror[2]), [-1, -1, 1])
    np.testing.assert_array_equal(np.diag(p.mirror[3]), [1, -1, 1])
    np.testing.assert_array_equal(np.diag(p.mirror[4]), [1, 1, 1])


def test_leg_origins_follow_the_paper_layout():
    """Legs 3, 4 at the front, 1, 2 at the back; leg frame y points inwards (so M_i y is inwards)."""
    p = load_robot_params()
    for leg in LEGS:
        origin = p.leg_origins[leg]
        inward_body = p.mirror[leg] @ np.array([0.0, 1.0, 0.0])
        assert np.sign(origin[1]) == -np.sign(inward_body[1]), "leg %d y axis must point inwards" % leg
        assert (origin[0] > 0) == (leg in (3, 4))


def test_nominal_foot_is_mirrored_per_leg():
    p = load_robot_params()
    for leg in LEGS:
        np.testing.assert_allclose(p.nominal_foot_body(leg), p.leg_origins[leg] + p.mirror[leg] @ p.nominal_foot_leg)


@pytest.mark.parametrize("mutate, message", [
    (lambda t: t["body"].pop("mass"), "body.mass"),
    (lambda t: t["body"].__setitem__("mass", -1.0), "body.mass"),
    (lambda t: t["body"].__setitem__("mass", "heavy"), "must be a number"),
    (lambda t: t["body"].__setitem__("inertia_diag", [1.0, 0.1, 0.1]), "triangle inequality"),
    (lambda t: t["body"].__setitem__("inertia_diag", [0.1, 0.1]), "list of 3"),
    (lambda t: t["fluid"].__setitem__("density", float("nan")), "finite"),
    (lambda t: t["five_bar"].__setitem__("a2", 0.09), "a1 == a2"),
    (lambda t: t["leg_origins"].pop("3"), "leg_origins.3"),
    (lambda t: t["joint_limits_deg"].__setitem__("theta3", [90.0, 0.0]), "low < high"),
    (lambda t: t["hip"].__setitem__("l_z", 0.0), "hip.l_z"),
])
def test_bad_values_give_clear_errors(raw, mutate, message):
    tree = copy.deepcopy(raw)
    mutate(tree)
    with pytest.raises(ParameterError, match=message.replace(".", r"\.").replace("(", r"\(")):
        robot_params_from_dict(tree)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ParameterError, match="cannot read"):
        load_robot_params(str(tmp_path / "nope.yaml"))
    bad = tmp_path / "bad.yaml"
    bad.write_text("body: [unclosed\n")
    with pytest.raises(ParameterError, match="not valid YAML"):
        load_robot_params(str(bad))
    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("3\n")
    with pytest.raises(ParameterError, match="mapping"):
        load_robot_params(str(scalar))


@pytest.fixture
def fresh_config_dir():
    """config_dir() is cached per process; each case starts and ends with an empty cache."""
    common.config_dir.cache_clear()
    yield common.config_dir
    common.config_dir.cache_clear()


def _package_tree(root):
    """A tree holding the package's config/ (with robot.yaml) and a module path inside it."""
    (root / "config").mkdir(parents=True)
    (root / "config" / "robot.yaml").write_text("{}")
    (root / "package.xml").write_text("<package format='3'><name>underwater_quadruped</name></package>")
    return str(root / "quadruped_common" / "config.py")


def test_config_dir_is_the_tree_of_the_code_not_another_on_the_ros_package_path(tmp_path, monkeypatch, caplog):
    """A second checkout reads its own config/ even with another checkout's workspace sourced, and says so."""
    pytest.importorskip("rospkg")
    mine = _package_tree(tmp_path / "mine")
    _package_tree(tmp_path / "other")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "other"))
    with caplog.at_level("WARNING"):
        assert common._find_config_dir(mine) == str(tmp_path / "mine" / "config")
    assert str(tmp_path / "other" / "config") in caplog.text


def test_config_dir_of_an_install_space_is_its_share_folder(tmp_path, monkeypatch):
    share = tmp_path / "install" / "share" / "underwater_quadruped"
    _package_tree(share)
    module = tmp_path / "install" / "lib" / "python3" / "dist-packages" / "quadruped_common" / "config.py"
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "nowhere"))
    assert common._find_config_dir(str(module)) == str(share / "config")


def test_config_dir_falls_back_to_the_ros_package_path(tmp_path, monkeypatch):
    """Code with no config/ of its own (e.g. copied elsewhere) reads the package on ROS_PACKAGE_PATH."""
    pytest.importorskip("rospkg")
    _package_tree(tmp_path / "ros")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ros"))
    assert common._find_config_dir(str(tmp_path / "bare" / "pkg" / "m.py")) == str(tmp_path / "ros" / "config")


def test_config_dir_missing_everywhere_is_a_parameter_error(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path))
    with pytest.raises(ParameterError, match="cannot find the config/ folder"):
        common._find_config_dir(str(tmp_path / "bare" / "pkg" / "m.py"))


def test_config_dir_without_ros_is_the_source_tree(tmp_path, monkeypatch, fresh_config_dir):
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path))
    source_tree = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(common.__file__))), "config")
    assert fresh_config_dir() == source_tree
    assert os.path.isfile(common.config_path("robot.yaml"))


def test_imu_mount_must_lie_inside_the_body(raw):
    tree = copy.deepcopy(raw)
    assert np.allclose(robot_params_from_dict(tree).imu_mount_xyz, raw["imu"]["mount_xyz"])
    tree["imu"]["mount_xyz"] = [0.0, 0.0, 0.5]
    with pytest.raises(ParameterError, match="imu.mount_xyz.*outside the body"):
        robot_params_from_dict(tree)
    del tree["imu"]
    with pytest.raises(ParameterError, match="missing parameter 'imu.mount_xyz'"):
        robot_params_from_dict(tree)
