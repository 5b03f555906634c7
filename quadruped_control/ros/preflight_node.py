"""ROS glue of the pre-dive check (:mod:`quadruped_control.bringup.preflight`): the running stack's topics as its
bench and sensors, the operator's prompts, the report beside the bags, the verdict for the arming gate.

The stack runs disarmed on a stand. The node drives the servos as a person would by hand: ServoCommand on
``servo_command`` (pwm_node takes it while the controller, disarmed, sends none) through the calibration
file's command map, the outputs switched with ``pwm_node/enable``; it reads ``joint_states`` and ``imu/data``.

Subscribes  imu/data (sensor_msgs/Imu), joint_states (sensor_msgs/JointState),
            controller_state (underwater_quadruped/ControllerState: refuses to run while armed)
Publishes   servo_command (underwater_quadruped/ServoCommand), preflight/result (diagnostic_msgs/DiagnosticStatus,
            latched: OK passed, ERROR failed; values: each check and the report's path),
            sim/stand_rpy_deg (geometry_msgs/Vector3Stamped, with ~simulated_operator only)
Parameters  ~simulated_operator (false: prompts on the terminal; true: holds the simulated robot's body in each
            guided pose through sim/stand_rpy_deg), ~report_dir (. : where preflight_<time>.md / .json go, beside
            the bags), ~imu_rate (200), ~joint_rate (100), ~min_rate_fraction (0.9: the least share of each rate
            that passes), ~robot_yaml, ~calibration_yaml, ~safety_yaml (the servo model's lag for the speed check),
            ~settle (0.4 s), ~sweep_points (5: per joint), ~min_speed_fraction (0.7: of the rated speed),
            ~exit_when_done (false: the node stays up to keep the latched verdict; true: exits 0 if passed, else 1)
"""
from __future__ import annotations

import json
import math
import os
import threading
import time
from typing import Dict, List, Optional

import numpy as np
import rospy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import Imu, JointState
from std_srvs.srv import SetBool

from quadruped_common.robot import JOINT_NAMES
from quadruped_common.ros.node_startup import start_node
from quadruped_control.bringup.preflight import PreflightReport, SensorReadings, run_preflight
from quadruped_control.bringup.servo_check import Bench, ServoCheckSettings
from quadruped_control.control.safety_config import load_safety_config
from quadruped_control.model.params import load_robot_params
from quadruped_drivers.calibration import ServoCalibration, load_servo_calibration
from quadruped_drivers.servo_rig import COMMAND_PERIOD, ramp
from underwater_quadruped.msg import ControllerState, ServoCommand



