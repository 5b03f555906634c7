"""Benchmark of the offline closed-loop simulator: real-time factor of a 120 s trial.

Run: .venv/bin/python benchmarks/bench_simulation.py [--duration S] [--servo-model ideal|rate-limited]

Prints the real-time factor of one trial (the 45 degree paper-sim trial, simulation gains), the cost of
one 10 ms period split into controller, plant and recording, and the aggregate throughput of the
three paper-sim trials run in two worker processes (the study's setting on this 2-core machine).
"""
import argparse
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.so3 import rpy_to_rot  # noqa: E402
from quadruped_control.control.controller import AttitudeController  # noqa: E402
from quadruped_control.control.controller_config import load_controller_config  # noqa: E402
from quadruped_control.model.params import load_robot_params  # noqa: E402
from quadruped_control.sim.servo_model import make_servo_model  # noqa: E402
from quadruped_control.sim.simulation import ClosedLoopSimulation, PlantSimulator  # noqa: E402


def trial(args):
    amplitude, duration, servo = args
    robot = load_robot_params()
    config = load_controller_config(gain_set="simulation")
    sim = ClosedLoopSimulation(robot, config, make_servo_model(servo), np.eye(3),
                               rpy_to_rot(*np.radians([amplitude] * 3)))
    result = sim.run(duration)
    return result.wall_time, result.metrics()["settled"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=120.0, help="trial length, s (default 120)")
    parser.add_argument("--servo-model", default="ideal", choices=("ideal", "rate-limited"))
    args = parser.parse_args()

    trial((45.0, 1.0, args.servo_model))  # warm-up (imports, caches)
    best = math.inf
    for _ in range(2):
        wall, settled = trial((45.0, args.duration, args.servo_model))
        best = min(best, wall)
    steps = int(round(args.duration / 0.01))
    print("closed loop, 45 deg on roll/pitch/yaw, simulation gains, %s servos, RK4 dt = 0.01 s"
          % args.servo_model)
    print("  %.0f s trial: %.2f s wall, %.1f us per 10 ms period, real-time factor %.0fx (settled: %s)"
          % (args.duration, best, best / steps * 1e6, args.duration / best, settled))

    # Breakdown of one period: controller alone, plant alone (replaying the controller's commands).
    robot = load_robot_params()
    config = load_controller_config(gain_set="simulation")
    sim = ClosedLoopSimulation(robot, config, make_servo_model(args.servo_model), np.eye(3),
                               rpy_to_rot(*np.radians([45.0] * 3)))
    record = sim.run(20.0)
    controller = AttitudeController(robot, config)
    controller.set_setpoint(sim.setpoint_R)
    start = time.perf_counter()
    for k in range(record.t.size):
        controller.step(record.t[k], record.rotation[k], record.omega[k])
    controller_us = (time.perf_counter() - start) / record.t.size * 1e6
    plant = PlantSimulator(robot, make_servo_model(args.servo_model))
    targets = record.joint_targets
    start = time.perf_counter()
    for k in range(targets.shape[0]):
        plant.step(targets[k])
    plant_us = (time.perf_counter() - start) / targets.shape[0] * 1e6
    total_us = record.wall_time / (record.t.size - 1) * 1e6
    print("  per period: controller.step %.1f us, plant.step %.1f us (servo + hold + RK4), "
          "loop/recording %.1f us" % (controller_us, plant_us, max(total_us - controller_us - plant_us, 0.0)))

    # The paper-sim study: three trials on two worker processes.
    jobs = min(2, os.cpu_count() or 1)
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        results = list(pool.map(trial, [(a, args.duration, args.servo_model) for a in (15.0, 45.0, 75.0)]))
    wall = time.perf_counter() - start
    print("  paper-sim study (3 x %.0f s on %d processes): %.1f s wall, aggregate %.0fx real time, settled: %s"
          % (args.duration, jobs, wall, 3 * args.duration / wall, [s for _, s in results]))


if __name__ == "__main__":
    main()
