#!/usr/bin/env python3
"""rostest: a driver that cannot start (its I2C device file missing) ends with one line and is not restarted.

Runs ``roslaunch underwater_quadruped drivers.launch backend:=real`` (respawn on, as robot.launch) with a
copy of config/hardware.yaml whose ``i2c.bus`` names a bus this machine does not have, and reads what the
launch prints for ``~observe`` s after the first node gave up. Each of pwm_node, servo_feedback_node and
ms5837_node must: print exactly one line of its own, the FATAL "<node> cannot start: /dev/i2c-N does not
exist. Fix: ..."; be started once by roslaunch and never again by its supervisor; end with exit status 78
(EX_CONFIG). Nothing in the output may be a traceback. (vn100_node, its port missing too, keeps trying to connect: a USB
adapter plugged in later is found without a restart.)
"""
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest

import rospy
import rostest
import yaml

from quadruped_common.config import config_dir
from quadruped_common.startup_errors import EX_CONFIG

ANSI = re.compile(r"\x1b\[[0-9;]*m|\x1b\][^\x07]*\x07")
DRIVERS = ("pwm_node", "servo_feedback_node", "ms5837_node")


def missing_bus() -> int:
    return next(n for n in range(99, 1000) if not os.path.exists("/dev/i2c-%d" % n))


class NodeCannotStartTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("node_cannot_start_test", anonymous=True)
        self.observe = float(rospy.get_param("~observe", 5.0))
        self.scratch = tempfile.mkdtemp(prefix="uq_cannot_start_")
        self.bus = missing_bus()
        with open(os.path.join(config_dir(), "hardware.yaml")) as stream:
            hardware = yaml.safe_load(stream)
        hardware["i2c"]["bus"] = self.bus
        self.hardware_yaml = os.path.join(self.scratch, "hardware.yaml")
        with open(self.hardware_yaml, "w") as stream:
            yaml.safe_dump(hardware, stream, sort_keys=False)
        self.lines = []
        self.lock = threading.Lock()

    def tearDown(self):
        shutil.rmtree(self.scratch, ignore_errors=True)

    def read(self, stream):
        for raw in stream:
            with self.lock:
                self.lines.append(ANSI.sub("", raw).rstrip("\n"))

    def output(self):
        with self.lock:
            return list(self.lines)

    def test_a_missing_i2c_bus_is_one_line_and_no_restart(self):
        env = dict(os.environ, UQ_LOCK_DIR=self.scratch, PYTHONUNBUFFERED="1")
        launch = subprocess.Popen(
            ["roslaunch", "underwater_quadruped", "drivers.launch", "backend:=real",
             "hardware_yaml:=%s" % self.hardware_yaml, "imu_port:=%s" % os.path.join(self.scratch, "no_vn100")],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True,
            start_new_session=True)
        reader = threading.Thread(target=self.read, args=(launch.stdout,), daemon=True)
        reader.start()
        try:
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline and not all(
                    any("%s cannot start" % node in line for line in self.output()) for node in DRIVERS):
                self.assertIsNone(launch.poll(), "roslaunch ended early:\n" + "\n".join(self.output()))
                time.sleep(0.1)
            time.sleep(self.observe)  # a restart would print its line again within the first back-off (1 s)
        finally:
            launch.send_signal(signal.SIGINT)
            try:
                launch.wait(timeout=40.0)
            except subprocess.TimeoutExpired:
                os.killpg(launch.pid, signal.SIGKILL)
                launch.wait()
            reader.join(5.0)
        out = self.output()
        text = "\n".join(out)
        print(text)
        self.assertNotIn("Traceback", text)
        device = "/dev/i2c-%d" % self.bus
        for node in DRIVERS:
            # its log lines (rospy's "[LEVEL] [time]: <node>...") and its supervisor's ("<node>: ..."), not
            # roslaunch's own about it (summary, started, died)
            own = [line for line in out if re.match(r"(\[[A-Z]+\] \[[0-9.]+\]: )?%s\b" % node, line)]
            self.assertEqual(len(own), 1, "%s printed %d lines of its own:\n%s" % (node, len(own), "\n".join(own)))
            self.assertRegex(own[0], r"^\[FATAL\] \[[0-9.]+\]: %s cannot start: %s does not exist\. Fix: .*i2c\.bus"
                             % (node, re.escape(device)))
            starts = [line for line in out if re.match(r"process\[%s-\d+\]: started with pid" % node, line)]
            self.assertEqual(len(starts), 1, "roslaunch started %s %d times" % (node, len(starts)))
            died = [line for line in out if re.match(r"\[%s-\d+\] process has died \[pid \d+, exit code %d,"
                                                     % (node, EX_CONFIG), line)]
            self.assertEqual(len(died), 1, "%s did not end with exit status %d once" % (node, EX_CONFIG))
            restarts = [line for line in out if line.startswith(node + ": ") and "starting it again" in line]
            self.assertEqual(restarts, [], "%s was started again by its supervisor" % node)


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "node_cannot_start", NodeCannotStartTest, sys.argv)
