#!/usr/bin/env python3
"""rostest: one injection of each fault kind on the running simulated robot meets every target.

The campaign (quadruped_control.ros.fault_campaign) starts its own master and sim.launch in child
processes, so this test node only drives it and judges the summary: no pulse outside its limits, no leg
motion while unarmed, the chip holding or the controller holding within the PWM watchdog timeout plus one
period, tracking again within 5 s of each fault's end (and throughout the faults that do not touch the
control path), no message lost from the bag before a fault but the chunk a killed recorder was writing.
"""
import os
import sys
import tempfile
import unittest

import rostest

from quadruped_control.ros.fault_campaign import (KINDS, RECORDER_CHUNK_MESSAGES, failures, format_table,
                                                  run_campaign)
from quadruped_drivers.hardware_config import load_hardware_config


class FaultCampaignTest(unittest.TestCase):
    def test_one_injection_of_each_kind(self):
        out = os.path.join(os.environ.get("ROS_HOME", tempfile.gettempdir()), "fault_campaign")
        # Shorter seeded pauses than the campaign's 1-4 s between injections: CI's time (the judgement is the same).
        summary = run_campaign(list(KINDS), 1, out, seed=1, pause=(0.3, 1.0))
        print(format_table(summary))
        for kind in KINDS:
            self.assertEqual(summary[kind]["injections"], 1, "%s: %s" % (kind, summary[kind]["errors"]))
        safe_limit = load_hardware_config(None).watchdog_timeout + 0.01
        # A killed recorder loses the chunk it was writing (bounded, docs/faults.md); nothing else may lose any.
        problems = failures(summary, safe_limit, lost_allowed={"kill_recorder": RECORDER_CHUNK_MESSAGES})
        self.assertEqual(problems, [], "\n".join(problems))


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "fault_campaign", FaultCampaignTest, sys.argv)
