#!/usr/bin/env python3
"""rostest: a simulated day in the tank runs end to end and every study reads its folder as the day left it.

Waits for the tank_day node's last prompt ("The day is done"), then quiets the simulated robot (its IMU off: the
lock-step clock then runs at real time, and the studies get the cores). Checks the folder: the plan, one folder per
run in the plan's order, each complete with its bag and run.yaml (gains, configuration files and their hashes, the
code's version, the legs, the run's events, the day's notes), t_rec 1.0 s in force in the pitch-75 runs' bags. Then
runs each study's command line on the folder (hang, step_test, identify_bags, table1_bags) and checks it read what it
needs: the hang run, the step test's eleven steps with the gains of its bag, the first repeat fitted and the second
held out, and Table 1's pitch 75 twice.
"""
import glob
import json
import os
import subprocess
import sys
import threading
import unittest

import rospy
import rostest
import yaml
from std_msgs.msg import String
from std_srvs.srv import SetBool

from quadruped_common.config import config_path
from quadruped_control.analysis.bag_report import gains_in_force, read_bags

RUNS = ["01_hang", "02_tether", "03_step_test", "04_table1_pitch_75_r1", "05_table1_pitch_75_r2"]


class TankDayTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("tank_day_test", anonymous=True)
        self.day = rospy.get_param("~day_dir")
        self.prompts = []
        self.lock = threading.Lock()
        rospy.Subscriber("/tank_day/prompt", String, self.on_prompt, queue_size=50)

    def on_prompt(self, msg):
        with self.lock:
            self.prompts.append(msg.data)

    def study(self, module, *args):
        out = os.path.join(self.day, "studies", module)
        done = subprocess.run([sys.executable, "-m", "quadruped_control.studies." + module] + list(args)
                              + ["--out", out], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              universal_newlines=True, timeout=300)
        self.assertEqual(done.returncode, 0, "%s on the day's folder:\n%s" % (module, done.stdout[-3000:]))
        self.assertNotIn("missing:", done.stdout, "%s found something missing:\n%s" % (module, done.stdout))
        with open(os.path.join(out, module + ".json")) as stream:
            return json.load(stream)

    def test_the_day_runs_end_to_end_and_every_study_reads_its_folder(self):
        deadline = rospy.get_time() + 400.0
        while not rospy.is_shutdown():
            with self.lock:
                if self.prompts and self.prompts[-1].startswith("The day is done"):
                    break
            self.assertLess(rospy.get_time(), deadline, "the day did not end; prompts: %r" % self.prompts)
            rospy.sleep(1.0)
        rospy.wait_for_service("/sim_node/imu_streaming", 10.0)
        rospy.ServiceProxy("/sim_node/imu_streaming", SetBool)(False)
        with self.lock:
            prompts = list(self.prompts)
        self.assertEqual([p.split(":")[0] for p in prompts if p[:2].isdigit()],
                         ["01_hang", "02_tether", "02_tether, held", "02_tether, released", "03_step_test",
                          "04_table1_pitch_75_r1", "05_table1_pitch_75_r2"])

        with open(os.path.join(self.day, "plan.yaml")) as stream:
            plan = yaml.safe_load(stream)
        self.assertEqual([run["run"] for run in plan["runs"]], RUNS)
        self.assertEqual(sorted(os.path.basename(p) for p in glob.glob(os.path.join(self.day, "0*"))), RUNS)
        for name in RUNS:
            with open(os.path.join(self.day, name, "run.yaml")) as stream:
                record = yaml.safe_load(stream)
            self.assertEqual((record["run"], record["status"], record["day_notes"]),
                             (name, "complete", "rostest tank_day"))
            self.assertEqual(record["gains"]["at_start"]["k_p"], 10.0)  # the experiment gain set
            if "table1" in name:
                self.assertEqual(record["gains"]["at_arming"]["t_rec"], 1.0)
            self.assertEqual(record["config"]["/attitude_controller/controller_yaml"]["path"],
                             config_path("controller.yaml"))
            self.assertEqual(len(record["config"]["/sim_node/tank_yaml"]["sha256"]), 64)
            self.assertTrue(record["code"].startswith(("git ", "package ")), record["code"])
            self.assertEqual(len(record["legs_rad"]["at_end"]), 12)
            self.assertGreater(record["end"]["ros_time"], record["start"]["ros_time"])
            self.assertTrue(glob.glob(os.path.join(self.day, name, "uq_*.bag")), "%s has no bag" % name)
        with open(os.path.join(self.day, "02_tether", "run.yaml")) as stream:
            events = [e["what"] for e in yaml.safe_load(stream)["events"]]
        self.assertEqual(events, ["free", "held", "released"])
        for name in RUNS[3:]:
            data = read_bags(glob.glob(os.path.join(self.day, name, "uq_*.bag")))
            armed = [t for t, a in zip(data.state_t, data.state_armed) if a]
            self.assertEqual(gains_in_force(data, min(armed), max(armed))["gains"]["t_rec"], 1.0)

        hang = self.study("hang", self.day, "--skip", "0", "--compare", config_path("tank.yaml"))
        self.assertIn("01_hang", hang["source"])
        self.assertEqual(hang["missing"], [])
        step = self.study("step_test", self.day, "--compare", config_path("tank.yaml"))
        self.assertEqual(len(step["steps"]), 11)
        self.assertEqual((step["gains_source"], step["gains"]["k_p"]), ("the bag's parameter_updates", 10.0))
        fit = self.study("identify_bags", self.day, "--parameters", "center_of_buoyancy_z", "net_weight",
                         "--window", "2", "--stride", "4", "--lead-in", "1", "--evaluations", "4", "--popsize", "2")
        self.assertEqual([run["source"].split("/")[-2] for run in fit["training"]["runs"]],
                         ["03_step_test", "04_table1_pitch_75_r1"])
        self.assertEqual([run["source"].split("/")[-2] for run in fit["held_out"]["runs"]], ["05_table1_pitch_75_r2"])
        table = self.study("table1_bags", self.day)
        self.assertEqual([(row["case"], row["runs"]) for row in table["rows"]],
                         [("pitch 75", ["04_table1_pitch_75_r1", "05_table1_pitch_75_r2"])])
        self.assertEqual([t["repeat"] for t in table["repeats"]], [1, 2])
        self.assertAlmostEqual(table["runs"][0]["initial_rpy_deg"][2], -43.40, delta=0.5)  # Table 1's psi_init


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "tank_day", TankDayTest, sys.argv)
