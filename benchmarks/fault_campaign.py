"""Fault campaign: the whole robot failing while it moves, on the simulated robot.

    source scripts/env.sh   # or a sourced workspace: roslaunch and the package must be found
    .venv/bin/python benchmarks/fault_campaign.py --per-kind 20 --out out/faults          # every kind
    .venv/bin/python benchmarks/fault_campaign.py --per-kind 3 --kinds imu_link_1 cpu_hogs --out out/f

Runs ``sim.launch`` in real time (the faults are about timing: watchdogs, link timeouts, respawn
delays), armed and in manoeuvres, and injects ``--per-kind`` faults of each kind at seeded random moments
(``quadruped_control/ros/fault_campaign.py`` says how each kind is injected and what the stack must do).
Prints, per kind: injections, time to safe state (max), tracking kept during the fault, time to
recovery (median / max), pulses outside limits on the chip, legs moved while unarmed, and messages lost
from the bag before the fault; writes everything to ``OUT/fault_campaign.json``. Exits 1 if a target of
the targets are missed (each listed). It takes about 2 minutes per kind at 20 injections, more for the long
faults (10 s link loss, CPU hogs) and the master kills (a graph each); run it on a quiet machine.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_control.ros.fault_campaign import KINDS, failures, format_table, run_campaign  # noqa: E402
from quadruped_drivers.hardware_config import load_hardware_config  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--per-kind", type=int, default=20)
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="out/faults")
    args = parser.parse_args()
    hardware = load_hardware_config(None)
    # The target: the chip in its failsafe or the controller holding within the watchdog timeout + one
    # period of the controller (100 Hz).
    safe_limit = hardware.watchdog_timeout + 0.01
    started = time.monotonic()
    summary = run_campaign(args.kinds, args.per_kind, args.out, seed=args.seed)
    print()
    print("Fault campaign: %d per kind, seed %d, %.0f s; details in %s/fault_campaign.json"
          % (args.per_kind, args.seed, time.monotonic() - started, args.out))
    print(format_table(summary))
    problems = failures(summary, safe_limit)
    print()
    print("targets: %s" % ("all met" if not problems else "%d missed" % len(problems)))
    for problem in problems:
        print("  - " + problem)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
