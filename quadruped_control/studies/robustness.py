"""Robustness of the paper's simulation study: ``simulate --study robustness``.

The paper-sim setpoints under +-0.5 degree initial-attitude perturbations (several seeds), with the
experiment gains (ideal and rate-limited servos), with the normalised force direction, with the
rate-limited servo, and with the estimated robot parameters that matter varied (paw net buoyancy, leg
pairing, nominal foot height): ``DIR/robustness.json`` and ``DIR/robustness.md``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from typing import List, Tuple

import numpy as np

from quadruped_common.config import config_path
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.simulation import SIMULATION_SCHEMA, load_simulation_tree
from quadruped_control.studies.paper_sim import paper_sim_specs
from quadruped_control.studies.trial import TrialSpec, format_value, run_many


def main_study(args: argparse.Namespace) -> int:
    """Run the study (exit status 0; the table says which variants settle)."""
    os.makedirs(args.out, exist_ok=True)
    tree = load_simulation_tree()
    values = SIMULATION_SCHEMA.read(tree)  # the file's values, else the schema's defaults
    delta = float(values["robustness.initial_perturbation_deg"])
    seeds = [int(s) for s in values["robustness.seeds"]]
    base_initial = np.array([float(v) for v in values["paper_sim.initial_rpy_deg"]])
    variants: List[Tuple[str, List[TrialSpec]]] = []
    variants.append(("baseline (sim gains, ideal servos)", paper_sim_specs(args, tree, None, "base ")))
    for seed in seeds:
        rng = np.random.default_rng(seed)
        initial = tuple((base_initial + rng.uniform(-delta, delta, 3)).tolist())
        variants.append(("initial +-%g deg, seed %d" % (delta, seed),
                         paper_sim_specs(args, tree, None, "seed%d " % seed, initial_rpy_deg=initial, seed=seed)))
    variants.append(("experiment gains, ideal servos",
                     paper_sim_specs(args, tree, None, "exp ", gains="experiment")))
    variants.append(("experiment gains, rate-limited servos",
                     paper_sim_specs(args, tree, None, "exp-servo ", gains="experiment", servo_model="rate-limited")))
    variants.append(("sim gains, rate-limited servos",
                     paper_sim_specs(args, tree, None, "servo ", servo_model="rate-limited")))
    variants.append(("sim gains, normalised force direction",
                     paper_sim_specs(args, tree, None, "norm ", normalize_force=True)))
    # Sensitivity to the estimated parameters of config/robot.yaml (see docs/simulation_study.md).
    robot = load_robot_params(args.robot_yaml)
    neutral_mass = robot.rho * robot.paw_volume
    nominal = np.asarray(robot.nominal_foot_leg, dtype=float)
    variants.append(("paws neutrally buoyant (m_s = rho V_s)",
                     paper_sim_specs(args, tree, None, "neutral ", robot_overrides=(("paw_mass", neutral_mass),))))
    variants.append(("paws twice as heavy in water",
                     paper_sim_specs(args, tree, None, "heavy ", robot_overrides=(
                         ("paw_mass", neutral_mass + 2.0 * (robot.paw_mass - neutral_mass)),))))
    variants.append(("paper's literal pairs (1,2), (3,4)",
                     paper_sim_specs(args, tree, None, "pairs12 ", config_overrides=(("pairs", ((1, 2), (3, 4))),))))
    for dz in (-0.01, 0.01):
        foot = tuple((nominal + np.array([0.0, 0.0, dz])).tolist())
        variants.append(("nominal foot %+.0f cm in z" % (100 * dz),
                         paper_sim_specs(args, tree, None, "foot%+g " % dz,
                                          robot_overrides=(("nominal_foot_leg", foot),))))
    specs = [dataclasses.replace(spec, keep_trace=False) for _, group in variants for spec in group]
    start = time.perf_counter()
    summaries = run_many(specs, args, "robustness")
    wall = time.perf_counter() - start
    rows = []
    index = 0
    for name, group in variants:
        for spec in group:
            s = summaries[index]
            index += 1
            m = s["metrics"]
            rows.append({
                "variant": name, "setpoint_deg": spec.setpoint_rpy_deg[0],
                "initial_rpy_deg": list(spec.initial_rpy_deg), "settled": m["settled"],
                "geodesic_max_last_30s_deg": m["geodesic"]["max_smoothed_last_30s_deg"],
                "geodesic_mean_last_10pct_deg": m["geodesic"]["mean_smoothed_last_10pct_deg"],
                "t_s_max": None if any(m[a]["t_s"] is None for a in ("roll", "pitch", "yaw"))
                else max(m[a]["t_s"] for a in ("roll", "pitch", "yaw")),
                "e_ss_deg": [m[a]["e_ss"] for a in ("roll", "pitch", "yaw")],
                "M_p": [m[a]["M_p"] for a in ("roll", "pitch", "yaw")],
                "metrics": m,
            })
    table = ["| variant | setpoint [deg] | settled | max smoothed geodesic error, last 30 s [deg] | "
             "mean, last 10 % [deg] | max t_s [s] | e_ss roll/pitch/yaw [deg] |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        table.append("| %s | %g | %s | %.2f | %.2f | %s | %s |" % (
            r["variant"], r["setpoint_deg"], "yes" if r["settled"] else "no", r["geodesic_max_last_30s_deg"],
            r["geodesic_mean_last_10pct_deg"], format_value(r["t_s_max"], "%.1f"),
            " / ".join(format_value(v) for v in r["e_ss_deg"])))
    with open(os.path.join(args.out, "robustness.json"), "w") as stream:
        json.dump({"study": "robustness", "wall_time": wall, "robot_yaml": args.robot_yaml or config_path("robot.yaml"),
                   "nominal_foot_leg": [float(v) for v in robot.nominal_foot_leg], "rows": rows},
                  stream, indent=2, allow_nan=False)
    with open(os.path.join(args.out, "robustness.md"), "w") as stream:
        stream.write("\n".join(table) + "\n")
    print("\n".join(table))
    print("\n%d trials in %.1f s wall; results in %s" % (len(rows), wall, args.out))
    return 0
