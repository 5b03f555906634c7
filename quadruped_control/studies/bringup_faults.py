"""Do calibration, the speed check and the IMU check find a robot built wrong? Seeded faults on the simulated rig.

    python -m quadruped_control.studies.bringup_faults [--cases 40] [--clean 20] [--seed 1] [--out out/bringup]

Each case draws (from its seed) one fault of a random kind (:data:`KINDS`) on random joints with a random
magnitude, builds the rig with it (:class:`~quadruped_drivers.servo_rig.SimulatedServoRig`, feedback noise
of its own seed), runs the servo calibration against the reference poses, after a passed one the pre-dive
check's speed check through the fitted maps, and the IMU mount check on three
guided poses the operator holds only roughly (level within 1 deg, each tilt 20-40 deg about an axis up to 3 deg
off). A servo or
wiring fault is detected when the calibration names every joint it concerns; an IMU fault when the IMU check
fails. A clean case (no fault) must pass all three. Writes ``bringup_faults.md`` / ``.json`` (command, seeds,
code version, each case) into ``--out``.
"""
from __future__ import annotations

import argparse
import math
import sys
from collections import OrderedDict
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import exp_so3, rot_to_rpy, rpy_to_rot
from quadruped_control.bringup.calibrate import run_on_rig, speeds_on_rig
from quadruped_control.bringup.imu_check import GUIDED_POSES, check_imu_mount, expected_specific_force
from quadruped_control.bringup.servo_check import ServoCheckSettings
from quadruped_control.model.params import load_robot_params
from quadruped_control.studies.runner import code_record, write_study_report
from quadruped_drivers.servo_rig import SimulatedServoRig
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.hardware_faults import HardwareFaults

KINDS = ("reversed", "horn_offset", "swapped_pwm", "swapped_feedback", "imu_rotated", "stuck_adc", "slow_servo")


def draw_fault(rng: np.random.Generator, kind: str, zero_tolerance_deg: float) -> Tuple[HardwareFaults, Tuple[str, ...]]:
    """One fault of ``kind``: the faults and the joints it concerns (none for the IMU)."""
    a, b = (JOINT_NAMES[i] for i in rng.choice(len(JOINT_NAMES), 2, replace=False))
    if kind == "reversed":
        return HardwareFaults(reversed=(a,)), (a,)
    if kind == "horn_offset":  # past the tolerance (below it the calibration trims it), up to two splines
        magnitude = rng.uniform(zero_tolerance_deg + 1.0, 30.0) * rng.choice([-1.0, 1.0])
        return HardwareFaults(horn_offset_deg=((a, float(round(magnitude, 1))),)), (a,)
    if kind == "swapped_pwm":
        return HardwareFaults(swapped_pwm=((a, b),)), (a, b)
    if kind == "swapped_feedback":
        return HardwareFaults(swapped_feedback=((a, b),)), (a, b)
    if kind == "stuck_adc":
        return HardwareFaults(stuck_feedback_v=((a, float(round(rng.uniform(0.0, 3.3), 3))),)), (a,)
    if kind == "slow_servo":  # worn or wet: from a fifth of its speed to 0.6 (the check's limit is 0.7)
        return HardwareFaults(servo_speed_scale=((a, float(round(rng.uniform(0.2, 0.6), 2))),)), (a,)
    if kind == "imu_rotated":  # any proper rotation at least 15 deg from the identity
        axis = rng.normal(size=3)
        angle = rng.uniform(math.radians(15.0), math.pi)
        rpy = np.degrees(rot_to_rpy(exp_so3(axis / np.linalg.norm(axis) * angle)))
        return HardwareFaults(imu_mount_rpy_deg=tuple(float(round(v, 1)) for v in rpy)), ()
    raise ValueError("unknown fault kind %r" % kind)


def operator_readings(faults: HardwareFaults, rng: np.random.Generator, noise: float = 0.02) -> np.ndarray:
    """The IMU's specific force in the guided poses, held roughly by the operator, through the real mount."""
    mount = rpy_to_rot(*np.radians(faults.imu_mount_rpy_deg))
    rows = []
    for _, _, (roll_sign, pitch_sign) in GUIDED_POSES:
        tilted = bool(roll_sign or pitch_sign)
        tilt = math.radians(rng.uniform(20.0, 40.0)) if tilted else 0.0
        stray = np.radians(rng.uniform(-3.0, 3.0, 2) if tilted else rng.uniform(-1.0, 1.0, 2))
        body = expected_specific_force(roll_sign * tilt + stray[0], pitch_sign * tilt + stray[1])
        rows.append(mount.T @ body + rng.normal(0.0, noise, 3))
    return np.array(rows)


