"""Seeded trials of the servo tracking watch: per trial, a simulated robot built with two faulty servos the
configuration does not know (one reversed, one stuck, on joints of two legs drawn from the seed), armed towards a
30 deg roll (tests/rostest/servo_tracking.test); prints when each was named after arming, and whether a healthy
joint was named, then min / median / max per fault. (A half-speed servo is not yet found reliably: docs/faults.md.)

    source scripts/env.sh
    python benchmarks/servo_faults.py --trials 20 --seed 0     (about 20 s a trial; on a quiet machine)
"""
import argparse
import os
import random
import re
import statistics
import subprocess
import sys
import tempfile

from quadruped_common.robot import JOINT_NAMES

FAULTS = ("servo_reversed", "servo_stuck")


def trial(number: int, seed: int, out: str):
    """One rostest run; returns ({fault: seconds to named, or None}, healthy joints named, passed)."""
    rng = random.Random(seed * 1000 + number)
    first = rng.choice(JOINT_NAMES)
    joints = [first, rng.choice([name for name in JOINT_NAMES if name[:4] != first[:4]])]  # one fault per leg
    faults = "{servo_reversed: [%s], servo_stuck: [%s]}" % tuple(joints)
    env = dict(os.environ, ROS_HOME=os.path.join(out, "trial%02d" % number))
    run = subprocess.run(["rostest", "--text", "underwater_quadruped", "servo_tracking.test", "faults:=" + faults,
                          "faulty:=" + " ".join(joints)], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, universal_newlines=True)
    named = {}
    for fault, joint in zip(FAULTS, joints):
        found = re.search(r"^%s: named ([0-9.]+) s after arming" % joint, run.stdout, re.M)
        named[fault] = (joint, float(found.group(1)) if found else None)
    healthy = "healthy joints named" in run.stdout
    return named, healthy, run.returncode == 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    out = tempfile.mkdtemp(prefix="uq_servo_faults.")
    times = {fault: [] for fault in FAULTS}
    missed, false_reports, failed = 0, 0, 0
    for number in range(args.trials):
        named, healthy, passed = trial(number, args.seed, out)
        cells = []
        for fault, (joint, seconds) in named.items():
            cells.append("%s %s %s" % (fault, joint, "%.2f s" % seconds if seconds is not None else "NOT named"))
            if seconds is None:
                missed += 1
            else:
                times[fault].append(seconds)
        false_reports += healthy
        failed += not passed
        print("trial %2d: %s%s" % (number, "; ".join(cells), "; HEALTHY JOINT NAMED" if healthy else ""), flush=True)
    for fault, values in times.items():
        if values:
            print("%-18s named in %d of %d: min %.2f / median %.2f / max %.2f s after arming"
                  % (fault, len(values), args.trials, min(values), statistics.median(values), max(values)))
    print("%d trials (seed %d): %d faults not named, %d trials naming a healthy joint, %d rostests failed; logs in %s"
          % (args.trials, args.seed, missed, false_reports, failed, out))
    return 0 if missed == 0 and false_reports == 0 and failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
