"""Benchmark of the attitude controller: time per AttitudeController.step in a realistic closed loop.

Run: .venv/bin/python benchmarks/bench_controller.py [--steps N] [--gain-set simulation|experiment]

The controller runs against the paper's floating-base model (RK4, dt = 0.01 s) tracking a sequence of
roll/pitch/yaw setpoints, so the steps include every phase (power starts with allocation, Euler
integration with IK failures, recoveries with arc-length retrace) and IK for all four legs. Only the
controller step is timed. Target: p99 < 0.5 ms per step.
"""
import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.robot import LEGS
from quadruped_common.so3 import rpy_to_rot  # noqa: E402
from quadruped_control.control.controller import AttitudeController  # noqa: E402
from quadruped_control.control.controller_config import load_controller_config  # noqa: E402
from quadruped_control.model.kinematics import joint_angles  # noqa: E402
from quadruped_control.model.params import load_robot_params  # noqa: E402
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState, held_joint_input  # noqa: E402

DT = 0.01


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="closed-loop steps (default 20000 = 200 s)")
    parser.add_argument("--gain-set", default="simulation")
    parser.add_argument("--scheme", default=None, help="stroke scheme (default: config/controller.yaml's)")
    args = parser.parse_args()

    params = load_robot_params()
    model = FloatingBaseModel(params)
    config = load_controller_config(gain_set=args.gain_set)
    if args.scheme:
        config = config.replace(stroke_scheme=args.scheme)
    controller = AttitudeController(params, config)
    state = RigidBodyState(rotation=rpy_to_rot(math.radians(30.0), 0.0, 0.0))
    q_previous = np.array([joint_angles(params.nominal_foot_body(leg), leg, params) for leg in LEGS])
    setpoints = [(0.0, 0.0, 0.0), (math.radians(45.0), 0.0, 0.0), (0.0, math.radians(30.0), 0.0),
                 (math.radians(15.0), math.radians(15.0), math.radians(15.0))]
    durations = np.empty(args.steps)
    phases = {}
    clock = time.perf_counter
    for k in range(args.steps):
        if k % 5000 == 0:
            controller.set_setpoint_rpy(*setpoints[(k // 5000) % len(setpoints)])
        start = clock()
        out = controller.step(k * DT, state.rotation, state.omega)
        durations[k] = clock() - start
        phases[out.state.pair_phase] = phases.get(out.state.pair_phase, 0) + 1
        q_hold, q_dot = held_joint_input(q_previous, out.joint_targets, DT)
        state = model.step(state, q_hold, q_dot, DT)
        q_previous = out.joint_targets

    us = durations * 1e6
    print("AttitudeController.step over %d closed-loop steps (%s gains, %s strokes):"
          % (args.steps, args.gain_set, config.stroke_scheme))
    print("  median %.1f us   mean %.1f us   p90 %.1f us   p99 %.1f us   p99.9 %.1f us   max %.1f us"
          % (np.median(us), us.mean(), np.percentile(us, 90), np.percentile(us, 99), np.percentile(us, 99.9),
             us.max()))
    print("  target p99 < 500 us: %s" % ("met" if np.percentile(us, 99) < 500.0 else "NOT met"))
    print("  phase mix: " + ", ".join("%s/%s %.0f%%" % (a, b, 100.0 * n / args.steps)
                                      for (a, b), n in sorted(phases.items())))

    # Breakdown of the fixed costs (best of 3 runs of 2000 calls each).
    feet = [tuple(params.nominal_foot_body(leg).tolist()) for leg in LEGS]

    def per_call_us(function, repeats=2000):
        best = math.inf
        for _ in range(3):
            t0 = clock()
            for _ in range(repeats):
                function()
            best = min(best, (clock() - t0) / repeats)
        return best * 1e6

    ik_us = per_call_us(lambda: [joint_angles(r, leg, params) for leg, r in zip(LEGS, feet)])
    hold_controller = AttitudeController(params, config)
    hold_us = per_call_us(lambda: hold_controller.hold(0.0, "bench"))
    print("  parts: IK for 4 legs %.1f us; hold() %.1f us" % (ik_us, hold_us))


if __name__ == "__main__":
    main()
