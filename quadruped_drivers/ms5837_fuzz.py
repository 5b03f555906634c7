"""Fuzzing the MS5837 depth-sensor path: the driver against the register-level fake with random faults (no ROS).

:func:`run` drives :class:`~quadruped_drivers.ms5837.Ms5837` (non-blocking :meth:`~quadruped_drivers.ms5837.Ms5837.poll`
every 10 ms, as a 100 Hz loop would) against :class:`~quadruped_drivers.i2c.fake_ms5837.FakeMs5837` on a
:class:`~quadruped_drivers.i2c.fake_bus.FakeI2CBus`, on a simulated clock, while the true depth follows a slow
random walk. Each cycle draws one fault: none, a NACK, an I/O error, an aborted write, garbage ADC codes
(random 24-bit, 0, 0xFFFFFF), a stuck ADC for a while, a chip slower than its data sheet, a conversion read
early by another master, a true depth step beyond the rate bound, or a corrupted PROM followed by a restart
(which must be refused). It counts what must never happen: exceptions out of the driver (``crashes``;
``PromCrcError`` from a restart on a corrupted PROM is the expected refusal, counted in ``crc_refusals``), a
poll slower than ``hang_s`` (``hangs``), a fresh reading with a non-finite value (``nonfinite_fresh``) or a
pressure / temperature outside the plausible limits (``implausible_fresh``), a corrupted PROM accepted
(``bad_prom_accepted``), and a reading the node would publish (:func:`~quadruped_drivers.depth_sensor.publishable`)
that is not fresh, not finite or not plausible (``implausible_published``). ``fresh_off_truth`` (informational) counts fresh readings further than 0.5 m from the
true depth: garbage that happens to be plausible and within the rate bound cannot be told from data.

    python -m quadruped_drivers.ms5837_fuzz --cycles 100000 --seed 1
"""
from __future__ import annotations

import argparse
import math
import random
import sys
import time
from typing import Dict, List, Optional

from quadruped_drivers.depth_sensor import publishable
from quadruped_drivers.i2c.fake_bus import FakeI2CBus
from quadruped_drivers.i2c.fake_ms5837 import FakeMs5837
from quadruped_drivers.ms5837 import REASONS, Model, Ms5837, PromCrcError

FAULTS = ("none", "nack", "oserror", "abort", "garbage", "stuck", "slow", "early_read", "step", "prom")
MUST_BE_ZERO = ("crashes", "hangs", "nonfinite_fresh", "implausible_fresh", "bad_prom_accepted",
                "implausible_published")
PERIOD = 0.01
SURFACE_PA = 101325.0
DENSITY = 1025.0
G = 9.80665


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, seconds)


