#!/usr/bin/env python3
"""rostest: the tether failsafe on the simulated robot, in real time.

~trials seeded trials: the test is the laptop (tether/heartbeat at 5 Hz); armed and stroking, after a seeded
0.3-1.5 s the heartbeat stops; the controller must disarm within ~timeout + 0.1 s of the last heartbeat; when the
heartbeat returns nothing moves (no servo_command, still disarmed) until the next arm. Arming without the
heartbeat is refused, naming it. Prints each delay.
"""
import random
import sys
import threading
import time
import unittest

import rospy
import rostest
from std_msgs.msg import Header
from std_srvs.srv import SetBool

from underwater_quadruped.msg import ControllerState, ServoCommand

NODE = "/attitude_controller"


class TetherTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("tether_test", anonymous=True)
        self.lock = threading.Lock()
        self.beating = threading.Event()
        self.last_beat = None
        self.armed = False
        self.acting = False
        self.disarmed_at = None
        self.commands = []
        self.pub = rospy.Publisher("tether/heartbeat", Header, queue_size=1)
        rospy.Subscriber("controller_state", ControllerState, self.on_state, queue_size=10, tcp_nodelay=True)
        rospy.Subscriber("servo_command", ServoCommand, self.on_command, queue_size=100)
        threading.Thread(target=self.beat, daemon=True).start()
        rospy.wait_for_service(NODE + "/arm", timeout=60.0)
        self.arm = rospy.ServiceProxy(NODE + "/arm", SetBool)
        self.timeout = float(rospy.get_param("~timeout"))
        self.rng = random.Random(int(rospy.get_param("~seed", 1)))

    def beat(self):
        while not rospy.is_shutdown():
            if self.beating.is_set():
                self.pub.publish(Header(stamp=rospy.Time.now()))
                with self.lock:
                    self.last_beat = time.monotonic()
            time.sleep(0.2)

    def on_state(self, msg):
        with self.lock:
            if self.armed and not msg.armed and self.disarmed_at is None:
                self.disarmed_at = time.monotonic()
            self.armed, self.acting = bool(msg.armed), bool(msg.armed and not msg.holding)

    def on_command(self, _msg):
        with self.lock:
            self.commands.append(time.monotonic())

    def wait(self, predicate, seconds, what):
        deadline = time.monotonic() + seconds
        while not predicate():
            self.assertLess(time.monotonic(), deadline, what)
            time.sleep(0.01)

    def test_heartbeat_loss_disarms_and_nothing_moves_when_it_returns(self):
        refused = self.arm(True)
        self.assertFalse(refused.success)
        self.assertIn("no tether heartbeat", refused.message)
        delays = []
        for _ in range(int(rospy.get_param("~trials", 3))):
            self.beating.set()
            self.wait(lambda: self.arm(True).success, 30.0, "arming with the heartbeat")
            self.wait(lambda: self.acting, 30.0, "the controller stroking")
            time.sleep(self.rng.uniform(0.3, 1.5))
            with self.lock:
                self.disarmed_at = None
            self.beating.clear()
            self.wait(lambda: self.disarmed_at is not None, self.timeout + 5.0, "the failsafe never disarmed")
            with self.lock:
                delays.append(self.disarmed_at - self.last_beat)
            self.beating.set()  # the tether is back: nothing may move until the next arm
            time.sleep(0.3)
            start = time.monotonic()
            time.sleep(1.0)
            with self.lock:
                moved = [t for t in self.commands if t >= start]
                armed = self.armed
            self.assertEqual(moved, [], "servo commands after the heartbeat returned, before an arm")
            self.assertFalse(armed)
        print("tether failsafe: disarmed after the last heartbeat [s]: %s (timeout %.1f s)"
              % (" ".join("%.3f" % d for d in delays), self.timeout))
        self.assertLessEqual(max(delays), self.timeout + 0.1)


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "tether", TetherTest, sys.argv)
