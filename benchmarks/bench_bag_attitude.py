"""Benchmark of reading a recorded attitude: ``bag_report.attitude_rpy`` on a ten-minute IMU stream.

Run: .venv/bin/python benchmarks/bench_bag_attitude.py [--samples N] [--repeats R]

The hang study and the step test read every IMU sample of their bags (a ten-minute hang at the VN-100's 200 Hz
is 120,000 samples) through ``attitude_rpy``: the checks, the stamp order and the quaternion to roll-pitch-yaw
conversion (``so3.quaternions_to_rotations``, vectorised over samples). Also times ``so3.quat_to_rot`` per
call, the controller's conversion of each IMU sample (the supervisor's tick), which shares its equation.
Prints min / median / max over the repeats.
"""
import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.so3 import quat_to_rot  # noqa: E402
from quadruped_control.analysis.bag_report import attitude_rpy  # noqa: E402


def _figures(seconds):
    return "min %.4g   median %.4g   max %.4g" % (min(seconds), statistics.median(seconds), max(seconds))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=120000, help="IMU samples (default 120000: 10 min at 200 Hz)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    quaternions = rng.normal(size=(args.samples, 4))
    quaternions /= np.linalg.norm(quaternions, axis=1, keepdims=True)
    times = np.arange(args.samples) / 200.0
    seconds = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        attitude_rpy(times, quaternions)
        seconds.append(time.perf_counter() - start)
    print("attitude_rpy, %d samples, %d repeats [s]: %s" % (args.samples, args.repeats, _figures(seconds)))
    calls = 20000
    per_call = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        for q in quaternions[:calls]:
            quat_to_rot(q)
        per_call.append((time.perf_counter() - start) / calls * 1e6)
    print("quat_to_rot per call, %d calls, %d repeats [us]: %s" % (calls, args.repeats, _figures(per_call)))


if __name__ == "__main__":
    main()
