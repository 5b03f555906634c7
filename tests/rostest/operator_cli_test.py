#!/usr/bin/env python3
"""rostest: ``uq`` (nodes/uq, quadruped_control/ros/operator_tool.py) on the simulated robot, in real time.

Each subcommand runs as its own process (``rosrun underwater_quadruped uq ...``), as the operator runs it; the
test checks what it prints, its exit status and its effect: status disarmed; arm (controller_state armed); a
relative setpoint taken and reached (controller_state's setpoint, the degree telemetry); absolute and tilt
setpoints taken; status armed; a named sequence started (its first setpoint in controller_state), then stopped
with Ctrl-C; stop (estop_state latched, disarmed); arm refused during the e-stop (the reason printed, exit 1);
status naming the refusal; reset (estop_state clear) and arm again; disarm; the sequence refused, disarmed.
"""
import math
import os
import signal
import subprocess
import sys
import threading
import time
import unittest

import rospkg
import rospy
import rostest
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import Bool, Float64

from quadruped_common.so3 import quat_to_rot, rot_to_rpy
from underwater_quadruped.msg import ControllerState

#: the first command as the operator types it; the others run the same script without rosrun's look-up (1-2 s)
ROSRUN = ["rosrun", "underwater_quadruped", "uq"]
UQ = [os.path.join(rospkg.RosPack().get_path("underwater_quadruped"), "nodes", "uq")]


class OperatorCliTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("operator_cli_test", anonymous=True)
        self.lock = threading.Lock()
        self.latest = {}
        for topic, kind in (("controller_state", ControllerState), ("estop_state", Bool),
                            ("telemetry/rpy_deg", Vector3Stamped), ("telemetry/setpoint_rpy_deg", Vector3Stamped),
                            ("telemetry/heading_at_arming_deg", Float64)):
            rospy.Subscriber(topic, kind, self.store, callback_args=topic, queue_size=1)
        rospy.wait_for_service("attitude_controller/arm", timeout=60.0)
        self.wait(lambda: "controller_state" in self.latest and "estop_state" in self.latest, 60.0, "the stack")

    def store(self, msg, topic):
        with self.lock:
            self.latest[topic] = msg

    def get(self, topic):
        with self.lock:
            return self.latest.get(topic)

    def wait(self, predicate, seconds, what):
        deadline = time.monotonic() + seconds
        while not predicate():
            self.assertLess(time.monotonic(), deadline, "timed out waiting for " + what)
            time.sleep(0.05)

    def uq(self, *args, code=0, says="", command=UQ):
        """Run ``uq ARGS``; check its exit status and that it printed ``says``; its output."""
        start = time.monotonic()
        done = subprocess.run(command + list(args), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              universal_newlines=True, timeout=60)
        print("uq %s -> %d in %.1f s: %s" % (" ".join(args), done.returncode, time.monotonic() - start,
                                            done.stdout.strip()))
        self.assertEqual(done.returncode, code, done.stdout)
        self.assertIn(says, done.stdout)
        return done.stdout

    def setpoint_rpy(self):
        """controller_state's (world) setpoint, REP-103 degrees."""
        q = self.get("controller_state").setpoint
        return [math.degrees(a) for a in rot_to_rpy(quat_to_rot([q.x, q.y, q.z, q.w]))]

    def armed(self):
        return self.get("controller_state").armed

    def test_every_subcommand_on_the_simulated_robot(self):
        self.uq("status", says="disarmed | e-stop clear | attitude roll", command=ROSRUN)
        self.uq("arm", says="armed")
        self.wait(self.armed, 5.0, "controller_state armed")

        self.uq("setpoint", "15", "0", "0", says="setpoint taken: roll 15.0 pitch 0.0 yaw 0.0 deg, relative")
        heading = self.get("telemetry/heading_at_arming_deg").data
        self.assertTrue(math.isfinite(heading))
        roll, pitch, yaw = self.setpoint_rpy()
        self.assertAlmostEqual(roll, 15.0, delta=0.1)
        self.assertAlmostEqual(math.remainder(yaw - heading, 360.0), 0.0, delta=0.1)  # yaw 0 where it faced at arming
        self.wait(lambda: abs(self.get("telemetry/setpoint_rpy_deg").vector.x - 15.0) < 0.1, 2.0, "telemetry setpoint")
        self.wait(lambda: abs(self.get("telemetry/rpy_deg").vector.x - 15.0) < 3.0, 40.0, "roll 15 reached")

        self.uq("setpoint", "0", "0", "30", "--absolute", says="absolute; world roll 0.0 pitch 0.0 yaw 30.0 deg")
        self.assertAlmostEqual(self.setpoint_rpy()[2], 30.0, delta=0.1)
        self.uq("setpoint", "10", "0", "0", "--tilt", says="tilt (yaw free)")
        self.uq("status", says="armed")

        sequence = subprocess.Popen(UQ + ["sequence", "step_test"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    universal_newlines=True)
        try:
            self.wait(lambda: abs(self.setpoint_rpy()[0] - 45.0) < 0.1, 20.0, "the sequence's first setpoint")
        finally:
            stopped = time.monotonic()
            sequence.send_signal(signal.SIGINT)
            output = sequence.communicate(timeout=30)[0]
        print("uq sequence step_test -> %d, %.1f s after Ctrl-C: %s" % (sequence.returncode,
                                                                       time.monotonic() - stopped, output.strip()))
        self.assertLess(time.monotonic() - stopped, 5.0, "Ctrl-C did not end the sequence at once")
        self.assertIn("sequence step_test: 11 setpoints", output)
        self.assertIn("stopped at setpoint 1 of 11", output)
        self.assertEqual(sequence.returncode, 1)

        self.uq("stop", says="e-stop")
        self.wait(lambda: self.get("estop_state").data, 2.0, "estop_state latched")
        self.wait(lambda: not self.armed(), 2.0, "disarmed by the e-stop")
        self.uq("arm", code=1, says="arming refused: e-stop: the e-stop is latched")
        self.assertFalse(self.armed())
        self.uq("status", says="E-STOP LATCHED")

        self.uq("reset", says="outputs enabled")
        self.wait(lambda: not self.get("estop_state").data, 2.0, "estop_state clear")
        time.sleep(0.5)  # pwm_node's outputs_state (5 Hz) says enabled before the arm is judged
        self.uq("arm", says="armed")
        self.wait(self.armed, 5.0, "armed again after the reset")
        self.uq("disarm", says="disarmed")
        self.wait(lambda: not self.armed(), 2.0, "disarmed")
        self.uq("--timeout", "1", "sequence", "step_test", code=1, says="refused: the controller was not armed")


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "operator_cli", OperatorCliTest, sys.argv)
