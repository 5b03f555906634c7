#!/usr/bin/env python3
"""rostest: the attitude controller killed with SIGKILL while armed comes back (its supervisor restarts it) disarmed.

The drivers' joint_states and outputs_state come from stand-ins (driver_stand_ins.py), so that the arming checks
pass. Sequence: armed at start-up (arm:=true) once the checks pass, and stroking; SIGKILL; the respawned process publishes
controller_state with armed false and no servo_command for 3 s, counts the restart in its diagnostics;
an arm command makes it stroke again; a second kill brings it back disarmed again.
"""
import os
import signal
import sys
import threading
import time
import unittest
import xmlrpc.client

import rosgraph
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Imu
from std_srvs.srv import SetBool

from driver_stand_ins import DriverStandIns
from underwater_quadruped.msg import ControllerState, ServoCommand

NODE = "/attitude_controller"


class ControllerRestartTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("controller_restart_test", anonymous=True)

    def setUp(self):
        self.lock = threading.Lock()
        self.commands, self.states, self.restarts = [], [], []
        self.imu_pub = rospy.Publisher("imu/data", Imu, queue_size=10)
        rospy.Subscriber("servo_command", ServoCommand, self.on_command, queue_size=200)
        rospy.Subscriber("controller_state", ControllerState, self.on_state, queue_size=200)
        rospy.Subscriber("diagnostics", DiagnosticArray, self.on_diagnostics, queue_size=50)
        self.stop = threading.Event()
        threading.Thread(target=self.publish_imu, daemon=True).start()
        self.stand_ins = DriverStandIns()
        self.stand_ins.start()

    def tearDown(self):
        self.stop.set()
        self.stand_ins.stop()

    def publish_imu(self):
        rate = rospy.Rate(200)
        while not self.stop.is_set() and not rospy.is_shutdown():
            msg = Imu()
            msg.header.stamp = rospy.Time.now()
            msg.header.frame_id = "imu_link"
            msg.orientation.w = 1.0
            self.imu_pub.publish(msg)
            rate.sleep()

    def on_command(self, msg):
        with self.lock:
            self.commands.append(time.monotonic())

    def on_state(self, msg):
        with self.lock:
            self.states.append((time.monotonic(), msg.armed))

    def on_diagnostics(self, msg):
        for status in msg.status:
            if status.name == "attitude_controller: control loop":
                values = {v.key: v.value for v in status.values}
                if "restarts" in values:
                    with self.lock:
                        self.restarts.append(int(values["restarts"]))

    def window(self, seconds):
        start = time.monotonic()
        rospy.sleep(seconds)
        with self.lock:
            return [t for t in self.commands if t >= start], [s for s in self.states if s[0] >= start]

    def controller_pid(self):
        master = rosgraph.Master("/controller_restart_test")
        uri = master.lookupNode(NODE)
        code, message, pid = xmlrpc.client.ServerProxy(uri).getPid("/controller_restart_test")
        self.assertEqual(code, 1, message)
        return pid

    def kill_and_wait_for_respawn(self, starts_after):
        pid = self.controller_pid()
        os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            try:
                if rospy.get_param(NODE + "/starts") == starts_after and self.controller_pid() != pid:
                    break
            except Exception:  # noqa: BLE001 - the node is not registered again yet
                pass
            rospy.sleep(0.2)
        else:
            self.fail("the controller was not respawned within 60 s")
        rospy.wait_for_service(NODE + "/arm", timeout=30.0)
        return pid

    def test_a_killed_controller_comes_back_disarmed(self):
        rospy.wait_for_service(NODE + "/arm", timeout=60.0)
        commands, states = self.window(2.0)
        self.assertTrue(commands, "armed at start-up (arm:=true) but no servo command")
        self.assertTrue(states and all(armed for _, armed in states[-20:]))

        for restart in (1, 2):
            self.kill_and_wait_for_respawn(restart + 1)
            commands, states = self.window(3.0)
            self.assertTrue(states, "the respawned controller publishes no controller_state")
            self.assertFalse(any(armed for _, armed in states), "respawned controller is armed")
            self.assertEqual(commands, [], "servo commands from a respawned, never re-armed controller")
            with self.lock:
                self.assertIn(restart, self.restarts, "diagnostics do not count the restart")
            # recovery needs the operator: an arm command, then the legs move again
            self.assertTrue(rospy.ServiceProxy(NODE + "/arm", SetBool)(True).success)
            commands, states = self.window(2.0)
            self.assertTrue(commands, "no servo command after the arm command")
            self.assertTrue(all(armed for _, armed in states[-10:]))


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "controller_restart", ControllerRestartTest, sys.argv)
