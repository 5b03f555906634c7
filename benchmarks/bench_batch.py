"""Benchmark of the batched simulator (:mod:`quadruped_control.sim.batch`): real-time factor per core
against the batch size N, and peak memory.

Run: .venv/bin/python benchmarks/bench_batch.py [--plant paper|tank] [--scheme paper|coordinated]
[--sizes 1 15 240 1500] [--duration 180] [--runs 3]

Each N runs in a fresh process (so its peak resident memory is its own): N trials of ``--duration`` s
on the ``--plant`` (tank: config/tank.yaml) with rate-limited servos and the experiment gains, the
``--scheme`` stroke scheme (the paper's runs the compiled controller loop, the coordinated one the
robot's controller objects inside the batch), the setpoints cycling through Table 1's fifteen cases
(16 parameter sets x 15 trials at N = 240: the gains scaled by 0.7 .. 1.3 per set). Prints, per N, the
aggregate real-time factor on one core (simulated seconds of all trials per wall second) as min /
median / max of ``--runs`` runs, the same for the per-trial engine at N = 1 for comparison, and the
peak RSS. Run nothing else beside it (2 shared cores).
"""
import argparse
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.so3 import rpy_to_rot  # noqa: E402
from quadruped_control.control.controller_config import load_controller_config  # noqa: E402
from quadruped_control.model.params import load_robot_params  # noqa: E402
from quadruped_control.sim.batch import BatchSimulation, BatchTrial  # noqa: E402
from quadruped_control.sim.plants import TankModel, load_tank_params  # noqa: E402
from quadruped_control.sim.servo_model import load_servo_params, make_servo_model, tank_servo_params  # noqa: E402
from quadruped_control.sim.simulation import ClosedLoopSimulation  # noqa: E402
from quadruped_control.studies.paper_experiments import PAPER_TABLE, initial_attitude, setpoint_rpy_deg  # noqa: E402


def _trials(n, plant, scheme):
    base = load_controller_config(None, "experiment").replace(stroke_scheme=scheme)
    servo = load_servo_params()
    tank = load_tank_params() if plant == "tank" else None
    if tank is not None:
        servo = tank_servo_params(servo, tank)
    cases = [(setpoint_rpy_deg(row), initial_attitude(setpoint_rpy_deg(row), row["theta_init"], row["psi_init"])[0])
             for row in PAPER_TABLE]
    trials = []
    for i in range(n):
        setpoint, initial = cases[i % len(cases)]
        scale = 0.7 + 0.6 * ((i // len(cases)) % 16) / 15.0
        gains = dataclasses.replace(base.gains, k_p=base.gains.k_p * scale, k_d=base.gains.k_d * scale)
        trials.append(BatchTrial(config=base.with_gains(gains), setpoint=rpy_to_rot(*np.radians(setpoint)),
                                 initial=rpy_to_rot(*np.radians(initial)), servo_model="rate-limited",
                                 servo_params=servo, tank=tank))
    return trials


def one_size(n, duration, runs, plant, scheme):
    robot = load_robot_params()
    factors = []
    for _ in range(runs):
        result = BatchSimulation(robot, _trials(n, plant, scheme)).run(duration)
        factors.append(result.real_time_factor)
    return {"n": n, "factors": factors, "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def per_trial(duration, runs, plant, scheme):
    robot = load_robot_params()
    trial = _trials(1, plant, scheme)[0]
    factors = []
    for _ in range(runs):
        model = TankModel(robot, trial.tank) if trial.tank is not None else None
        sim = ClosedLoopSimulation(robot, trial.config, make_servo_model("rate-limited", trial.servo_params),
                                   initial_R=trial.initial, setpoint_R=trial.setpoint, model=model)
        start = time.perf_counter()
        sim.run(duration)
        factors.append(duration / (time.perf_counter() - start))
    return {"n": 1, "factors": factors, "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plant", choices=("paper", "tank"), default="tank")
    parser.add_argument("--scheme", choices=("paper", "coordinated"), default="paper")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 15, 240, 1500])
    parser.add_argument("--duration", type=float, default=180.0)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--per-trial", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.per_trial:
        print(json.dumps(per_trial(args.duration, args.runs, args.plant, args.scheme)))
        return
    if args.child is not None:
        print(json.dumps(one_size(args.child, args.duration, args.runs, args.plant, args.scheme)))
        return
    print("batched simulator: %s plant, %s strokes, rate-limited servos, experiment gains, %g s trials, %d runs"
          % (args.plant, args.scheme, args.duration, args.runs))
    print("%-18s %28s %14s" % ("engine / N", "real time x per core min/med/max", "peak RSS MiB"))
    rows = [("per-trial, N=1", ["--per-trial"])] + [("batch, N=%d" % n, ["--child", str(n)]) for n in args.sizes]
    for name, extra in rows:
        out = subprocess.run([sys.executable, os.path.abspath(__file__), "--duration", str(args.duration),
                              "--runs", str(args.runs), "--plant", args.plant,
                              "--scheme", args.scheme] + extra, check=True, capture_output=True, text=True)
        row = json.loads(out.stdout.strip().splitlines()[-1])
        f = row["factors"]
        print("%-18s %9.0f / %6.0f / %6.0f %14.0f" % (name, min(f), statistics.median(f), max(f), row["peak_rss_mib"]))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
