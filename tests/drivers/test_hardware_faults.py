"""The robot built wrong: each fault changes what the wires carry, and no fault changes nothing."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_common.config import ParameterError
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import quat_to_rot, rpy_to_rot
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_faults import BuiltRobot, HardwareFaults, hardware_faults_from_dict, load_hardware_faults

CAL = load_servo_calibration()
NEUTRAL = np.array([j.neutral_angle_rad for j in CAL.joints])
J = JOINT_NAMES.index


def test_no_fault_is_the_configured_robot():
    robot = BuiltRobot(CAL)
    angles = NEUTRAL + np.radians(np.linspace(-20.0, 20.0, 12))
    pulses = CAL.angles_to_pulses(angles)
    assert np.allclose(robot.joint_targets(pulses), angles)
    assert np.allclose(robot.feedback_volts(angles), CAL.angles_to_volts(angles))
    q = np.array([0.1, 0.2, 0.3, 0.9]) / np.linalg.norm([0.1, 0.2, 0.3, 0.9])
    out_q, w, f = robot.imu_output(q, [0.1, 0.2, 0.3], [0.0, 0.0, 9.81])
    assert np.allclose(out_q, q) and np.allclose(w, [0.1, 0.2, 0.3]) and np.allclose(f, [0.0, 0.0, 9.81])
    assert not HardwareFaults() and not load_hardware_faults("")


def test_reversed_servo_turns_the_joint_the_other_way_and_its_feedback_hides_it():
    robot = BuiltRobot(CAL, HardwareFaults(reversed=("leg2_hip",)))
    angles = NEUTRAL.copy()
    angles[J("leg2_hip")] += math.radians(10.0)
    true = robot.joint_targets(CAL.angles_to_pulses(angles))
    assert math.degrees(true[J("leg2_hip")] - NEUTRAL[J("leg2_hip")]) == pytest.approx(-10.0)
    # read through the configured map, the feedback says the joint went where it was told
    assert np.allclose(CAL.volts_to_angles(robot.feedback_volts(true)), angles)


def test_horn_offset_moves_the_joint_and_not_the_feedback():
    robot = BuiltRobot(CAL, HardwareFaults(horn_offset_deg=(("leg1_motor1", 14.4),)))
    true = robot.joint_targets(CAL.angles_to_pulses(NEUTRAL))
    assert math.degrees(true[0] - NEUTRAL[0]) == pytest.approx(14.4)
    assert np.allclose(CAL.volts_to_angles(robot.feedback_volts(true)), NEUTRAL)


def test_swapped_wires_and_a_stuck_adc():
    robot = BuiltRobot(CAL, HardwareFaults(swapped_pwm=(("leg1_hip", "leg3_hip"),),
                                           swapped_feedback=(("leg1_motor1", "leg4_motor2"),),
                                           stuck_feedback_v=(("leg2_motor2", 1.2),)))
    angles = NEUTRAL.copy()
    angles[J("leg1_hip")] += 0.2
    true = robot.joint_targets(CAL.angles_to_pulses(angles))
    assert true[J("leg3_hip")] == pytest.approx(angles[J("leg1_hip")]) and true[J("leg1_hip")] == pytest.approx(NEUTRAL[J("leg1_hip")])
    volts = robot.feedback_volts(angles)
    expected = CAL.angles_to_volts(angles)
    assert volts[J("leg1_motor1")] == pytest.approx(expected[J("leg4_motor2")])
    assert volts[J("leg4_motor2")] == pytest.approx(expected[J("leg1_motor1")])
    assert volts[J("leg2_motor2")] == 1.2


def test_limp_servo_has_no_target():
    pulses = CAL.angles_to_pulses(NEUTRAL)
    pulses[3] = 0.0
    assert np.isnan(BuiltRobot(CAL).joint_targets(pulses)[3])


def test_rotated_imu_reports_gravity_in_its_own_axes():
    robot = BuiltRobot(CAL, load_hardware_faults("{imu_mount_rpy_deg: [0, 0, 90]}"))
    q, _, f = robot.imu_output([0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [9.81, 0.0, 0.0])
    assert np.allclose(f, [0.0, -9.81, 0.0])
    assert np.allclose(quat_to_rot(q), rpy_to_rot(0.0, 0.0, math.pi / 2))


def test_servo_faults_show_in_the_feedback():
    faults = load_hardware_faults("{servo_reversed: [leg3_motor2], servo_stuck: [leg1_hip], "
                                  "servo_speed_scale: {leg2_motor1: 0.5}}")
    robot = BuiltRobot(CAL, faults)
    angles = NEUTRAL + math.radians(10.0)
    true = robot.joint_targets(CAL.angles_to_pulses(angles))
    assert math.degrees(true[J("leg3_motor2")] - NEUTRAL[J("leg3_motor2")]) == pytest.approx(-10.0)
    assert math.isnan(true[J("leg1_hip")])  # stuck: it stays where it is
    # the potentiometer is on the shaft: the feedback reads where the reversed servo went, not the command
    held = np.where(np.isnan(true), NEUTRAL, true)  # the stuck joint where it was
    assert math.degrees(CAL.volts_to_angles(robot.feedback_volts(held))[J("leg3_motor2")]
                        - NEUTRAL[J("leg3_motor2")]) == pytest.approx(-10.0)
    assert robot.speed_scale[J("leg2_motor1")] == 0.5 and np.sum(robot.speed_scale < 1.0) == 1
    assert faults.describe() == ["servo leg3_motor2 turns the other way", "servo leg1_hip stuck",
                                 "servo leg2_motor1 at 50 % of its speed"]


@pytest.mark.parametrize("tree, message", [
    ({"servo_speed_scale": {"leg1_hip": 0.0}}, "servo_speed_scale.leg1_hip"),
    ({"servo_stuck": "leg1_hip"}, "servo_stuck"),
    ({"reversed": ["leg9_hip"]}, "reversed\\[0\\]"),
    ({"swapped_pwm": [["leg1_hip", "leg1_hip"]]}, "two joints"),
    ({"swapped_pwm": [["leg1_hip", "leg2_hip"], ["leg2_hip", "leg3_hip"]]}, "no other pair"),
    ({"horn_offset_deg": {"leg1_hip": 120.0}}, "horn_offset_deg.leg1_hip"),
    ({"stuck_feedback_v": {"legX": 1.0}}, "unknown hardware fault 'stuck_feedback_v.legX'"),
    ({"imu_mount": [0, 0, 0]}, "unknown hardware fault 'imu_mount'"),
    ({"imu_mount_rpy_deg": [0, 0]}, "imu_mount_rpy_deg"),
])
def test_bad_faults_are_refused_naming_the_key(tree, message):
    with pytest.raises(ParameterError, match=message):
        hardware_faults_from_dict(tree)


def test_faults_from_a_file_and_inline(tmp_path):
    path = tmp_path / "faults.yaml"
    path.write_text("reversed: [leg2_hip]\nswapped_feedback: [[leg1_motor1, leg2_motor1]]\n")
    faults = load_hardware_faults(str(path))
    assert faults.describe() == ["reversed servo leg2_hip", "feedback wires of leg1_motor1 and leg2_motor1 swapped"]
    assert load_hardware_faults("{reversed: [leg2_hip]}").reversed == ("leg2_hip",)
    with pytest.raises(ParameterError, match="faults.yaml"):
        path.write_text("reversed: leg2_hip\n")
        load_hardware_faults(str(path))
