#!/usr/bin/env python3
"""rostest: the jog CLI (``python -m quadruped_control.bringup.jog --backend sim --keys ...``) on the simulated
robot, judged from what the fake PCA9685 really produces (/sim/servo_output: pulse widths, joint targets).

Keys ``nnh+++]`` then waits, then ``q``: leg1_hip selected, held where it is (its first pulses command the
angle it was at), then +1 +1 +1 +5 deg. Meanwhile no other channel ever has a pulse; a second jog started
while the first holds the bus is refused in one line naming the first (exit 2); after ``q`` every output is
off. Each key waits ``SETTLE`` s.
"""
import math
import subprocess
import sys
import threading
import time
import unittest

import numpy as np
import rospy
import rostest

from quadruped_common.robot import JOINT_NAMES
from quadruped_drivers.calibration import load_servo_calibration
from underwater_quadruped.msg import ServoCommand

JOINT = "leg1_hip"  # two "n" from the first joint, leg1_motor1
SETTLE = 0.25
STEPS_DEG = 8.0  # +1 +1 +1 +5
KEYS = "nnh+++]" + "." * 24 + "q"  # the dots: the first jog holds the bus for 6 s after its steps
TICK_US = 1e6 / 50.0 / 4096  # one PCA9685 count at 50 Hz


class JogTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("jog_test", anonymous=True)
        self.socket = rospy.get_param("~bus_socket")
        self.lock = threading.Lock()
        self.outputs = []
        rospy.Subscriber("sim/servo_output", ServoCommand, self.on_output, queue_size=500)
        index = JOINT_NAMES.index(JOINT)
        # the angle resolution at the chip (one count) plus the feedback's
        self.tolerance = math.radians(TICK_US / load_servo_calibration().joints[index].us_per_rad * 180 / math.pi
                                      + 0.2)

    def on_output(self, msg):
        with self.lock:
            self.outputs.append((time.monotonic(), np.array(msg.pulse_width_us), np.array(msg.joint_target)))

    def latest(self):
        with self.lock:
            return self.outputs[-1] if self.outputs else None

    def since(self, start):
        with self.lock:
            return [item for item in self.outputs if item[0] >= start]

    def jog(self, keys):
        return subprocess.Popen([sys.executable, "-m", "quadruped_control.bringup.jog", "--backend", "sim",
                                 "--bus-socket", self.socket, "--keys", keys, "--settle", str(SETTLE)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True)

    def test_jog_one_servo_on_the_simulated_robot(self):
        deadline = time.monotonic() + 30.0
        while self.latest() is None and time.monotonic() < deadline:
            rospy.sleep(0.1)
        self.assertIsNotNone(self.latest(), "sim_node publishes no servo output")
        index = JOINT_NAMES.index(JOINT)
        _, widths, targets = self.latest()
        self.assertTrue(np.all(widths == 0.0), "outputs on before the jog")
        start_angle = targets[index]  # a limp servo's target is where it is
        others = np.arange(len(JOINT_NAMES)) != index

        started = time.monotonic()
        first = self.jog(KEYS)
        try:
            goal = start_angle + math.radians(STEPS_DEG)
            reached = None
            deadline = time.monotonic() + 20.0
            while reached is None and time.monotonic() < deadline and first.poll() is None:
                latest = self.latest()
                if latest[1][index] > 0.0 and abs(latest[2][index] - goal) < self.tolerance:
                    reached = latest
                rospy.sleep(0.02)
            self.assertIsNotNone(reached, "%s never reached %+.1f deg from where it was (jog exit %s)"
                                 % (JOINT, STEPS_DEG, first.poll()))

            # a second jog while the first holds the bus: refused in one line naming the first
            second = self.jog("+q")
            out, err = second.communicate(timeout=30)
            self.assertEqual(second.returncode, 2, "second jog not refused: %s %s" % (out, err))
            self.assertEqual(err.count("\n"), 1, err)
            self.assertNotIn("Traceback", err)
            self.assertIn("in use by pid %d" % first.pid, err)
            self.assertIsNone(first.poll(), "the first jog ended before the second was refused")
            out, err = first.communicate(timeout=30)
        finally:
            if first.poll() is None:
                first.kill()
        self.assertEqual(first.returncode, 0, err)
        self.assertIn("%s held where it is" % JOINT, out)
        self.assertEqual(out.strip().splitlines()[-1], "outputs off")
        ended = time.monotonic()
        rospy.sleep(0.3)

        during = self.since(started)
        on = [item for item in during if item[1][index] > 0.0]
        self.assertTrue(on)
        self.assertTrue(all(np.all(item[1][others] == 0.0) for item in during),
                        "a channel other than %s had pulses" % JOINT)
        # held where it was: its first pulses command the angle it was at (no jump), then the steps
        self.assertLess(abs(on[0][2][index] - start_angle), self.tolerance, "the servo jumped when it was held")
        self.assertLess(abs(on[-1][2][index] - goal), self.tolerance)
        moved = max(abs(item[2][index] - start_angle) for item in during)
        self.assertLess(moved, math.radians(STEPS_DEG) + self.tolerance, "it went beyond the scripted steps")
        after = [item for item in self.since(ended + 0.1)]
        self.assertTrue(after and all(np.all(item[1] == 0.0) for item in after), "outputs on after quitting")


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "jog", JogTest, sys.argv)
