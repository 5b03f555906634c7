"""The paper's simulation study (section "Simulation Validation"): ``simulate --study paper-sim``.

Setpoints 15, 45 and 75 degrees applied simultaneously to roll, pitch and yaw, simulation gains (K_p = 5,
K_i = 0.15, K_d = 1, K_aw = 0.25, t_rec = 1.5 s), RK4 at 0.01 s. The paper gives neither the initial
attitude nor the trial length: level at rest and 120 s (``paper_sim`` in config/simulation.yaml). Writes
``DIR/paper_sim.png`` (three trials in one figure), ``DIR/study.json`` and each trial's files in
``DIR/trial_<deg>/``. :func:`paper_sim_specs` also serves the robustness study.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any, Dict, List, Optional

from quadruped_common.config import config_path
from quadruped_control.sim.simulation import SIMULATION_SCHEMA, load_simulation_tree
from quadruped_control.studies.trial import GAIN_ALIASES, TrialSpec, format_metrics_table, run_many, without_trace


def paper_sim_specs(args: argparse.Namespace, tree: Dict[str, Any], out: Optional[str],
                    label_prefix: str = "", **overrides: Any) -> List[TrialSpec]:
    """The three trials of the paper's study (config ``paper_sim``), with ``overrides`` of TrialSpec fields."""
    values = SIMULATION_SCHEMA.read(tree)  # the file's values, else the schema's defaults
    setpoints = [float(v) for v in values["paper_sim.setpoints_deg"]]
    initial = tuple(float(v) for v in values["paper_sim.initial_rpy_deg"])
    duration = args.duration if args.duration_given else float(values["paper_sim.duration"])
    specs = []
    for amplitude in setpoints:
        fields = dict(label="%s%g deg" % (label_prefix, amplitude), setpoint_rpy_deg=(amplitude,) * 3,
                      initial_rpy_deg=initial, duration=duration, gains=str(values["paper_sim.gains"]),
                      servo_model="ideal", seed=args.seed,
                      restoring_offset=tuple(args.restoring_offset) if args.restoring_offset else None,
                      out_dir=os.path.join(out, "trial_%g" % amplitude) if out else None,
                      robot_yaml=args.robot_yaml, quiet=True)
        fields.update(overrides)
        specs.append(TrialSpec(**fields))
    return specs


def main_study(args: argparse.Namespace) -> int:
    """Run the study; exit status 0 when all three trials settle, 2 otherwise."""
    from quadruped_control.analysis.plotting import Trace, plot_trials

    os.makedirs(args.out, exist_ok=True)
    tree = load_simulation_tree()
    specs = paper_sim_specs(args, tree, args.out, gains=GAIN_ALIASES[args.gains], servo_model=args.servo_model,
                             normalize_force=args.normalize_force, scheme=args.scheme, plant=args.plant or "paper",
                             tank_yaml=args.tank_yaml)
    start = time.perf_counter()
    summaries = run_many(specs, args, "paper-sim")
    wall = time.perf_counter() - start
    traces = [Trace(s["trace"]["t"], s["trace"]["rpy"], s["trace"]["setpoint"], s["trace"]["geodesic"],
                    label=s["label"]) for s in summaries]
    figure = os.path.join(args.out, "paper_sim.png")
    plot_trials(traces, figure, title="Closed-loop simulation: setpoints on roll, pitch and yaw (%s gains, %s servos)"
                % (specs[0].gains, specs[0].servo_model))
    study = {"study": "paper-sim", "figure": figure, "wall_time": wall,
             "robot_yaml": args.robot_yaml or config_path("robot.yaml"),
             "all_settled": all(s["metrics"]["settled"] for s in summaries),
             "trials": [without_trace(s) for s in summaries]}
    with open(os.path.join(args.out, "study.json"), "w") as stream:
        json.dump(study, stream, indent=2, allow_nan=False)
    for s in summaries:
        print(format_metrics_table(s["metrics"], "trial %s (%.0fx real time)" % (s["label"], s["real_time_factor"])))
        print()
    print("figure: %s\nstudy: %s\nall trials settled: %s (%.1f s wall)"
          % (figure, os.path.join(args.out, "study.json"), study["all_settled"], wall))
    return 0 if study["all_settled"] else 2