def run(cycles: int, seed: int = 0, model: Model = Model.BA30, hang_s: float = 0.5) -> Dict[str, int]:
    """Fuzz ``cycles`` 10 ms cycles; returns the counters (module docstring)."""
    rng = random.Random(seed)
    clock = _Clock()
    bus = FakeI2CBus(require_lock=True, name="fuzz-ms5837")
    bus.log_enabled = False
    max_depth = 250.0 if model is Model.BA30 else 8.0
    depth, temperature = rng.uniform(0.0, max_depth / 2), rng.uniform(2.0, 30.0)
    fake = bus.attach(0x76, FakeMs5837(model, clock=clock, seed=seed,
                                       pressure_pa=SURFACE_PA + DENSITY * G * depth, temperature_c=temperature))
    driver = Ms5837(bus, model, clock=clock, sleep=clock.sleep, surface_pa=SURFACE_PA, density=DENSITY, g=G)
    driver.start()
    stats: Dict[str, int] = {"cycles": 0, "readings": 0, "fresh": 0, "crashes": 0, "hangs": 0,
                             "nonfinite_fresh": 0, "implausible_fresh": 0, "bad_prom_accepted": 0,
                             "crc_refusals": 0, "fresh_off_truth": 0, "restarts": 0, "published": 0,
                             "implausible_published": 0}
    for fault in FAULTS:
        stats["fault " + fault] = 0
    stuck_until = -1
    low_pa, high_pa = driver.plausible_pa
    for index in range(cycles):
        clock.t += PERIOD
        stats["cycles"] += 1
        # the true state: a slow random walk, within the sensor's range
        depth = min(max_depth, max(0.0, depth + rng.gauss(0.0, 0.005)))
        temperature = min(35.0, max(0.0, temperature + rng.gauss(0.0, 0.01)))
        fault = rng.choice(FAULTS) if rng.random() < 0.3 else "none"
        stats["fault " + fault] += 1
        if fault == "step":
            depth = min(max_depth, max(0.0, depth + rng.choice((-1, 1)) * rng.uniform(1.0, 20.0)))
        fake.set_state(SURFACE_PA + DENSITY * G * depth, temperature)
        fake.conversion_scale = 1.0
        if index == stuck_until:
            fake.stick_adc(None)
        if fault == "nack":
            bus.inject_fault(0x76, "nack")
        elif fault == "oserror":
            bus.inject_fault(0x76, "oserror")
        elif fault == "abort":
            bus.inject_fault(0x76, "abort", keep=0)
        elif fault == "garbage":
            fake.inject_codes([rng.choice((0, 1, 0xFFFFFF, rng.randrange(1 << 24)))
                               for _ in range(rng.randint(1, 4))])
        elif fault == "stuck":
            fake.stick_adc(rng.randrange(1 << 24))
            stuck_until = index + rng.randint(1, 60)
        elif fault == "slow":
            fake.conversion_scale = rng.uniform(1.2, 3.0)
        elif fault == "early_read":
            fake.write(b"\x00")  # another master reads the ADC mid-conversion
            fake.read(3)
        started = time.perf_counter()
        try:
            if fault == "prom":
                word = rng.randrange(7)
                flip = 1 << rng.randrange(12 if word == 0 else 16)
                fake.corrupt_prom(word, flip)
                stats["restarts"] += 1
                try:
                    driver.start()
                    stats["bad_prom_accepted"] += 1
                except PromCrcError:
                    stats["crc_refusals"] += 1
                fake.corrupt_prom(word, flip)  # repaired: the next start reads a good PROM
                _restart(driver, stats)
                reading = None
            else:
                reading = driver.poll()
        except Exception:  # noqa: BLE001 - the campaign counts what would kill the node
            stats["crashes"] += 1
            _restart(driver, stats)
            continue
        if time.perf_counter() - started > hang_s:
            stats["hangs"] += 1
        if reading is None:
            continue
        stats["readings"] += 1
        values = (reading.pressure_pa, reading.temperature_c, reading.depth_m)
        if publishable(reading, driver):
            stats["published"] += 1
            if not (reading.fresh and all(math.isfinite(value) for value in values)
                    and low_pa <= reading.pressure_pa <= high_pa
                    and driver.plausible_c[0] <= reading.temperature_c <= driver.plausible_c[1]):
                stats["implausible_published"] += 1
        if not reading.fresh:
            continue
        stats["fresh"] += 1
        if not all(math.isfinite(value) for value in values):
            stats["nonfinite_fresh"] += 1
        elif not (low_pa <= reading.pressure_pa <= high_pa
                  and driver.plausible_c[0] <= reading.temperature_c <= driver.plausible_c[1]):
            stats["implausible_fresh"] += 1
        elif abs(reading.depth_m - depth) > 0.5:
            stats["fresh_off_truth"] += 1
    stats.update({"driver " + name: count for name, count in driver.counters().items()})
    return stats


def _restart(driver: Ms5837, stats: Dict[str, int]) -> None:
    """Start the driver again until it takes (a NACK may hit the restart itself)."""
    for _ in range(5):
        try:
            driver.start()
            return
        except (OSError, PromCrcError):
            continue
    stats["crashes"] += 1  # could not restart on a healthy chip


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cycles", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", choices=[model.value for model in Model], default=Model.BA30.value)
    args = parser.parse_args(argv)
    started = time.perf_counter()
    stats = run(args.cycles, seed=args.seed, model=Model(args.model))
    print("== ms5837 %s (%.1f s)" % (args.model, time.perf_counter() - started))
    for key, value in stats.items():
        print("  %-34s %s" % (key, value))
    failures = ["%s = %s" % (key, stats[key]) for key in MUST_BE_ZERO if stats[key]]
    print("  RESULT: %s" % ("FAIL: " + "; ".join(failures) if failures else "0 failures"))
    return 1 if failures else 0


__all__ = ["FAULTS", "MUST_BE_ZERO", "REASONS", "main", "run"]

if __name__ == "__main__":
    sys.exit(main())