def run_case(seed: int, kind: Optional[str], settings: ServoCheckSettings = ServoCheckSettings()) -> Dict[str, Any]:
    """One seeded case (``kind`` None: fault-free): what was built, what each check said, the verdict."""
    rng = np.random.default_rng(seed)
    faults, concerned = draw_fault(rng, kind, settings.zero_tolerance_deg) if kind else (HardwareFaults(), ())
    hardware, calibration, params = load_hardware_config(), load_servo_calibration(), load_robot_params()
    rig = SimulatedServoRig(hardware, calibration, seed=seed, faults=faults)
    servo = run_on_rig(rig, hardware, calibration, params, settings)
    if servo.passed:
        speeds = speeds_on_rig(rig, hardware, servo.calibration, params, settings)
        servo.findings, servo.speeds = speeds.findings, speeds.speeds
    imu = check_imu_mount(operator_readings(faults, rng))
    if kind is None:
        detected = servo.passed and imu.passed  # "detected" here: all passed, no false alarm
    elif kind == "imu_rotated":
        detected = not imu.passed
    else:
        detected = set(concerned) <= set(servo.named())
    return OrderedDict([
        ("seed", seed), ("kind", kind or "none"), ("faults", faults.describe()), ("detected", bool(detected)),
        ("servo_findings", [str(f) for f in servo.findings]), ("imu_problems", imu.problems),
        ("imu_error_deg", None if math.isnan(imu.error_deg) else round(imu.error_deg, 2)),
        ("speed_fraction", {name: round(value, 3) for name, value in servo.speeds.items()}),
    ])


def study(cases: int, clean: int, seed: int) -> List[Dict[str, Any]]:
    """``cases`` faulty cases (kinds in turn, so each kind is drawn) and ``clean`` fault-free ones."""
    seeds = np.random.SeedSequence(seed).generate_state(cases + clean)
    rows = [run_case(int(s), KINDS[i % len(KINDS)]) for i, s in enumerate(seeds[:cases])]
    rows += [run_case(int(s), None) for s in seeds[cases:]]
    return rows


def table(rows: Sequence[Dict[str, Any]]) -> str:
    """Fault kind x detected, and the fault-free runs' false alarms."""
    lines = ["| fault kind | cases | detected | missed |", "|---|---|---|---|"]
    for kind in KINDS:
        mine = [r for r in rows if r["kind"] == kind]
        hits = sum(r["detected"] for r in mine)
        lines.append("| %s | %d | %d | %d |" % (kind, len(mine), hits, len(mine) - hits))
    clean = [r for r in rows if r["kind"] == "none"]
    alarms = sum(not r["detected"] for r in clean)
    lines.append("| none (fault-free) | %d | %d passed | %d false alarms |" % (len(clean), len(clean) - alarms, alarms))
    return "\n".join(lines) + "\n"


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the study; exit 1 when a fault is missed or a fault-free robot is refused."""
    parser = argparse.ArgumentParser(prog="python -m quadruped_control.studies.bringup_faults",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=40, help="faulty cases (kinds in turn)")
    parser.add_argument("--clean", type=int, default=20, help="fault-free cases")
    parser.add_argument("--seed", type=int, default=1, help="seed of the case seeds")
    parser.add_argument("--out", default="out/bringup", help="folder of the report")
    args = parser.parse_args(argv)
    if args.cases < 0 or args.clean < 0:
        parser.error("--cases and --clean must be >= 0")
    rows = study(args.cases, args.clean, args.seed)
    text = "# Calibration, speed and IMU checks against a robot built wrong\n\n" + table(rows)
    missed = [r for r in rows if not r["detected"]]
    for r in missed:
        text += "\n- seed %d, %s %s: servo %s; imu %s" % (r["seed"], r["kind"], r["faults"], r["servo_findings"],
                                                         r["imu_problems"])
    report = OrderedDict([("command", " ".join(["python -m quadruped_control.studies.bringup_faults"] +
                                               list(argv if argv is not None else sys.argv[1:]))),
                          ("cases", args.cases), ("clean", args.clean), ("seed", args.seed), ("rows", rows)])
    report.update(code_record())
    write_study_report(args.out, "bringup_faults", text + "\n", report)
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