class StackBench(Bench, SensorReadings):
    """The running stack as the check's bench and sensors (module docstring)."""

    def __init__(self, calibration: ServoCalibration, speed: float = math.radians(90.0)) -> None:
        self.calibration = calibration
        self.speed = speed
        self.current = np.array([j.neutral_angle_rad for j in calibration.joints])
        self.index = {name: i for i, name in enumerate(JOINT_NAMES)}
        self.lock = threading.Lock()
        self.joints = np.full(len(JOINT_NAMES), math.nan)
        self.joint_seq = 0
        self.recording: Optional[List] = None  # (stamp s, angles) of each joint_states while a step is recorded
        self.counts = {"imu": 0, "joints": 0}
        self.forces: List[np.ndarray] = []
        self.command_pub = rospy.Publisher("servo_command", ServoCommand, queue_size=1, tcp_nodelay=True)
        rospy.Subscriber("joint_states", JointState, self._on_joints, queue_size=10, tcp_nodelay=True)
        rospy.Subscriber("imu/data", Imu, self._on_imu, queue_size=50, tcp_nodelay=True)
        self.enable = rospy.ServiceProxy("pwm_node/enable", SetBool)

    def _on_joints(self, msg: JointState) -> None:
        values = np.full(len(JOINT_NAMES), math.nan)
        for name, position in zip(msg.name, msg.position):
            if name in self.index:
                values[self.index[name]] = position
        with self.lock:
            self.joints = values
            self.joint_seq += 1
            self.counts["joints"] += 1
            if self.recording is not None:
                self.recording.append((msg.header.stamp.to_sec(), values))

    def _on_imu(self, msg: Imu) -> None:
        a = msg.linear_acceleration
        with self.lock:
            self.counts["imu"] += 1
            self.forces.append(np.array([a.x, a.y, a.z]))
            del self.forces[:-2000]

    # ---- Bench ---------------------------------------------------------------------------------

    def outputs(self, on: bool) -> None:
        rospy.wait_for_service("pwm_node/enable", timeout=10.0)
        answer = self.enable(bool(on))
        if not answer.success:
            raise RuntimeError("pwm_node/enable %s refused: %s" % (on, answer.message))

    def hold(self, angles: np.ndarray, duration: float) -> None:
        msg = ServoCommand()
        msg.name = list(JOINT_NAMES)
        msg.pulse_width_us = [float(v) for v in self.calibration.angles_to_pulses(angles)]
        msg.joint_target = [float(v) for v in angles]
        end = rospy.get_time() + duration
        while not rospy.is_shutdown():
            msg.header.stamp = rospy.Time.now()
            self.command_pub.publish(msg)
            remaining = end - rospy.get_time()
            if remaining <= 0:
                break
            rospy.sleep(min(COMMAND_PERIOD, remaining))
        self.current = np.array(angles, dtype=float)

    def move_to(self, angles: np.ndarray) -> None:
        for pose in ramp(self.current, angles, self.speed):
            self.hold(pose, COMMAND_PERIOD)

    def step(self, angles: np.ndarray, duration: float):
        """Readings stamped at or after the command's publication (the feedback node stamps each at its reading)."""
        sent = rospy.get_time()
        with self.lock:
            self.recording = []
        try:
            self.hold(angles, duration)
        finally:
            with self.lock:
                rows, self.recording = self.recording, None
        rows = [(t, q) for t, q in rows if t >= sent]
        return (np.array([t for t, _ in rows]), np.array([q for _, q in rows]).reshape(len(rows), len(JOINT_NAMES)))

    def wait(self, seconds: float) -> None:
        rospy.sleep(seconds)

    def read_volts(self) -> np.ndarray:
        raise ValueError("the running stack publishes joint angles, not feedback volts")

    def read_angles(self) -> np.ndarray:
        """The next joint_states message's angles (waits up to 0.2 s for a new one)."""
        with self.lock:
            seq = self.joint_seq
        deadline = rospy.get_time() + 0.2
        while not rospy.is_shutdown() and rospy.get_time() < deadline:
            with self.lock:
                if self.joint_seq != seq:
                    return self.joints.copy()
            rospy.sleep(0.005)
        return np.full(len(JOINT_NAMES), math.nan)

    # ---- SensorReadings ------------------------------------------------------------------------

    def rates(self, seconds: float) -> Dict[str, float]:
        with self.lock:
            before = dict(self.counts)
        start = rospy.get_time()
        rospy.sleep(seconds)
        elapsed = max(rospy.get_time() - start, 1e-9)
        with self.lock:
            return {name: (self.counts[name] - before[name]) / elapsed for name in before}

    def joint_angles(self) -> np.ndarray:
        with self.lock:
            return self.joints.copy()

    def specific_force(self, seconds: float) -> np.ndarray:
        with self.lock:
            total = self.counts["imu"]
        rospy.sleep(seconds)
        with self.lock:
            new = self.counts["imu"] - total
            samples = self.forces[-new:] if new > 0 else []
        return np.mean(samples, axis=0) if samples else np.full(3, math.nan)


