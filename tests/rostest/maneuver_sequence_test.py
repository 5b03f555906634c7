#!/usr/bin/env python3
"""rostest: the maneuver node's sequence reaches the controller, each setpoint for as long as it is held.

Listens to /controller_state (the setpoint the controller steers to, every control step, stamped in simulated
time). Passes when the setpoint goes from level to roll 10 deg for 4 s and then to pitch 5 deg, never to
anything else (the bad sequence's node published nothing), and both maneuver nodes have ended: the good one
after its last hold, the bad one at once. During the roll hold the test disarms the controller for a second and
arms it again: the sequence keeps its schedule, and the maneuver node logs the stop and the return (/rosout).

Before that disarm the test raises K_p live (as rqt_reconfigure does); at the end it keeps it with ~save_gains
(the file loads; the same set again and the shipped controller.yaml are refused). The gains in force are on the
latched parameter_updates from the start; the stack's bag (~bag_dir), read by the bag report, holds four trials
(level, roll, roll again after the re-arm, pitch), each with the gains in force, the live change in the second.
"""
import glob
import math
import os
import sys
import threading
import unittest

import numpy as np
import rosnode
import rospy
import rostest
from dynamic_reconfigure.client import Client as ReconfigureClient
from dynamic_reconfigure.msg import Config
from rosgraph_msgs.msg import Log
from std_srvs.srv import SetBool

from quadruped_common.config import config_path
from quadruped_common.so3 import quat_to_rot, rot_to_rpy
from quadruped_control.analysis.bag_report import analyse_trials, read_bags
from quadruped_control.control.controller_config import load_controller_config
from underwater_quadruped.msg import ControllerState
from underwater_quadruped.srv import SaveGains

LEVEL, ROLL_10, PITCH_5 = (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (0.0, 5.0, 0.0)


class ManeuverSequenceTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("maneuver_sequence_test", anonymous=True)
        self.lock = threading.Lock()
        self.changes = []  # (stamp s, setpoint rpy deg) at each change of the setpoint
        self.maneuver_log = []  # what /maneuver logged
        self.k_p = []  # K_p of each /attitude_controller/parameter_updates
        rospy.Subscriber("controller_state", ControllerState, self.on_state, queue_size=100)
        rospy.Subscriber("/attitude_controller/parameter_updates", Config, self.on_gains, queue_size=10)
        rospy.Subscriber("/rosout", Log, self.on_log, queue_size=100)

    def on_log(self, msg):
        if msg.name == "/maneuver":
            with self.lock:
                self.maneuver_log.append((msg.level, msg.msg))

    def on_gains(self, msg):
        with self.lock:
            self.k_p.append(next(p.value for p in msg.doubles if p.name == "k_p"))

    def check_gains_and_bag(self):
        """~save_gains to a new file, then the same set again and to the shipped file; the gains on
        parameter_updates; the bag's trials and their gains."""
        save = rospy.ServiceProxy("/attitude_controller/save_gains", SaveGains)
        path = os.path.join(rospy.get_param("~bag_dir"), "gains", "tuned.yaml")
        new, again, shipped = [save(path, "tuned", False), save(path, "tuned", False),
                               save(config_path("controller.yaml"), "tuned", False)]
        self.assertTrue(new.success, new.message)
        self.assertEqual(load_controller_config(path, "tuned").gains.k_p, 7.0)
        self.assertFalse(again.success or shipped.success, (again.message, shipped.message))
        self.assertIn("already has a gain set 'tuned'", again.message)
        self.assertIn("is the shipped configuration", shipped.message)
        with self.lock:
            self.assertEqual((self.k_p[0], self.k_p[-1]), (5.0, 7.0), "parameter_updates: K_p %r" % self.k_p)
        bags = glob.glob(os.path.join(rospy.get_param("~bag_dir"), "*.bag*"))  # .active: still recording
        trials = analyse_trials(read_bags(bags))["trials"]
        rpy = [tuple(round(a, 1) + 0.0 for a in t["setpoint_rpy_deg"]) for t in trials]
        self.assertEqual(rpy, [LEVEL, ROLL_10, ROLL_10, PITCH_5], "trials %r" % trials)
        self.assertEqual([t["gains"]["k_p"] for t in trials], [5.0, 5.0, 7.0, 7.0])
        self.assertEqual([c["changes"] for c in trials[1]["gain_changes"]], [{"k_p": [5.0, 7.0]}])
        self.assertTrue(all(t["metrics"] for t in trials), "a trial too short to measure: %r" % trials)

    def on_state(self, msg):
        s = msg.setpoint
        rpy = tuple(round(math.degrees(a), 3) for a in rot_to_rpy(quat_to_rot(np.array([s.x, s.y, s.z, s.w]))))
        with self.lock:
            if not self.changes or self.changes[-1][1] != rpy:
                self.changes.append((msg.header.stamp.to_sec(), rpy))

    def test_each_setpoint_is_held_as_long_as_the_sequence_says_and_the_nodes_end(self):
        deadline = rospy.Time.now() + rospy.Duration(120.0)
        interrupted = False
        while not rospy.is_shutdown() and rospy.Time.now() < deadline:
            with self.lock:
                done = [rpy for _, rpy in self.changes] == [LEVEL, ROLL_10, PITCH_5]
                rolling = [rpy for _, rpy in self.changes] == [LEVEL, ROLL_10]
            if rolling and not interrupted:
                interrupted = True
                # K_p 5 (the simulation set) -> 7, as rqt_reconfigure does: a change during the roll's trial
                ReconfigureClient("/attitude_controller", timeout=10.0).update_configuration({"k_p": 7.0})
                rospy.sleep(0.3)  # recorded well inside that trial, which then lasts long enough to measure
                arm = rospy.ServiceProxy("/attitude_controller/arm", SetBool)
                rospy.wait_for_service("/attitude_controller/arm", timeout=10.0)
                arm(False)
                rospy.sleep(1.0)
                arm(True)
            nodes = rosnode.get_node_names()
            if done and "/maneuver" not in nodes and "/maneuver_bad" not in nodes:
                break
            rospy.sleep(0.5)
        with self.lock:
            changes = list(self.changes)
        self.assertEqual([rpy for _, rpy in changes], [LEVEL, ROLL_10, PITCH_5],
                         "the controller's setpoints were %r" % (changes,))
        held = changes[2][0] - changes[1][0]
        self.assertAlmostEqual(held, 4.0, delta=0.25, msg="roll 10 deg held %.2f s, not 4" % held)
        nodes = rosnode.get_node_names()
        self.assertNotIn("/maneuver", nodes, "the maneuver node did not end after its sequence")
        self.assertNotIn("/maneuver_bad", nodes, "the maneuver node given a bad sequence did not end")
        self.assertTrue(interrupted, "the roll hold was never seen, so the controller was never disarmed")
        with self.lock:
            log = list(self.maneuver_log)
        warnings = [text for level, text in log if level == Log.WARN]
        self.assertTrue(any("stopped acting during setpoint 1 (disarmed)" in text for text in warnings),
                        "the maneuver node did not warn of the disarm: %r" % (log,))
        # (during setpoint 1 unless the simulated clock ran past its 4 s while the test called the service)
        self.assertTrue(any("acts again during setpoint" in text for _, text in log),
                        "the maneuver node did not log the controller's return: %r" % (log,))
        self.check_gains_and_bag()


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "maneuver_sequence", ManeuverSequenceTest, sys.argv)
