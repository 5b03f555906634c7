"""quadruped_common.robot: leg numbering, joint names and order, mirror table, joint limits."""
import math

import pytest

from quadruped_common import robot
from quadruped_common.config import ParameterError
from quadruped_common.robot import (JOINT_NAMES, LEGS, MIRROR_DIAG, joint_index, joint_limits_from_dict, load_joint_limits,
                                    load_servo_no_load_speed, servo_no_load_speed_from_dict)


def test_joint_names_and_indices():
    assert len(JOINT_NAMES) == 12
    assert JOINT_NAMES[joint_index(3, 2)] == "leg3_motor2"
    assert JOINT_NAMES[joint_index(1, 3)] == "leg1_hip"
    with pytest.raises(ValueError):
        joint_index(5, 1)


def test_every_leg_has_a_mirror_and_three_joints():
    assert LEGS == (1, 2, 3, 4) and sorted(MIRROR_DIAG) == list(LEGS)
    assert [JOINT_NAMES[joint_index(leg, 3)] for leg in LEGS] == ["leg%d_hip" % leg for leg in LEGS]


def test_joint_limits_of_the_package_config_are_in_radians():
    limits = load_joint_limits()
    assert limits.as_array().shape == (3, 2)
    assert limits.theta3 == pytest.approx((0.0, math.pi))  # config/robot.yaml: [0, 180] degrees


@pytest.mark.parametrize("theta1, message", [([10.0, -10.0], "low < high"), ([-200.0, 200.0], "more than 360"),
                                             ([0.0], "theta1")])
def test_bad_joint_limits_name_the_key(theta1, message):
    tree = {"joint_limits_deg": {"theta1": theta1, "theta2": [-130.0, 50.0], "theta3": [0.0, 180.0]}}
    with pytest.raises(ParameterError, match=message):
        joint_limits_from_dict(tree)


def test_servo_no_load_speed_is_read_once_for_model_and_drivers():
    from quadruped_control.model.params import load_robot_params
    assert load_servo_no_load_speed() == pytest.approx(95.0 * 2.0 * math.pi / 60.0)  # [paper] 95 rpm
    assert load_robot_params().servo_no_load_speed == load_servo_no_load_speed()
    with pytest.raises(ParameterError, match="servo.no_load_speed_rpm"):
        servo_no_load_speed_from_dict({"servo": {"no_load_speed_rpm": 0.0}})


def test_leg_pairs_are_read_from_the_controller_config_for_every_layer(tmp_path):
    """The bag analysis reads the pairs the controller strokes with (config/controller.yaml ``pairs``)."""
    assert robot.load_leg_pairs() == robot.DEFAULT_LEG_PAIRS == ((1, 3), (2, 4))
    path = tmp_path / "controller.yaml"
    path.write_text("tau_max: 2.0\n")
    assert robot.load_leg_pairs(str(path)) == robot.DEFAULT_LEG_PAIRS  # none named: the default
    path.write_text("pairs: [[1, 2], [4, 3]]\n")
    assert robot.load_leg_pairs(str(path)) == ((1, 2), (4, 3))
    for bad, message in (([[1, 2], [2, 3]], "partition"), ([[1, 2, 3], [4]], "two pairs"), (3, "two pairs"),
                         ([[1, 2.0], [3, 4]], "integer")):
        with pytest.raises(ParameterError, match=message):
            robot.leg_pairs(bad)
