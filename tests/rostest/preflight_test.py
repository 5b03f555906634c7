#!/usr/bin/env python3
"""rostest: the pre-dive check on the simulated robot decides whether the controller may arm.

~expect_pass: the check's verdict (preflight/result) must be OK and arming must succeed; otherwise ERROR, the
summary must name ~expect_failed (the failed check), a value must name ~expect_part (the joint or the IMU),
and arming must be refused with the reason, naming a joint part. The report files must exist.
"""
import os
import sys
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from std_srvs.srv import SetBool


class PreflightTest(unittest.TestCase):
    def test_verdict_gates_arming(self):
        rospy.init_node("preflight_test", anonymous=True)
        result = []
        rospy.Subscriber("preflight/result", DiagnosticStatus, result.append, queue_size=1)
        deadline = time.monotonic() + float(rospy.get_param("~timeout", 240.0))
        while not result and time.monotonic() < deadline and not rospy.is_shutdown():
            time.sleep(0.1)
        self.assertTrue(result, "no preflight/result within the timeout")
        status = result[-1]
        values = {kv.key: kv.value for kv in status.values}
        self.assertTrue(os.path.exists(values["report"]), values)
        self.assertTrue(os.path.exists(values["report"][:-3] + ".json"))
        rospy.wait_for_service("attitude_controller/arm", timeout=30.0)
        answer = rospy.ServiceProxy("attitude_controller/arm", SetBool)(True)
        if rospy.get_param("~expect_pass"):
            self.assertEqual(status.level, DiagnosticStatus.OK, "%s %s" % (status.message, values))
            self.assertTrue(answer.success, answer.message)
        else:
            self.assertEqual(status.level, DiagnosticStatus.ERROR, status.message)
            self.assertIn(rospy.get_param("~expect_failed"), status.message)
            self.assertTrue(any(rospy.get_param("~expect_part") in v for v in values.values()), values)
            self.assertFalse(answer.success, answer.message)
            self.assertIn("pre-dive check", answer.message)
            if rospy.get_param("~expect_part").startswith("leg"):
                self.assertIn(rospy.get_param("~expect_part"), answer.message)


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "preflight", PreflightTest, sys.argv)
