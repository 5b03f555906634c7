"""Fault and fuzz campaigns at full size (tests/drivers/test_fault_scenarios.py runs them small). Prints the figures.

    .venv/bin/python benchmarks/fuzz_campaign.py --part vn100   # 300,000 mutated VN-100 packets
    .venv/bin/python benchmarks/fuzz_campaign.py --part i2c     # 36,000 faulty I2C cycles + failsafe trials
    .venv/bin/python benchmarks/fuzz_campaign.py --part controller  # 100,000 random controller inputs
    .venv/bin/python benchmarks/fuzz_campaign.py --part config  # 600 mutated config files
    .venv/bin/python benchmarks/fuzz_campaign.py --part depth   # 2 x 100,000 faulty MS5837 cycles (Bar30, Bar02)
    .venv/bin/python benchmarks/fuzz_campaign.py                # every part

Each part is a function in :data:`PARTS` returning (figures, failures); the script exits 1 if any part
reports a failure. The code under test is the drivers' own (pure core, register-level fakes);
the campaign logic lives in ``quadruped_drivers/vn100/fuzz.py``, ``quadruped_drivers/fault_scenarios.py`` and
``quadruped_drivers/ms5837_fuzz.py`` so the tests (``tests/drivers/test_fault_scenarios.py``,
``tests/drivers/test_ms5837.py``) run the same code at a CI-sized count.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import sys
import tempfile
import time
import traceback
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.config import ParameterError, config_path  # noqa: E402
from quadruped_common.monitoring import imu_values_problem, time_problem  # noqa: E402
from quadruped_common.so3 import rot_to_quat, rpy_to_rot  # noqa: E402
from quadruped_common.tunables import TUNABLES  # noqa: E402
from quadruped_control.control.controller import AttitudeController  # noqa: E402
from quadruped_control.control.controller_config import apply_tunables, load_controller_config  # noqa: E402
from quadruped_control.control.supervisor import ControlSupervisor  # noqa: E402
from quadruped_control.model.params import load_robot_params  # noqa: E402
from quadruped_control.sim.config_files import LOADERS  # noqa: E402
from quadruped_drivers.calibration import load_servo_calibration  # noqa: E402
from quadruped_drivers.fault_scenarios import PERIOD, failsafe_latency, faulty_cycles  # noqa: E402
from quadruped_drivers import ms5837_fuzz  # noqa: E402
from quadruped_drivers.hardware_config import load_hardware_config  # noqa: E402
from quadruped_drivers.ms5837 import Model  # noqa: E402
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


HANG_S = 0.5
SPIKES = (1e3, -1e6, 3.4e38, 1e154, math.nan, math.inf, -math.inf, 40.0)
BAD_TIMES = (math.nan, math.inf, -math.inf)


# --------------------------------------------------------------------------------------------------
# Controller
# --------------------------------------------------------------------------------------------------

def _random_sample(rng: random.Random, t: float) -> Tuple[Any, Any, Any, float]:
    """(quaternion, rate, acceleration, stamp): mostly good, often faulty."""
    q = rot_to_quat(rpy_to_rot(rng.uniform(-math.pi, math.pi), rng.uniform(-1.5, 1.5), rng.uniform(-math.pi, math.pi)))
    w = [rng.gauss(0.0, 0.5) for _ in range(3)]
    a = [rng.gauss(0.0, 2.0), rng.gauss(0.0, 2.0), 9.81 + rng.gauss(0.0, 2.0)]
    stamp = t - rng.uniform(0.0, 0.005)
    fault = rng.random()
    if fault < 0.10:
        w[rng.randrange(3)] = rng.choice(SPIKES)
    elif fault < 0.15:
        q = list(q)
        q[rng.randrange(4)] = rng.choice((math.nan, math.inf, 0.0, 2.0, 1e30, 3.4e38))
    elif fault < 0.18:
        a[rng.randrange(3)] = rng.choice((200.0, -1e6, math.nan, math.inf, 3.4e38))
    elif fault < 0.23:
        stamp = rng.choice(BAD_TIMES + (t - 1.0, t + 1.0, 1e300, -1e300))
    elif fault < 0.25:
        w = [rng.uniform(-36.0, 36.0) for _ in range(3)]  # in range but violent
    return q, w, a, stamp


def run_controller(inputs: int, seed: int) -> Dict[str, Any]:
    rng = random.Random(seed)
    robot = load_robot_params()
    counts = {"inputs": 0, "crashes": 0, "hangs": 0, "nan_outputs_or_states": 0, "unusable_samples_used": 0,
              "integral_beyond_limit": 0, "steps": 0, "holds": 0, "samples_dropped": 0, "updates_applied": 0,
              "updates_refused": 0}
    first_error: List[str] = []
    episode = 0
    while counts["inputs"] < inputs:
        episode += 1
        config = load_controller_config(gain_set=rng.choice(["simulation", "experiment", "experiment_fast_recovery"]))
        controller = AttitudeController(robot, config)
        used: List[Tuple[np.ndarray, float, float]] = []
        state = {"stamp": None, "now": None}
        step = controller.step

        def recording_step(t, R, omega, _step=step, _used=used, _state=state):
            _used.append((np.array(omega, dtype=float), _state["stamp"], _state["now"]))
            return _step(t, R, omega)

        controller.step = recording_step  # type: ignore[method-assign]
        supervisor = ControlSupervisor(controller, lambda angles: np.clip(1500.0 + 600.0 * angles, 500.0, 2500.0),
                                       armed=True)
        t = rng.uniform(0.0, 1e6)
        last_plausible: Optional[Tuple[Any, Any, float]] = None
        for _ in range(min(2000, inputs - counts["inputs"])):
            counts["inputs"] += 1
            t += rng.choice((0.01, 0.01, 0.01, 0.005, 0.0125, 0.02, 0.05, 0.1, 0.0))
            now = t if rng.random() > 0.02 else rng.choice(BAD_TIMES)
            q, w, a, stamp = _random_sample(rng, t)
            try:
                if rng.random() < 0.01:
                    values = {tn.name: rng.choice((rng.uniform(tn.low, tn.high), tn.high, tn.low, math.nan, math.inf,
                                                   1e300, -1.0)) for tn in TUNABLES if rng.random() < 0.5}
                    try:
                        updated = apply_tunables(controller.config, values)
                        controller.set_gains(updated.gains)
                        controller.set_timing(updated.t_rec, updated.t_pow_max, updated.tau_max)
                        counts["updates_applied"] += 1
                    except ParameterError:
                        counts["updates_refused"] += 1
                if rng.random() < 0.002:
                    supervisor.arm(False)
                    supervisor.arm(True)
                started = time.perf_counter()
                dropped = supervisor.set_imu(q, w, stamp, a)
                if dropped is None:
                    last_plausible = (q, w, stamp)
                else:
                    counts["samples_dropped"] += 1
                state["stamp"] = last_plausible[2] if last_plausible else None
                state["now"] = now
                before = len(used)
                out = supervisor.tick(t, now)
                if time.perf_counter() - started > HANG_S:
                    counts["hangs"] += 1
            except Exception:  # noqa: BLE001 - counted: that is the point of the campaign
                counts["crashes"] += 1
                if not first_error:
                    first_error.append(traceback.format_exc())
                continue
            record = out.output.state
            values_ok = all(np.all(np.isfinite(v)) for v in (out.pulse_widths_us, out.joint_targets, record.tau_cmd,
                                                             record.tau_sat, record.integral, record.e_R,
                                                             record.foot_targets, record.tau_feedforward))
            if not values_ok:
                counts["nan_outputs_or_states"] += 1
            if np.linalg.norm(record.integral) > controller.config.integral_limit * (1 + 1e-12):
                counts["integral_beyond_limit"] += 1
            if out.problem:
                counts["holds"] += 1
            if len(used) > before:
                counts["steps"] += 1
                omega_used, stamp_used, now_used = used[-1]
                q_used, w_used, _ = last_plausible if last_plausible else (None, None, None)
                usable = (last_plausible is not None and stamp_used is not None
                          and imu_values_problem(q_used, w_used, None, supervisor.imu_limits) is None
                          and time_problem(stamp_used, now_used, supervisor.max_imu_age) is None
                          and np.array_equal(omega_used, np.asarray(w_used, dtype=float)))
                if not usable:
                    counts["unusable_samples_used"] += 1
    if first_error:
        print(first_error[0], file=sys.stderr)
    counts["episodes"] = episode
    return counts


# --------------------------------------------------------------------------------------------------
# Configuration files
# --------------------------------------------------------------------------------------------------


NASTY_TEXT = (".nan", ".inf", "-.inf", "1.0e+300", "-1.0e+300", "9" * 400, "-" + "9" * 400, "true", "false",
              "null", "'text'", "[]", "{}", "[1, [2, [3]]]", "{a: 1}", "0x7fffffffffffffffffff", "1e400")


def _parse(text: str) -> Any:
    try:
        return yaml.safe_load(text)
    except (yaml.YAMLError, ValueError):
        return None


def _leaf_lines(lines: List[str]) -> List[Tuple[int, str, str]]:
    """(line index, indent, key) of every 'key: value' line with a scalar or flow value."""
    out = []
    for index, line in enumerate(lines):
        stripped = line.split("#", 1)[0].rstrip()
        if ":" not in stripped or stripped.lstrip().startswith("-"):
            continue
        key, _, value = stripped.partition(":")
        if value.strip():
            out.append((index, key[: len(key) - len(key.lstrip())], key.strip().strip("'\"")))
    return out


def _mutate(rng: random.Random, text: str) -> Tuple[bytes, str, Optional[str], bool]:
    """(mutated bytes, kind, key the message must name or None, must be rejected)."""
    lines = text.splitlines()
    leaves = _leaf_lines(lines)
    kind = rng.choice(("value", "value", "value", "type", "duplicate", "non_string_key", "alias", "bomb",
                       "recursion", "nesting", "encoding", "huge_int", "delete"))
    index, indent, key = rng.choice(leaves)
    original = lines[index].split(":", 1)[1].split("#", 1)[0].strip()
    if kind == "value":
        try:
            parsed = yaml.safe_load(original)
        except yaml.YAMLError:
            parsed = None
        # never a value of the original's own kind (a string key may hold 'text', a flag true or false)
        choices = [v for v in NASTY_TEXT if not (isinstance(parsed, str) and isinstance(_parse(v), str))
                   and not (isinstance(parsed, bool) and v in ("true", "false"))]
        value = rng.choice(choices)
        lines[index] = "%s%s: %s" % (indent, key, value)
        return ("\n".join(lines) + "\n").encode(), kind, key, True
    if kind == "type":
        try:
            parsed = yaml.safe_load(original)
        except yaml.YAMLError:
            parsed = None
        if isinstance(parsed, bool):
            value = rng.choice(("1", "0", "'true'"))
        elif isinstance(parsed, (int, float)):
            value = rng.choice(("true", "false", "'%s'" % original, "[%s]" % original))
        elif isinstance(parsed, str):
            value = rng.choice(("1", "true", "null", "[]"))
        else:
            value = "'%s'" % original.replace("'", "")
        lines[index] = "%s%s: %s" % (indent, key, value)
        return ("\n".join(lines) + "\n").encode(), kind, key, True
    if kind == "duplicate":
        lines.insert(index + 1, "%s%s: %s" % (indent, key, original))
        return ("\n".join(lines) + "\n").encode(), kind, key, True
    if kind == "non_string_key":
        new_key = rng.choice(("1", "true", "null", "2.5", "[a]", "{b: 1}"))
        lines[index] = "%s%s: %s" % (indent, new_key, original)
        return ("\n".join(lines) + "\n").encode(), kind, None, True
    if kind == "alias":
        lines.insert(index, "%sanchored_key_x: &anc [1, 2]" % indent)
        lines[index + 1] = "%s%s: *anc" % (indent, key)
        return ("\n".join(lines) + "\n").encode(), kind, None, True
    if kind == "bomb":
        bomb = ['lol0: &l0 ["lol"]'] + ["lol%d: &l%d [%s]" % (i, i, ", ".join(["*l%d" % (i - 1)] * 9)) for i in range(1, 10)]
        return (text + "\n" + "\n".join(bomb) + "\n").encode(), kind, None, True
    if kind == "recursion":
        return (text + "\nrecursive: &r [*r]\n").encode(), kind, None, True
    if kind == "nesting":
        depth = rng.choice((40, 200, 5000))
        return (text + "\ndeep: " + "[" * depth + "]" * depth + "\n").encode(), kind, None, True
    if kind == "encoding":
        raw = bytearray(text.encode())
        raw[rng.randrange(len(raw))] = rng.choice((0xFF, 0xFE, 0xC3, 0x80))
        return bytes(raw), kind, None, True
    if kind == "huge_int":
        lines[index] = "%s%s: %s" % (indent, key, "1" + "0" * rng.choice((25, 400, 5000)))
        return ("\n".join(lines) + "\n").encode(), kind, key, True
    # delete: the key may be optional, so the file may stay valid
    del lines[index]
    return ("\n".join(lines) + "\n").encode(), kind, key, False


def run_config(files: int, seed: int) -> Dict[str, Any]:
    rng = random.Random(seed)
    counts = {"files": 0, "crashes": 0, "hangs": 0, "rejected": 0, "rejected_naming_file": 0,
              "rejected_naming_file_and_key": 0, "rejected_needing_key": 0, "malformed_accepted": 0,
              "accepted_maybe_valid": 0}
    examples: List[str] = []
    names = sorted(LOADERS)
    with tempfile.TemporaryDirectory(prefix="uq-fuzz-") as folder:
        for number in range(files):
            name = names[number % len(names)]
            text = open(config_path(name)).read()
            data, kind, key, must_reject = _mutate(rng, text)
            path = os.path.join(folder, "%04d_%s" % (number, name.replace("/", "_")))  # tank_ensemble/...
            with open(path, "wb") as stream:
                stream.write(data)
            counts["files"] += 1
            started = time.perf_counter()
            try:
                LOADERS[name](path)
                accepted = True
            except ParameterError as exc:
                accepted = False
                message = str(exc)
                counts["rejected"] += 1
                if message.startswith(path + ":") or message.startswith("cannot read " + path):
                    counts["rejected_naming_file"] += 1
                if key is not None:
                    counts["rejected_needing_key"] += 1
                    if key in message:
                        counts["rejected_naming_file_and_key"] += 1
                    elif len(examples) < 5:
                        examples.append("%s (%s %s): %s" % (name, kind, key, message))
            except Exception as exc:  # noqa: BLE001 - a raw traceback is what the campaign looks for
                accepted = False
                counts["crashes"] += 1
                if len(examples) < 5:
                    examples.append("CRASH %s (%s): %s: %s" % (name, kind, type(exc).__name__, exc))
            if time.perf_counter() - started > 5.0:
                counts["hangs"] += 1
            if accepted:
                if must_reject:
                    counts["malformed_accepted"] += 1
                    if len(examples) < 5:
                        examples.append("ACCEPTED %s (%s %s)" % (name, kind, key))
                else:
                    counts["accepted_maybe_valid"] += 1
    for line in examples:
        print("  example: " + line)
    return counts


def part_controller(args: argparse.Namespace) -> Result:
    """Random inputs through the supervisor and the controller, as the controller node drives them."""
    stats = run_controller(args.inputs, args.seed)
    return stats, _zero(stats, ("crashes", "hangs", "nan_outputs_or_states", "unusable_samples_used",
                                "integral_beyond_limit"))


def part_config(args: argparse.Namespace) -> Result:
    """Mutated copies of every config file through the strict loader and the typed schemas."""
    stats = run_config(args.files, args.seed)
    stats["rejected_without_file"] = stats["rejected"] - stats["rejected_naming_file"]
    stats["rejected_without_key"] = stats["rejected_needing_key"] - stats["rejected_naming_file_and_key"]
    return stats, _zero(stats, ("crashes", "hangs", "malformed_accepted", "rejected_without_file",
                                "rejected_without_key"))


def part_depth(args: argparse.Namespace) -> Result:
    """Faulty 10 ms cycles of the MS5837 driver against its register-level fake, both models."""
    stats: Dict[str, object] = {}
    failures: List[str] = []
    for model in (Model.BA30, Model.BA02):
        result = ms5837_fuzz.run(args.depth_cycles, seed=args.seed, model=model)
        stats.update({"%s %s" % (model.value, key): value for key, value in result.items()})
        failures += ["%s %s = %s" % (model.value, key, result[key]) for key in ms5837_fuzz.MUST_BE_ZERO if result[key]]
    return stats, failures


PARTS: Dict[str, Callable[[argparse.Namespace], Result]] = {"vn100": part_vn100, "i2c": part_i2c,
                                                          "controller": part_controller, "config": part_config,
                                                          "depth": part_depth}


def main(argv: List[str] = None) -> int:  # type: ignore[assignment]
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--part", choices=sorted(PARTS), action="append",
                        help="campaign part (repeatable; default: all)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--packets", type=int, default=300_000, help="vn100: mutated packets")
    parser.add_argument("--cycles", type=int, default=36_000, help="i2c: faulty cycles")
    parser.add_argument("--seeds", type=int, default=12, help="i2c: independent rigs the cycles are split over")
    parser.add_argument("--trials", type=int, default=500, help="i2c: failsafe trials per failsafe and failure rate")
    parser.add_argument("--inputs", type=int, default=100_000, help="controller: random inputs")
    parser.add_argument("--files", type=int, default=600, help="config: mutated config files")
    parser.add_argument("--depth-cycles", type=int, default=100_000, help="depth: faulty cycles per MS5837 model")
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
