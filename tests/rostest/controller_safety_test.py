#!/usr/bin/env python3
"""rostest: safety behaviour of the attitude controller node, with IMU samples from this test.

Sequence: unarmed -> no servo_command at all; arming refused, with the reasons in the answer and in the
"arming" diagnostic, while the joints and pwm_node's outputs_state are missing; with them (published by this
test: the legs at the nominal pose, the outputs ready) armed with a good IMU -> stroking; NaN quaternion ->
safe pose (targets frozen), hold reason and an ERROR diagnostic; good again -> stroking resumes;
non-unit quaternion -> hold; IMU silent -> stale hold from the fallback timer, node still alive;
disarmed -> servo commands stop.
"""
import math
import sys
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import Imu
from std_srvs.srv import SetBool

from driver_stand_ins import DriverStandIns
from underwater_quadruped.msg import ControllerState, ServoCommand


class ControllerSafetyTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("controller_safety_test", anonymous=True)

    def setUp(self):
        self.lock = threading.Lock()
        self.mode = "good"
        self.commands = []
        self.states = []
        self.diagnostics = []
        self.imu_pub = rospy.Publisher("imu/data", Imu, queue_size=10)
        self.stand_ins = DriverStandIns()  # started once the refusal without them is seen
        rospy.Subscriber("servo_command", ServoCommand, self.on_command, queue_size=200)
        rospy.Subscriber("controller_state", ControllerState, self.on_state, queue_size=200)
        rospy.Subscriber("diagnostics", DiagnosticArray, self.on_diagnostics, queue_size=50)
        self.stop = threading.Event()
        self.publisher_thread = threading.Thread(target=self.publish_imu, daemon=True)
        self.publisher_thread.start()
        rospy.wait_for_service("attitude_controller/arm", timeout=60.0)
        self.arm = rospy.ServiceProxy("attitude_controller/arm", SetBool)

    def tearDown(self):
        self.stop.set()
        self.stand_ins.stop()

    def publish_imu(self):
        rate = rospy.Rate(200)
        while not self.stop.is_set() and not rospy.is_shutdown():
            mode = self.mode
            if mode != "silent":
                msg = Imu()
                msg.header.stamp = rospy.Time.now()
                msg.header.frame_id = "imu_link"
                msg.orientation.w = {"good": 1.0, "nan": float("nan"), "nonunit": 0.5}[mode]
                self.imu_pub.publish(msg)
            rate.sleep()

    def on_command(self, msg):
        with self.lock:
            self.commands.append((time.monotonic(), np.array(msg.joint_target), np.array(msg.pulse_width_us)))

    def on_state(self, msg):
        with self.lock:
            self.states.append((time.monotonic(), msg))

    def on_diagnostics(self, msg):
        with self.lock:
            for status in msg.status:
                if status.name.startswith("attitude_controller"):
                    self.diagnostics.append((time.monotonic(), status))

    def window(self, seconds):
        """Let ``seconds`` pass and return the commands, states and diagnostics received meanwhile."""
        start = time.monotonic()
        rospy.sleep(seconds)
        with self.lock:
            pick = lambda items: [item for item in items if item[0] >= start]  # noqa: E731
            return pick(self.commands), pick(self.states), pick(self.diagnostics)

    def assert_holding(self, states, commands, reason_part):
        # The feet retrace to the nominal pose over t_rec (1.5 s); judge the last third of the window.
        late = [s for t, s in states[2 * len(states) // 3:]]
        self.assertTrue(late, "no controller_state while holding")
        self.assertTrue(all(s.holding for s in late), "controller not holding the safe pose")
        self.assertTrue(all(reason_part in s.hold_reason for s in late),
                        "hold reason %r lacks %r" % (late[-1].hold_reason, reason_part))
        targets = [c[1] for c in commands[2 * len(commands) // 3:]]
        self.assertTrue(targets, "the safe pose must still be commanded while armed")
        spread = np.max(np.ptp(np.array(targets), axis=0))
        self.assertLess(spread, 1e-6, "joint targets moved while holding (stroking?)")

    def test_safety_sequence(self):
        # 1. Unarmed: no servo command at all, state says disarmed.
        commands, states, _ = self.window(1.5)
        self.assertEqual(commands, [], "servo commands while unarmed")
        self.assertTrue(states and all(not s.armed for _, s in states))

        # 2. Without joint feedback and pwm_node's outputs_state, arming is refused with both reasons.
        answer = self.arm(True)
        self.assertFalse(answer.success)
        self.assertIn("joints: no joint feedback received yet", answer.message)
        self.assertIn("outputs: no outputs_state from pwm_node yet", answer.message)
        self.assertNotIn("imu:", answer.message)
        _, _, diagnostics = self.window(2.5)
        arming = [d for _, d in diagnostics if d.name.endswith("arming")]
        self.assertTrue(arming and arming[-1].level == DiagnosticStatus.WARN
                        and "joints: " in arming[-1].message and "outputs: " in arming[-1].message,
                        "no arming diagnostic naming the reasons: %r" % (arming[-1:],))
        self.stand_ins.start()
        rospy.sleep(0.5)

        # 3. Armed with a good IMU (level body, 30 deg roll setpoint): the legs stroke.
        self.assertTrue(self.arm(True).success)
        commands, states, _ = self.window(3.0)
        self.assertGreater(len(commands), 200, "expected ~100 Hz servo commands when armed")
        self.assertTrue(all(not s.holding for _, s in states[5:]), "holding with a good IMU")
        targets = np.array([c[1] for c in commands])
        self.assertGreater(np.max(np.ptp(targets, axis=0)), math.radians(5.0), "no stroking when armed")
        self.assertTrue(any(1 in s.pair_phase for _, s in states), "no power stroke seen")

        # 4. NaN quaternion: safe pose, reason, ERROR diagnostic, node alive.
        self.mode = "nan"
        commands, states, diagnostics = self.window(3.5)
        self.assert_holding(states, commands, "non-finite")
        self.assertTrue(any(d.level == DiagnosticStatus.ERROR and "non-finite" in d.message
                            for _, d in diagnostics), "no ERROR diagnostic for the NaN IMU")

        # 5. Good again: stroking resumes.
        self.mode = "good"
        commands, states, _ = self.window(2.5)
        self.assertTrue(all(not s.holding for _, s in states[len(states) // 2:]), "did not resume")

        # 6. Non-unit quaternion: hold.
        self.mode = "nonunit"
        commands, states, _ = self.window(3.5)
        self.assert_holding(states, commands, "quaternion norm")

        # 7. IMU silent (after good samples): the fallback timer keeps the node ticking and holding.
        self.mode = "good"
        rospy.sleep(1.0)
        self.mode = "silent"
        commands, states, diagnostics = self.window(3.5)
        self.assert_holding(states, commands, "stale")
        self.assertGreater(len(states), 100, "controller stopped ticking without IMU samples")

        # 8. Disarm: no more servo commands.
        self.mode = "good"
        self.assertTrue(self.arm(False).success)
        rospy.sleep(0.2)
        commands, states, _ = self.window(1.0)
        self.assertEqual(commands, [], "servo commands after disarming")

    def test_reconfigure_validates_and_applies(self):
        """Live gains through dynamic_reconfigure: a valid update is applied and echoed; an update
        that breaks t_rec >= 2 t_pow_max is refused as a whole and the old values come back."""
        from dynamic_reconfigure.client import Client
        client = Client("attitude_controller", timeout=30.0)
        start = client.get_configuration(timeout=10.0)
        self.assertAlmostEqual(start["k_p"], 5.0)  # the simulation gain set seeded the server
        applied = client.update_configuration({"k_p": 7.5, "t_rec": 2.0})
        self.assertAlmostEqual(applied["k_p"], 7.5)
        self.assertAlmostEqual(applied["t_rec"], 2.0)
        refused = client.update_configuration({"k_p": 9.0, "t_rec": 0.6, "t_pow_max": 0.5})
        self.assertAlmostEqual(refused["k_p"], 7.5)
        self.assertAlmostEqual(refused["t_rec"], 2.0)
        self.assertAlmostEqual(refused["t_pow_max"], 0.5)
        restored = client.update_configuration({"k_p": start["k_p"], "t_rec": start["t_rec"]})
        self.assertAlmostEqual(restored["t_rec"], start["t_rec"])


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "controller_safety", ControllerSafetyTest, sys.argv)
