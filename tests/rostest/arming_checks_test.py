#!/usr/bin/env python3
"""rostest: every arming precondition refused on its own, with its reason (arming_checks.test).

The test is the laptop (tether/heartbeat at 5 Hz) and the pre-dive check (preflight/result, latched). Per trial, in
an order drawn from ~seed, each check is broken alone through the simulated robot or the graph:

  imu             the fake VN-100 silent (/sim_node/imu_streaming false)
  joints          servo_feedback_node frozen (SIGSTOP)
  outputs         the PWM outputs disabled (/pwm_node/enable false)
  e-stop          the e-stop latched (/estop true; it switches the outputs off too: "outputs" may be named beside it)
  depth           the MS5837 off the bus (/sim_node/depth_sensor_fault true) until health/depth ERROR
  battery         both packs flat (/sim_node/battery_flat true) until health/battery ERROR
  leak            water on the probe (/sim_node/water_inside true) until health/leak ERROR
  tether          the heartbeat stopped for longer than its 2 s timeout
  pre-dive check  a failed pre-dive check published

then an arm must be refused naming that check and no other; the check is restored and an arm must be accepted
(then disarmed). Prints each refusal.
"""
import os
import random
import signal
import sys
import threading
import time
import unittest
import xmlrpc.client

import rosgraph
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from std_msgs.msg import Header
from std_srvs.srv import SetBool, Trigger

ARM = "/attitude_controller/arm"
CHECKS = ("imu", "joints", "outputs", "e-stop", "depth", "battery", "leak", "tether", "pre-dive check")
#: A check named with another that it implies (the e-stop switches the outputs off).
ALSO = {"e-stop": {"outputs"}}


def node_pid(name):
    uri = rosgraph.Master("/arming_checks_test").lookupNode(name)
    return int(xmlrpc.client.ServerProxy(uri).getPid("/arming_checks_test")[2])


class ArmingChecksTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("arming_checks_test", anonymous=True)
        self.beating = threading.Event()
        self.beating.set()
        self.heartbeat = rospy.Publisher("tether/heartbeat", Header, queue_size=1)
        self.preflight = rospy.Publisher("preflight/result", DiagnosticStatus, queue_size=1, latch=True)
        self.preflight.publish(DiagnosticStatus(level=DiagnosticStatus.OK, name="pre-dive check", message="passed"))
        self.lock = threading.Lock()
        self.health = {}  # source -> (arrival, level)
        for source in ("depth", "battery", "leak"):
            rospy.Subscriber("health/" + source, DiagnosticStatus, self.on_health, callback_args=source)
        threading.Thread(target=self.beat, daemon=True).start()
        rospy.wait_for_service(ARM, timeout=60.0)
        self.arm = rospy.ServiceProxy(ARM, SetBool)

    def beat(self):
        while not rospy.is_shutdown():
            if self.beating.is_set():
                self.heartbeat.publish(Header(stamp=rospy.Time.now()))
            time.sleep(0.2)

    def on_health(self, msg, source):
        with self.lock:
            self.health[source] = (time.monotonic(), msg.level)

    def wait_health(self, source, level, since, timeout=10.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                arrival, got = self.health.get(source, (0.0, -1))
            if arrival > since and got == level:
                return
            time.sleep(0.02)
        self.fail("no health/%s at level %d within %.0f s" % (source, level, timeout))

    def set_bool(self, service, value):
        rospy.wait_for_service(service, timeout=10.0)
        answer = rospy.ServiceProxy(service, SetBool)(value)
        self.assertTrue(answer.success, "%s(%s): %s" % (service, value, answer.message))

    def arm_when_ready(self, timeout=15.0):
        deadline = time.monotonic() + timeout
        while True:
            answer = self.arm(True)
            if answer.success:
                self.arm(False)
                return
            self.assertLess(time.monotonic(), deadline, "arming refused with every check restored: %s"
                            % answer.message)
            time.sleep(0.2)

    def break_check(self, check):
        """Break ``check`` alone and wait until the stack can know; returns how to restore it."""
        start = time.monotonic()
        if check == "imu":
            self.set_bool("/sim_node/imu_streaming", False)
            time.sleep(0.3)
            return lambda: self.set_bool("/sim_node/imu_streaming", True)
        if check == "joints":
            pid = node_pid("/servo_feedback_node")
            os.kill(pid, signal.SIGSTOP)
            time.sleep(0.4)
            return lambda: os.kill(pid, signal.SIGCONT)
        if check == "outputs":
            self.set_bool("/pwm_node/enable", False)
            time.sleep(0.5)
            return lambda: self.set_bool("/pwm_node/enable", True)
        if check == "e-stop":
            self.set_bool("/estop", True)
            time.sleep(0.3)
            return lambda: (self.set_bool("/estop", False), self.set_bool("/pwm_node/enable", True))
        if check == "tether":
            self.beating.clear()
            time.sleep(2.4)
            return self.beating.set
        if check == "pre-dive check":
            self.preflight.publish(DiagnosticStatus(level=DiagnosticStatus.ERROR, name="pre-dive check",
                                                    message="leg2_hip: no motion"))
            time.sleep(0.2)
            return lambda: self.preflight.publish(DiagnosticStatus(level=DiagnosticStatus.OK, name="pre-dive check",
                                                                   message="passed"))
        service = {"depth": "/sim_node/depth_sensor_fault", "battery": "/sim_node/battery_flat",
                   "leak": "/sim_node/water_inside"}[check]
        self.set_bool(service, True)
        self.wait_health(check, DiagnosticStatus.ERROR, start)
        time.sleep(0.1)

        def restore():
            cleared = time.monotonic()
            self.set_bool(service, False)
            if check == "leak":
                time.sleep(0.4)  # dry readings first: the report is latched until the reset
                answer = rospy.ServiceProxy("/leak_node/reset", Trigger)()
                self.assertTrue(answer.success, answer.message)
            self.wait_health(check, DiagnosticStatus.OK, cleared)
        return restore

    def test_each_check_refused_on_its_own(self):
        trials, seed = int(rospy.get_param("~trials", 1)), int(rospy.get_param("~seed", 1))
        rng = random.Random(seed)
        self.arm_when_ready(60.0)
        refusals = 0
        for trial in range(trials):
            for check in rng.sample(CHECKS, len(CHECKS)):
                restore = self.break_check(check)
                answer = None
                try:
                    answer = self.arm(True)
                finally:
                    if answer is not None and answer.success:
                        self.arm(False)
                    restore()
                named = {name for name in CHECKS if name + ": " in answer.message}
                print("trial %d, %s: %s" % (trial, check, answer.message if not answer.success else "ACCEPTED"))
                self.assertFalse(answer.success, "%s broken, yet arming was accepted" % check)
                self.assertIn(check, named, answer.message)
                self.assertEqual(named - {check} - ALSO.get(check, set()), set(), answer.message)
                refusals += 1
                self.arm_when_ready()
        print("%d trials: %d refusals, each naming its check alone" % (trials, refusals))


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "arming_checks", ArmingChecksTest, sys.argv)
