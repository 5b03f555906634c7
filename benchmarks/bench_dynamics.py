"""Benchmark of the floating-base model: microseconds per RK4 step (dt = 0.01 s, four moving legs).

Run: .venv/bin/python benchmarks/bench_dynamics.py [--steps N]
Prints the cost of one step split into its parts and the real-time factor of a 120 s trial.
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
from quadruped_control.model.kinematics import joint_angles  # noqa: E402
from quadruped_control.model.params import load_robot_params  # noqa: E402
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState, held_joint_input  # noqa: E402

DT = 0.01


def per_call_us(function, repeats):
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        for _ in range(repeats):
            function()
        best = min(best, (time.perf_counter() - start) / repeats)
    return best * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="steps per timing run (default 3000)")
    args = parser.parse_args()

    params = load_robot_params()
    model = FloatingBaseModel(params)
    q_nominal = np.array([joint_angles(params.nominal_foot_body(leg), leg, params) for leg in LEGS])
    phase = np.linspace(0.0, 2.0 * math.pi, 12, endpoint=False).reshape(4, 3)
    commands = [q_nominal + 0.15 * np.sin(2.0 * math.pi * k * DT + phase) for k in range(args.steps + 1)]
    inputs = [held_joint_input(commands[k], commands[k + 1], DT) for k in range(args.steps)]

    def trial():
        state = RigidBodyState(rotation=rpy_to_rot(0.2, -0.1, 0.5), omega=np.array([0.3, -0.2, 0.4]))
        for q_hold, q_dot in inputs:
            state = model.step(state, q_hold, q_dot, DT)
        return state

    trial()  # warm-up
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        trial()
        best = min(best, time.perf_counter() - start)
    step_us = best / args.steps * 1e6

    q_hold, q_dot = inputs[0]
    state = RigidBodyState(rotation=rpy_to_rot(0.2, -0.1, 0.5), omega=np.array([0.3, -0.2, 0.4]))
    context = model._context(model.leg_input(q_hold, q_dot))  # noqa: SLF001 (breakdown only)
    kinematics_us = per_call_us(lambda: model.leg_input(q_hold, q_dot), 2000)
    integrator_us = per_call_us(lambda: model._rk4(state, DT, (context, context, context)), 2000)  # noqa: SLF001
    validate_us = per_call_us(state.validate, 2000)

    print("floating-base model, RK4 dt = %.3f s, 4 legs moving, %d steps" % (DT, args.steps))
    print("  full step (validate + kinematics + 4 RK stages): %7.1f us/step" % step_us)
    print("    leg kinematics (8 FK/Jacobian calls)          : %7.1f us" % kinematics_us)
    print("    RK4 stages on SO(3)                           : %7.1f us" % integrator_us)
    print("    state validation                              : %7.1f us" % validate_us)
    print("  120 s trial (12000 steps): %.2f s wall, %.0fx real time" % (12000 * step_us * 1e-6, DT / (step_us * 1e-6)))


if __name__ == "__main__":
    main()
