#!/usr/bin/env python3
"""rostest: the PWM node on the simulated bus clamps commands at the chip and trips its watchdog.

Reads what the fake PCA9685 really produces (/sim/servo_output from sim_node). The launch file sets
the failsafe to 'neutral' so that tripping is visible as a change of every channel to its neutral width.
"""
import sys
import threading
import time
import unittest

import numpy as np
import rospy
import rostest

from quadruped_common.robot import JOINT_NAMES
from quadruped_drivers.hardware_config import load_hardware_config
from underwater_quadruped.msg import ServoCommand

TICK_US = 1e6 / 50.0 / 4096  # one PCA9685 count at 50 Hz: the resolution of a pulse width


class PwmWatchdogTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("pwm_watchdog_test", anonymous=True)
        self.hardware = load_hardware_config(rospy.get_param("~hardware_yaml"))
        self.lock = threading.Lock()
        self.outputs = []
        self.pub = rospy.Publisher("servo_command", ServoCommand, queue_size=10)
        rospy.Subscriber("sim/servo_output", ServoCommand, self.on_output, queue_size=200)

    def on_output(self, msg):
        with self.lock:
            self.outputs.append((time.monotonic(), np.array(msg.pulse_width_us)))

    def latest(self):
        with self.lock:
            return self.outputs[-1][1] if self.outputs else None

    def publish_for(self, widths, seconds):
        msg = ServoCommand(name=list(JOINT_NAMES), pulse_width_us=list(widths), joint_target=[0.0] * 12)
        rate = rospy.Rate(100)
        end = time.monotonic() + seconds
        while time.monotonic() < end and not rospy.is_shutdown():
            msg.header.stamp = rospy.Time.now()
            self.pub.publish(msg)
            rate.sleep()
        return time.monotonic()

    def test_clamp_and_watchdog(self):
        deadline = time.monotonic() + 60.0
        while self.latest() is None and time.monotonic() < deadline:
            rospy.sleep(0.1)
        self.assertIsNotNone(self.latest(), "sim_node publishes no servo output")
        # sim_node's output may come before pwm_node (slower to start on 3.8) has subscribed: wait for it.
        while self.pub.get_num_connections() == 0 and time.monotonic() < deadline:
            rospy.sleep(0.1)
        self.assertGreater(self.pub.get_num_connections(), 0, "pwm_node never subscribed to servo_command")

        # In-range command reaches the chip to within one PWM count, within 5 s of the first command.
        commanded = np.linspace(900.0, 2100.0, 12)
        for _ in range(5):
            self.publish_for(commanded, 1.0)
            if np.allclose(self.latest(), commanded, atol=TICK_US):
                break
        np.testing.assert_allclose(self.latest(), commanded, atol=TICK_US)

        # Out-of-range commands are clamped to each channel's limits at the chip.
        wild = np.array([100.0, 5000.0] * 6)
        self.publish_for(wild, 1.0)
        np.testing.assert_allclose(self.latest(), np.clip(wild, self.hardware.min_us, self.hardware.max_us),
                                   atol=TICK_US)
        with self.lock:
            for _, widths in self.outputs:
                on = widths > 0
                self.assertTrue(np.all(widths[on] >= self.hardware.min_us[on] - TICK_US))
                self.assertTrue(np.all(widths[on] <= self.hardware.max_us[on] + TICK_US))

        # Commands stop: every channel goes to its neutral width within the watchdog timeout plus one
        # watchdog check (10 ms), one simulation step (10 ms) and scheduling margin.
        stopped = self.publish_for(np.full(12, 1000.0), 1.0)
        timeout = self.hardware.watchdog_timeout
        tripped_at = None
        while time.monotonic() < stopped + 2.0:
            rospy.sleep(0.005)
            with self.lock:
                for stamp, widths in self.outputs:
                    if stamp > stopped and np.allclose(widths, self.hardware.neutral_us, atol=TICK_US):
                        tripped_at = stamp
                        break
            if tripped_at is not None:
                break
        self.assertIsNotNone(tripped_at, "the PWM watchdog never reached the neutral failsafe")
        elapsed = tripped_at - stopped
        self.assertGreater(elapsed, 0.8 * timeout, "watchdog tripped before its timeout")
        self.assertLess(elapsed, timeout + 0.15, "watchdog took %.0f ms" % (elapsed * 1e3))


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "pwm_watchdog", PwmWatchdogTest, sys.argv)
