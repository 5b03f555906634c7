"""Benchmark (not a test): one 180 s closed-loop trial on the tank plant, on one core.

    python benchmarks/bench_tank_trial.py [--repeats 3] [--duration 180]

Experiment gains, rate-limited servos, 45 degree roll setpoint from level. Reports the real-time factor
(simulated s per s) from wall time and from this process's CPU time (less sensitive to other load on a
shared machine), min / median / max over the repeats, and the paper plant for comparison.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_control.studies import trial  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=180.0)
    args = parser.parse_args()
    for plant in ("tank", "paper"):
        wall, cpu = [], []
        for _ in range(args.repeats):
            spec = trial.TrialSpec(label="bench", setpoint_rpy_deg=(45.0, 0.0, 0.0), duration=args.duration,
                                      gains="experiment", servo_model="rate-limited", plant=plant, quiet=True,
                                      keep_trace=False)
            w0, c0 = time.perf_counter(), time.process_time()
            trial.run_trial(spec)
            wall.append(args.duration / (time.perf_counter() - w0))
            cpu.append(args.duration / (time.process_time() - c0))
        print("%s plant, %g s trial x %d: real-time factor wall min/median/max %.0f / %.0f / %.0f, "
              "CPU %.0f / %.0f / %.0f" % (plant, args.duration, args.repeats, min(wall), statistics.median(wall),
                                          max(wall), min(cpu), statistics.median(cpu), max(cpu)))


if __name__ == "__main__":
    main()
