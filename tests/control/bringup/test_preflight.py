"""The pre-dive check on the simulated rig: five checks, skipped (never passed) after a failure, a report."""
from __future__ import annotations

import json
import math

import numpy as np

from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_control.bringup.preflight import PreflightReport, SensorReadings, run_preflight
from quadruped_control.bringup.reference import reference_poses
from quadruped_control.bringup.servo_check import DriverBench, ServoCheckSettings
from quadruped_control.bringup.stroke_check import check_strokes
from quadruped_control.model.params import load_robot_params
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.hardware_faults import HardwareFaults, load_hardware_faults
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray
from quadruped_drivers.servo_rig import PoseDriver, SimulatedServoRig

HW, CAL, PARAMS = load_hardware_config(), load_servo_calibration(), load_robot_params()
QUICK = ServoCheckSettings(points=3, settle_s=0.2, samples=2)
RATES = {"imu": 200.0, "joints": 100.0}


class Stand(SensorReadings):
    """The rig on a stand: its IMU (through the robot as built) and its feedback; ``rates`` as given."""

    def __init__(self, rig: SimulatedServoRig, bench: DriverBench, rates=RATES):
        self.rig, self.bench, self._rates = rig, bench, rates
        self.rotation = np.eye(3)

    def guide(self, name, instruction, roll_deg, pitch_deg):
        self.rotation = rpy_to_rot(math.radians(roll_deg), math.radians(pitch_deg), 0.0)

    def rates(self, seconds):
        return dict(self._rates)

    def joint_angles(self):
        return self.bench.read_angles()

    def specific_force(self, seconds):
        force = self.rotation.T @ np.array([0.0, 0.0, 9.81])
        return self.rig.built.imu_output(rot_to_quat(self.rotation), np.zeros(3), force)[2]


def rig_and_bench(faults: HardwareFaults = HardwareFaults()):
    rig = SimulatedServoRig(HW, CAL, faults=faults, slope_scale=1.0, offset_shift_deg=0.0)  # calibrated
    pwm = ServoPwmOutput(rig.bus, HW, clock=rig.clock, sleep=rig.sleep)
    feedback = ServoFeedbackArray(rig.bus, HW, CAL, clock=rig.clock)
    pwm.start()
    feedback.start()
    return rig, DriverBench(PoseDriver(pwm, feedback, CAL, clock=rig.clock, sleep=rig.sleep), pwm)


def check(faults=HardwareFaults(), rates=RATES) -> PreflightReport:
    rig, bench = rig_and_bench(faults)
    stand = Stand(rig, bench, rates)
    return run_preflight(bench, stand, stand.guide, PARAMS, CAL, RATES, QUICK, log=lambda line: None)


def statuses(report):
    return {item.name: item.status for item in report.items}


def test_a_robot_built_right_passes_and_the_report_says_so():
    report = check()
    assert report.passed, report.markdown()
    assert statuses(report) == {"sensors": "passed", "IMU mount": "passed", "channels": "passed",
                                "servo speed": "passed", "strokes": "passed"}
    assert report.as_dict()["checks"][3]["figures"]["speed_fraction"]["leg4_hip"] > 0.9
    assert report.markdown().startswith("# Pre-dive check: passed")
    assert json.loads(json.dumps(report.as_dict()))["passed"] is True


def test_a_rotated_imu_fails_its_check_and_only_it():
    report = check(load_hardware_faults("{imu_mount_rpy_deg: [180, 0, 0]}"))
    assert statuses(report)["IMU mount"] == "FAILED" and not report.passed
    assert statuses(report)["channels"] == "passed"
    assert report.summary() == "FAILED: IMU mount"


def test_a_swapped_channel_fails_the_channels_and_the_strokes_are_skipped():
    report = check(load_hardware_faults("{swapped_pwm: [[leg3_motor2, leg4_motor2]]}"))
    assert statuses(report)["channels"] == "FAILED" and statuses(report)["strokes"] == "skipped"
    assert statuses(report)["servo speed"] == "skipped"
    assert "leg3_motor2" in report.items[2].detail and "leg4_motor2" in report.items[2].detail
    assert report.summary().startswith("FAILED: channels (leg3_motor2, leg4_motor2)")


def test_a_servo_at_half_speed_fails_the_speed_check_by_name_and_only_it():
    report = check(load_hardware_faults("{servo_speed_scale: {leg4_motor1: 0.5}}"))
    assert statuses(report) == {"sensors": "passed", "IMU mount": "passed", "channels": "passed",
                                "servo speed": "FAILED", "strokes": "passed"}
    assert report.summary() == "FAILED: servo speed (leg4_motor1)"
    assert report.items[3].detail.startswith("leg4_motor1: it turns at 0.50 of its rated speed")


def test_slow_sensors_fail_and_nothing_moves_after():
    report = check(rates={"imu": 200.0, "joints": 40.0})
    assert statuses(report) == {"sensors": "FAILED", "IMU mount": "passed", "channels": "skipped",
                                "servo speed": "skipped", "strokes": "skipped"}
    assert "joints 40 Hz (expected 100)" in report.items[0].detail


def test_no_check_at_all_is_not_a_pass():
    assert not PreflightReport().passed


def test_strokes_turn_the_body_the_commanded_way_and_a_swap_between_legs_shows():
    stance = reference_poses(PARAMS)[0]
    _, bench = rig_and_bench()
    bench.current = stance.joint_angles()
    good = check_strokes(bench, PARAMS, stance)
    assert good.passed and max(good.angles_deg) < 5.0
    _, bench = rig_and_bench(load_hardware_faults("{swapped_pwm: [[leg1_hip, leg2_hip]]}"))
    bench.current = stance.joint_angles()
    bad = check_strokes(bench, PARAMS, stance)
    assert not bad.passed and "yaw" in bad.problems[0]
