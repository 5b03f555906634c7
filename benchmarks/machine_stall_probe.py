"""Records machine-level stalls while a benchmark runs (quadruped_common.stall_probe).

    python benchmarks/machine_stall_probe.py OUT.csv [--period 0.002] [--threshold 0.010]

Runs at SCHED_FIFO 99 where permitted (else says so in the file and runs at normal priority: then a
stall may also be other load) until SIGINT or SIGTERM, appending one ``start,end`` line (wall clock, s)
per sleep that ended more than THRESHOLD late.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.stall_probe import format_stall, watch  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out")
    parser.add_argument("--period", type=float, default=0.002)
    parser.add_argument("--threshold", type=float, default=0.010)
    args = parser.parse_args()
    running = [True]

    def stop(_signum, _frame):
        running[0] = False

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))
        priority = "SCHED_FIFO 99"
    except (AttributeError, PermissionError, OSError):
        priority = "normal priority (SCHED_FIFO not permitted): stalls may include other load"
    with open(args.out, "w", buffering=1) as out:
        out.write("# machine stall probe, %s, period %.3f s, threshold %.3f s\n" % (priority, args.period,
                                                                                 args.threshold))
        for stall in watch(args.period, args.threshold, keep_running=lambda: running[0]):
            out.write(format_stall(stall) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
