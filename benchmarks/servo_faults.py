"""Seeded trials of the servo faults a robot can be built with, the configuration not knowing them.

Default: the servo tracking watch. Per trial a simulated robot with two faulty servos (one reversed, one stuck, on
joints of two legs drawn from the seed), armed towards a 30 deg roll (tests/rostest/servo_tracking.test); prints
when each was named after arming, and whether a healthy joint was named, then min / median / max per fault.

``--slow``: the pre-dive check's speed check. Per trial a robot with one servo at ``--scale`` (0.5) of its speed on a
joint drawn from the seed, the whole pre-dive check then an arm (tests/rostest/preflight.test, lock-step;
``--wall-clock``: on the wall clock, as on the robot); prints whether it was named (and arming refused naming it),
its measured speed fraction and the slowest healthy joint's, then min / median / max of both. A slowed servo tracks
the slow moves of a hold and lags only in the fast ones, so the armed watch cannot be relied on to name it.

    source scripts/env.sh
    python benchmarks/servo_faults.py --trials 20 --seed 0          (about 20 s a trial; on a quiet machine)
    python benchmarks/servo_faults.py --slow --trials 20 --seed 0   (about 80 s a trial)
"""
import argparse
import glob
import json
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


def slow_trial(number: int, seed: int, scale: float, lockstep: bool, out: str):
    """One pre-dive check rostest with a slowed servo: (joint, its speed fraction or None, slowest healthy joint's
    (name, fraction), named and arming refused: the rostest passed)."""
    joint = random.Random(seed * 1000 + number).choice(JOINT_NAMES)
    home = os.path.join(out, "slow%02d" % number)
    run = subprocess.run(["rostest", "--text", "underwater_quadruped", "preflight.test",
                          "hardware_faults:={servo_speed_scale: {%s: %g}}" % (joint, scale), "expect_pass:=false",
                          "expect_failed:=servo speed", "expect_part:=" + joint,
                          "lockstep:=" + ("true" if lockstep else "false")],
                         env=dict(os.environ, ROS_HOME=home), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         universal_newlines=True)
    fractions = {}
    for path in glob.glob(os.path.join(home, "preflight_preflight", "preflight_*.json")):
        with open(path, encoding="utf-8") as f:
            for check in json.load(f)["checks"]:
                if check["name"] == "servo speed":
                    fractions = check["figures"].get("speed_fraction", {})
    healthy = {name: value for name, value in fractions.items() if name != joint}
    slowest = min(healthy.items(), key=lambda item: item[1]) if healthy else (None, None)
    ok = run.returncode == 0 and "\nOK" in run.stdout
    return joint, fractions.get(joint), slowest, ok


def main_slow(args) -> int:
    out = tempfile.mkdtemp(prefix="uq_slow_servo.")
    faulty, healthy, missed = [], [], 0
    for number in range(args.trials):
        joint, fraction, (other, other_fraction), ok = slow_trial(number, args.seed, args.scale, not args.wall_clock,
                                                                  out)
        missed += not ok
        if fraction is not None:
            faulty.append(fraction)
        if other_fraction is not None:
            healthy.append(other_fraction)
        print("trial %2d: %s at %.2f of its speed: %s, measured %s; slowest healthy joint %s %s" % (
            number, joint, args.scale, "named, arming refused" if ok else "NOT NAMED (or the rostest failed)",
            "%.2f" % fraction if fraction is not None else "-", other,
            "%.2f" % other_fraction if other_fraction is not None else "-"), flush=True)
    for label, values in (("slowed joint", faulty), ("slowest healthy joint", healthy)):
        if values:
            print("%-22s speed fraction: min %.2f / median %.2f / max %.2f" % (
                label, min(values), statistics.median(values), max(values)))
    print("%d trials (seed %d, %s): %d not named; logs in %s" % (
        args.trials, args.seed, "wall clock" if args.wall_clock else "lock-step", missed, out))
    return 0 if missed == 0 else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--slow", action="store_true", help="a slowed servo and the pre-dive check")
    parser.add_argument("--scale", type=float, default=0.5, help="--slow: the servo's fraction of its speed")
    parser.add_argument("--wall-clock", action="store_true", help="--slow: the simulation on the wall clock")
    args = parser.parse_args()
    if args.slow:
        return main_slow(args)
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