class PreflightNode:
    def __init__(self) -> None:
        optional = lambda name: rospy.get_param(name, "") or None  # noqa: E731
        self.params = load_robot_params(optional("~robot_yaml"))
        self.calibration = load_servo_calibration(optional("~calibration_yaml"))
        self.simulated = bool(rospy.get_param("~simulated_operator", False))
        self.report_dir = os.path.expanduser(str(rospy.get_param("~report_dir", ".")))
        self.expected = {"imu": float(rospy.get_param("~imu_rate", 200.0)),
                         "joints": float(rospy.get_param("~joint_rate", 100.0))}
        safety = load_safety_config(optional("~safety_yaml"))
        self.settings = ServoCheckSettings(settle_s=float(rospy.get_param("~settle", ServoCheckSettings.settle_s)),
                                           points=int(rospy.get_param("~sweep_points", ServoCheckSettings.points)),
                                           min_speed_fraction=float(rospy.get_param(
                                               "~min_speed_fraction", ServoCheckSettings.min_speed_fraction)),
                                           time_constant=safety.tracking.time_constant)
        self.min_rate_fraction = float(rospy.get_param("~min_rate_fraction", 0.9))
        self.result_pub = rospy.Publisher("preflight/result", DiagnosticStatus, queue_size=1, latch=True)
        self.stand_pub = rospy.Publisher("sim/stand_rpy_deg", Vector3Stamped, queue_size=1, latch=True)
        self.armed: Optional[bool] = None
        rospy.Subscriber("controller_state", ControllerState, self._on_state, queue_size=1)
        self.bench = StackBench(self.calibration)

    def _on_state(self, msg: ControllerState) -> None:
        self.armed = bool(msg.armed)

    def guide(self, name: str, instruction: str, roll_deg: float, pitch_deg: float) -> None:
        """The operator holds the robot in a guided pose: a prompt, or the simulated robot's stand."""
        if self.simulated:  # NaN: off the stand
            msg = Vector3Stamped()
            msg.header.stamp = rospy.Time.now()
            msg.vector.x, msg.vector.y, msg.vector.z = roll_deg, pitch_deg, 0.0 if math.isfinite(roll_deg) else math.nan
            self.stand_pub.publish(msg)
            rospy.sleep(0.5)
        else:
            input("pre-dive check: %s (%s), hold it still and press Enter. " % (instruction, name))

    def run(self) -> PreflightReport:
        # the stack up: the controller's state, then the sensors flowing for a second
        deadline = time.monotonic() + 30.0
        while not rospy.is_shutdown() and time.monotonic() < deadline and (
                self.armed is None or min(self.bench.counts.values()) == 0):
            time.sleep(0.05)
        rospy.sleep(1.0)
        if self.armed is not False:
            report = PreflightReport()
            report.notes.append("not run: the controller is %s; disarm it first" % (
                "armed" if self.armed else "not publishing controller_state"))
        else:
            report = run_preflight(self.bench, self.bench, self.guide, self.params, self.calibration, self.expected,
                                   self.settings, log=rospy.loginfo, min_rate_fraction=self.min_rate_fraction)
        path = self.save(report)
        status = DiagnosticStatus(level=DiagnosticStatus.OK if report.passed else DiagnosticStatus.ERROR,
                                  name="pre-dive check", message=report.summary(), hardware_id="none")
        status.values = [KeyValue(item.name, "%s: %s" % (item.status, item.detail)) for item in report.items]
        status.values.append(KeyValue("report", path))
        self.result_pub.publish(status)
        (rospy.loginfo if report.passed else rospy.logerr)("pre-dive check %s; report %s", report.summary(), path)
        return report

    def save(self, report: PreflightReport) -> str:
        os.makedirs(self.report_dir, exist_ok=True)
        base = os.path.join(self.report_dir, "preflight_%s" % time.strftime("%Y-%m-%d-%H-%M-%S"))
        with open(base + ".md", "w", encoding="utf-8") as f:
            f.write(report.markdown())
        with open(base + ".json", "w", encoding="utf-8") as f:
            json.dump(_finite(report.as_dict()), f, indent=1, allow_nan=False)
        return base + ".md"


def _finite(value):
    """``value`` with every non-finite float as None (strict JSON)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def main(argv: Optional[List[str]] = None) -> None:
    node = start_node("preflight", PreflightNode)
    report = node.run()
    if node.simulated:
        node.guide("off the stand", "into the water", math.nan, math.nan)  # the simulated body floats again
    if rospy.get_param("~exit_when_done", False):
        rospy.sleep(1.0)  # the latched verdict reaches the subscribers before the node ends
        raise SystemExit(0 if report.passed else 1)
    rospy.spin()  # keeps the latched verdict for a controller that restarts
