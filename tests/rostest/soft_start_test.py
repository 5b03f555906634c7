#!/usr/bin/env python3
"""rostest: the soft start on the simulated robot, judged on the simulated PCA9685's pulses (sim/servo_output).

~trials seeded trials, each: the legs posed away from the nominal pose (servo_command from this test while
the controller is disarmed; the watchdog's hold keeps them there), arm; then strokes for a seeded 1-2 s,
disarm (hold), arm again. After each arm: the first pulses are where the legs were (no jump), the joint speed
the pulses command, over any 0.2 s, stays within safety.yaml's bound (plus one PWM count), and the legs
reach the nominal pose within the travel time plus 1 s. Prints each arm's largest speed.
"""
import random
import sys
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
from std_srvs.srv import SetBool

from quadruped_common.robot import JOINT_NAMES
from quadruped_control.control.safety_config import load_safety_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.simulation import nominal_joint_angles
from quadruped_drivers.calibration import load_servo_calibration
from underwater_quadruped.msg import ServoCommand

WINDOW = 0.2  # s: speeds are judged over this span of the chip's pulses (they arrive at 100 Hz, jittered)


class SoftStartTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("soft_start_test", anonymous=True)
        self.lock = threading.Lock()
        self.outputs = []  # (receive time, 12 joint angles the chip's pulses command; NaN when off)
        self.calibration = load_servo_calibration()
        self.bound = load_safety_config().max_joint_speed
        robot = load_robot_params()
        self.nominal = nominal_joint_angles(robot).reshape(12)
        limits = robot.joint_limits.as_array()
        self.low, self.high = np.tile(limits[:, 0], 4), np.tile(limits[:, 1], 4)
        pulses = self.calibration.angles_to_pulses(self.nominal)
        self.tick_rad = np.max(np.abs(self.calibration.pulses_to_angles(pulses + 1e6 / 50 / 4096) - self.nominal))
        self.command_pub = rospy.Publisher("servo_command", ServoCommand, queue_size=10)
        rospy.Subscriber("sim/servo_output", ServoCommand, self.on_output, queue_size=200, tcp_nodelay=True)
        rospy.wait_for_service("attitude_controller/arm", timeout=60.0)
        self.arm_service = rospy.ServiceProxy("attitude_controller/arm", SetBool)
        self.rng = random.Random(int(rospy.get_param("~seed", 1)))

    def on_output(self, msg):
        widths = dict(zip(msg.name, msg.pulse_width_us))
        pulses = np.array([widths.get(name, 0.0) for name in JOINT_NAMES])
        angles = self.calibration.pulses_to_angles(pulses)
        angles[pulses <= 0.0] = np.nan
        with self.lock:
            self.outputs.append((time.monotonic(), angles))

    def since(self, start):
        with self.lock:
            return [(t, q) for t, q in self.outputs if t >= start]

    def latest(self):
        with self.lock:
            return self.outputs[-1][1].copy() if self.outputs else None

    def pose(self, angles, seconds=1.2):
        """Command ``angles`` directly (the controller disarmed) until the chip holds them."""
        pulses = self.calibration.angles_to_pulses(angles).tolist()
        end = time.monotonic() + seconds
        while time.monotonic() < end and not rospy.is_shutdown():
            msg = ServoCommand(name=list(JOINT_NAMES), pulse_width_us=pulses, joint_target=list(angles))
            msg.header.stamp = rospy.Time.now()
            self.command_pub.publish(msg)
            time.sleep(0.02)
        time.sleep(0.3)  # the watchdog's hold failsafe keeps the last pulses
        np.testing.assert_allclose(self.latest(), angles, atol=2 * self.tick_rad, err_msg="the pose did not reach the chip")

    def arm(self, value):
        answer = self.arm_service(value)
        self.assertTrue(answer.success, answer.message)

    def judge_arm(self, start_pose, what):
        """Arm from ``start_pose`` (on the chip now); returns the largest commanded speed seen (rad/s)."""
        travel = float(np.max(np.abs(start_pose - self.nominal)))
        armed_at = time.monotonic()
        self.arm(True)
        time.sleep(travel / self.bound + 1.0)
        rows = self.since(armed_at)
        self.assertGreater(len(rows), 20, "%s: no pulses after arming" % what)
        t = np.array([r[0] for r in rows])
        q = np.array([r[1] for r in rows])
        self.assertFalse(np.any(np.isnan(q)), "%s: an output went off" % what)
        np.testing.assert_allclose(q[0], start_pose, atol=2 * self.tick_rad,
                                   err_msg="%s: the first pulses after arming jumped" % what)
        reached = np.flatnonzero(np.max(np.abs(q - self.nominal), axis=1) <= 2 * self.tick_rad)
        self.assertTrue(reached.size, "%s: the legs never reached the nominal pose" % what)
        end = reached[0]  # the soft start ends here; the strokes after it may be faster
        fastest = 0.0
        for i in range(end + 1):
            j = np.searchsorted(t, t[i] + WINDOW)
            if j > end:
                break
            speed = (np.max(np.abs(q[j] - q[i])) - 2 * self.tick_rad) / (t[j] - t[i])
            fastest = max(fastest, speed)
        speed_all = np.max(np.abs(q[min(end, len(q) - 1)] - q[0])) / max(t[min(end, len(t) - 1)] - t[0], 1e-9)
        print("%s: travel %.2f rad, largest commanded speed %.3f rad/s over %.1f s (bound %.2f), mean %.3f"
              % (what, travel, fastest, WINDOW, self.bound, speed_all))
        self.assertLessEqual(fastest, self.bound * 1.05, "%s: the soft start moved a joint too fast" % what)
        return fastest

    def test_soft_start(self):
        deadline = time.monotonic() + 60.0
        while self.latest() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        self.assertIsNotNone(self.latest(), "no sim/servo_output")
        speeds = []
        for trial in range(int(rospy.get_param("~trials", 2))):
            offset = np.zeros(12)
            joints = self.rng.sample(range(12), 4)
            offset[joints] = [self.rng.choice((-1.0, 1.0)) * self.rng.uniform(0.3, 0.6) for _ in joints]
            start = np.clip(self.nominal + offset, self.low + 0.05, self.high - 0.05)
            self.pose(start)
            speeds.append(self.judge_arm(start, "trial %d, arm" % trial))
            time.sleep(self.rng.uniform(1.0, 2.0))  # strokes
            self.arm(False)
            time.sleep(0.3)
            mid_stroke = self.latest()
            speeds.append(self.judge_arm(mid_stroke, "trial %d, arm again" % trial))
            self.arm(False)
            time.sleep(0.3)
        print("soft start: largest commanded speed [rad/s] per arm: %s" % " ".join("%.3f" % v for v in speeds))


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "soft_start", SoftStartTest, sys.argv)
