#!/usr/bin/env python3
"""rostest: the servo tracking watch names each faulty servo of the simulated robot within ~within s of arming.

Arms the controller (its setpoint away from the robot's attitude, so the legs stroke at once), then reads the
controller's "servo tracking" diagnostic: each joint of ~faulty must be WARN or ERROR by name within ~within s of
the arm, and no other joint may be named. Prints when each was named and every healthy joint's last status.
"""
import sys
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from std_srvs.srv import SetBool


class ServoTrackingTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("servo_tracking_test", anonymous=True)
        self.lock = threading.Lock()
        self.named = {}  # joint -> (first time named, level)
        self.healthy_named = set()
        self.faulty = rospy.get_param("~faulty").split()
        self.armed_at = None
        self.last_status = {}
        rospy.Subscriber("diagnostics", DiagnosticArray, self.on_diagnostics, queue_size=50)
        rospy.wait_for_service("attitude_controller/arm", timeout=60.0)
        self.arm = rospy.ServiceProxy("attitude_controller/arm", SetBool)

    def on_diagnostics(self, msg):
        now = rospy.get_time()
        for status in msg.status:
            if not status.name.endswith("servo tracking") or self.armed_at is None:
                continue
            with self.lock:
                self.last_status = {item.key: item.value for item in status.values}
            for item in status.values:
                if item.value.startswith(("WARN", "ERROR")):
                    with self.lock:
                        if item.key in self.faulty:
                            self.named.setdefault(item.key, (now - self.armed_at, item.value))
                        else:
                            self.healthy_named.add("%s: %s" % (item.key, item.value))

    def test_faulty_servos_are_named(self):
        within = float(rospy.get_param("~within", 2.0))
        deadline = rospy.get_time() + 60.0
        while True:
            answer = self.arm(True)
            if answer.success:
                self.armed_at = rospy.get_time()
                break
            self.assertLess(rospy.get_time(), deadline, "arming refused: %s" % answer.message)
            time.sleep(0.5)
        rospy.sleep(within + 3.0)  # simulated time in lock-step
        with self.lock:
            named, healthy = dict(self.named), set(self.healthy_named)
        with self.lock:
            last = dict(self.last_status)
        for joint, value in sorted(last.items()):  # the healthy joints' evidence for the bound and slow_ratio
            if joint not in self.faulty:
                print("healthy %s: %s" % (joint, value))
        for joint in self.faulty:
            print("%s: %s" % (joint, "named %.2f s after arming (%s)" % named[joint] if joint in named else "NOT named"))
        self.assertEqual(sorted(named), sorted(self.faulty), "faulty servos not named: %s"
                         % sorted(set(self.faulty) - set(named)))
        late = {joint: t for joint, (t, _) in named.items() if t > within}
        self.assertEqual(late, {}, "named later than %.1f s after arming" % within)
        self.assertEqual(healthy, set(), "healthy joints named")


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "servo_tracking", ServoTrackingTest, sys.argv)
