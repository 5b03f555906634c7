"""Fault and fuzz campaigns of issue 10 ("Hardening"), at the issue's size. Prints the figures.

    .venv/bin/python benchmarks/fuzz_campaign.py --part vn100   # 300,000 mutated VN-100 packets
    .venv/bin/python benchmarks/fuzz_campaign.py --part i2c     # 36,000 faulty I2C cycles + failsafe trials
    .venv/bin/python benchmarks/fuzz_campaign.py                # every part

Each part is a function in :data:`PARTS` returning (figures, failures); the script exits 1 if any part
reports a failure. The code under test is the drivers' own (pure core, register-level fakes);
the campaign logic lives in ``quadruped_drivers/vn100/fuzz.py`` and ``quadruped_drivers/i2c/fault_scenarios.py``
so the tests (``tests/test_fault_campaigns.py``) run the same code at a CI-sized count.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Callable, Dict, List, Tuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_drivers.calibration import load_servo_calibration  # noqa: E402
from quadruped_drivers.hardware_config import load_hardware_config  # noqa: E402
from quadruped_drivers.i2c.fault_scenarios import PERIOD, failsafe_latency, faulty_cycles  # noqa: E402
from quadruped_drivers.vn100 import fuzz  # noqa: E402

Result = Tuple[Dict[str, object], List[str]]


def _zero(stats: Dict[str, object], keys: Tuple[str, ...]) -> List[str]:
    return ["%s = %s" % (key, stats[key]) for key in keys if stats[key] != 0]


def part_vn100(args: argparse.Namespace) -> Result:
    """Mutated VN-100 packets through the parser and the sample gate (what vn100_node runs per read)."""
    stats = fuzz.run(args.packets, seed=args.seed)
    return stats, _zero(stats, ("crashes", "hangs", "nan_outputs", "implausible_published", "bad_offsets"))


def part_i2c(args: argparse.Namespace) -> Result:
    """Faulty I2C cycles (feedback + PWM against the fakes) and watchdog failsafe trials."""
    hardware = load_hardware_config()
    calibration = load_servo_calibration()
    stats: Dict[str, object] = {}
    per_seed = args.cycles // args.seeds
    totals: Dict[str, object] = {}
    for seed in range(args.seeds):
        result = faulty_cycles(per_seed + (args.cycles % args.seeds if seed == 0 else 0), hardware, calibration,
                               seed=args.seed + seed)
        for key, value in result.items():
            if isinstance(value, (int, np.integer)):
                totals[key] = int(totals.get(key, 0)) + int(value)  # type: ignore[arg-type]
            elif value:
                totals[key] = value
    stats.update(totals)
    failures = _zero(stats, ("crashes", "hangs", "nan_outputs", "wrongly_fresh", "pulses_outside_limits"))
    bound = hardware.watchdog_timeout + PERIOD
    for failsafe in ("hold", "neutral", "off"):
        for rate in (0.0, 0.1, 0.2, 0.3, 0.4, 0.5):
            latencies = np.array([failsafe_latency(hardware, failsafe, rate, args.seed + trial)
                                  for trial in range(args.trials)])
            within = int(np.count_nonzero(latencies <= bound + 1e-9))
            key = "failsafe %-7s %2.0f %% write failures" % (failsafe, 100 * rate)
            stats[key] = "%d/%d trials within %.3f s, latency median %.4f s, max %.4f s" % (
                within, latencies.size, bound, float(np.median(latencies)), float(np.max(latencies)))
            if within != latencies.size:
                failures.append("%s: %d trials late" % (key, latencies.size - within))
    return stats, failures


PARTS: Dict[str, Callable[[argparse.Namespace], Result]] = {"vn100": part_vn100, "i2c": part_i2c}


def main(argv: List[str] = None) -> int:  # type: ignore[assignment]
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--part", choices=sorted(PARTS), action="append",
                        help="campaign part (repeatable; default: all)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--packets", type=int, default=300_000, help="vn100: mutated packets")
    parser.add_argument("--cycles", type=int, default=36_000, help="i2c: faulty cycles")
    parser.add_argument("--seeds", type=int, default=12, help="i2c: independent rigs the cycles are split over")
    parser.add_argument("--trials", type=int, default=500, help="i2c: failsafe trials per failsafe and failure rate")
    args = parser.parse_args(argv)
    failed = False
    for name in args.part or sorted(PARTS):
        started = time.perf_counter()
        stats, failures = PARTS[name](args)
        print("== %s (%.1f s)" % (name, time.perf_counter() - started))
        for key, value in stats.items():
            print("  %-44s %s" % (key, value))
        print("  RESULT: %s" % ("FAIL: " + "; ".join(failures) if failures else "0 failures"))
        failed = failed or bool(failures)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
