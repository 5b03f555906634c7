"""Figures of benchmarks/bench_sim_graph.sh: each run's health figures, its hold episodes and the
machine stalls seen beside it, then min / median / max over the runs.

    python benchmarks/sim_graph_summary.py OUT RUNS

OUT/runN/bags/*.bag are the runs' bags, OUT/runN/machine_stalls.csv the stall probe's record
(benchmarks/machine_stall_probe.py; missing: no attribution). Control periods longer than 12 ms (the
jitter outliers) are counted, and how many of them had a machine stall inside. A stale-IMU hold is
listed with how long the machine was stalled in the stale limit + one control period before the
controller decided to hold (the stamp of its first held /controller_state), and the holds with at least
half the stale limit stalled are counted.
"""
from __future__ import annotations

import glob
import os
import sys
from typing import Dict, List

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.stall_probe import Stall, read_stalls, stalled_time  # noqa: E402
from quadruped_control.analysis.bag_report import health, health_across_runs, hold_episodes, read_bags  # noqa: E402

STALE_LIMIT = 0.05  # attitude_controller ~imu_max_age default (s)
CONTROL_PERIOD = 0.01
REPORTED_STALL = 0.020  # machine stalls this long or longer are counted in the figures
LATE_PERIOD = 0.012  # a control period this long is a jitter outlier (|period - 10 ms| > 2 ms)


def run_figures(run_dir: str) -> Dict[str, Dict[str, str]]:
    data = read_bags(sorted(glob.glob(os.path.join(run_dir, "bags", "*.bag"))))
    figures = health(data)
    probe = os.path.join(run_dir, "machine_stalls.csv")
    have_probe = os.path.exists(probe)
    stalls: List[Stall] = []
    if have_probe:
        with open(probe) as lines:
            stalls = read_stalls(lines)
    holds = []
    during_stall = 0
    for episode in hold_episodes(data):
        line = "%.3f-%.3f %s" % (episode.start, episode.end, episode.reason)
        if episode.stale_imu and have_probe:
            window = STALE_LIMIT + CONTROL_PERIOD
            stalled = stalled_time(stalls, episode.start - window, episode.start)
            if stalled >= STALE_LIMIT / 2:
                during_stall += 1
            line += "  [machine stalled %.1f ms of the %.0f ms before]" % (stalled * 1e3, window * 1e3)
        holds.append(line)
    if have_probe:
        # Control periods from the controller's own step stamps (/controller_state, one per step),
        # from the first step that strokes (before it, the fallback timer steps a controller that
        # waits for its first IMU sample every 20 ms).
        stamps = np.array(data.state_t)
        stroking = stamps[~np.array(data.state_holding, dtype=bool)]
        steps = np.sort(stamps[stamps >= stroking.min()]) if stroking.size else np.zeros(0)
        late = [(a, b) for a, b in zip(steps[:-1], steps[1:]) if b - a > LATE_PERIOD]
        figures["machine (stall probe, SCHED_FIFO 99)"] = {
            "stalls (all)": str(len(stalls)),
            "stalls >= %.0f ms" % (REPORTED_STALL * 1e3): str(sum(s.duration >= REPORTED_STALL for s in stalls)),
            "longest stall [ms]": "%.1f" % (max((s.duration for s in stalls), default=0.0) * 1e3),
            "control periods > %.0f ms" % (LATE_PERIOD * 1e3): str(len(late)),
            "... with a stall inside": str(sum(stalled_time(stalls, a, b) > 0.0 for a, b in late)),
            "stale-IMU holds, >= %.0f ms stalled before" % (STALE_LIMIT / 2 * 1e3): str(during_stall),
        }
    figures["_holds"] = {str(i): line for i, line in enumerate(holds)}
    return figures


def main(out: str, runs: int) -> None:
    per_run = []
    for run in range(1, runs + 1):
        figures = run_figures(os.path.join(out, "run%d" % run))
        holds = figures.pop("_holds")
        per_run.append(figures)
        print("run %d" % run)
        for name, items in figures.items():
            print("  " + name)
            for key, value in items.items():
                print("    %-32s %s" % (key, value))
        print("  hold episodes (first and last held step, reason of the first)")
        for line in holds.values() or ["(none)"]:
            print("    " + line)
    print("over %d runs: min / median / max" % runs)
    for name, items in health_across_runs(per_run).items():
        print("  " + name)
        for key, s in items.items():
            print("    %-32s %10.3f %10.3f %10.3f%s" % (key, s["min"], s["median"], s["max"],
                                                     "" if s["n"] == runs else "  (%d runs)" % s["n"]))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
