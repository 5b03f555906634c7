"""Whole-trial agreement of the batched simulator with the per-trial engine (docs/batch_simulation.md).

Run: .venv/bin/python benchmarks/batch_agreement.py [--plant paper|tank] [--duration 160] [--jobs 2]
     .venv/bin/python benchmarks/batch_agreement.py --study paper-sim
     .venv/bin/python benchmarks/batch_agreement.py --study schemes [--plant tank] [--jobs 2]
     .venv/bin/python benchmarks/batch_agreement.py --sensitivity "roll 45" "pitch 30"

The first form runs the 15 trials of Table 1 (experiment gains, rate-limited servos) on both engines and
prints, per trial, the settled outcome and the final smoothed geodesic error of each, then how many
outcomes agree and the worst difference. ``--sensitivity LABEL ...`` runs the per-trial engine from the
trial's nominal start and from starts tilted by +-1e-15 rad about the body x axis, beside the batch: how
much of the difference the per-trial engine shows against itself. ``--study schemes`` runs the schemes
study's ensemble (608 trials on the paper plant, both schemes; on the tank 304 with rate-limited servos)
on both engines and also compares the study's summary table (settled counts, medians) of the two.
"""
import argparse
import os
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.so3 import exp_so3, rpy_to_rot  # noqa: E402
from quadruped_control.sim.servo_model import make_servo_model  # noqa: E402
from quadruped_control.sim.simulation import ClosedLoopSimulation, load_simulation_tree  # noqa: E402
from quadruped_control.studies.paper_experiments import experiment_specs  # noqa: E402
from quadruped_control.studies.paper_sim import paper_sim_specs  # noqa: E402
from quadruped_control.studies.schemes import build_specs, compare, trial_row  # noqa: E402
from quadruped_control.studies.trial import run_batch, run_trial, trial_setup  # noqa: E402


def _outcome(metrics):
    return metrics["settled"], metrics["geodesic"]["final_smoothed_deg"]


def _tilted(args):
    spec, eps = args
    setup = trial_setup(spec)
    sim = ClosedLoopSimulation(setup.robot, setup.config, make_servo_model(spec.servo_model, setup.servo_params),
                               initial_R=rpy_to_rot(*np.radians(spec.initial_rpy_deg)) @ exp_so3([eps, 0.0, 0.0]),
                               setpoint_R=rpy_to_rot(*np.radians(spec.setpoint_rpy_deg)), model=setup.model)
    return _outcome(sim.run(spec.duration).metrics())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plant", choices=("paper", "tank"), default="paper")
    parser.add_argument("--duration", type=float, default=160.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--sensitivity", nargs="+", metavar="LABEL", default=None)
    parser.add_argument("--study", choices=("table1", "paper-sim", "schemes"), default="table1",
                        help="Table 1's 15 trials (default), the paper's simulation study (3 trials, 120 s, "
                             "simulation gains, ideal servos; --plant and --duration are ignored) or the "
                             "schemes study's ensemble (--duration is ignored)")
    args = parser.parse_args()
    study = argparse.Namespace(seed=0, tank_yaml=None, robot_yaml=None)
    if args.study == "paper-sim":
        study.duration_given, study.restoring_offset = False, None
        specs = paper_sim_specs(study, load_simulation_tree(), None, keep_trace=False)
        args.plant = "paper"
    elif args.study == "schemes":
        specs = build_specs(servos=("ideal", "rate-limited") if args.plant == "paper" else ("rate-limited",),
                            plant=args.plant)
    else:
        specs, _ = experiment_specs(study, args.plant, "experiment", "rate-limited", args.duration,
                                    keep_trace=False)
    if args.sensitivity:
        specs = [spec for spec in specs if spec.label in args.sensitivity]
        batch = run_batch(specs)
        with ProcessPoolExecutor(args.jobs) as pool:
            for spec, summary in zip(specs, batch):
                runs = list(pool.map(_tilted, [(spec, eps) for eps in (0.0, 1e-15, -1e-15)]))
                print("%-14s per-trial nominal / +1e-15 / -1e-15 rad: %s   batch: %s" % (
                    spec.label, " / ".join("%.2f deg %s" % (e, "settled" if s else "not settled") for s, e in runs),
                    "%.2f deg %s" % (_outcome(summary["metrics"])[1], "settled" if summary["metrics"]["settled"]
                                     else "not settled")))
        return
    batch = run_batch(specs)
    with ProcessPoolExecutor(args.jobs) as pool:
        single = list(pool.map(run_trial, specs))
    same, worst = 0, 0.0
    for spec, b, r in zip(specs, batch, single):
        (sb, eb), (sr, er) = _outcome(b["metrics"]), _outcome(r["metrics"])
        same += sb == sr
        worst = max(worst, abs(eb - er))
        print("%-14s settled batch %-5s per-trial %-5s final smoothed %.3f / %.3f deg" % (spec.label, sb, sr, eb, er))
    print("%s plant: same settled outcome %d / %d, worst final smoothed difference %.3f deg"
          % (args.plant, same, len(specs), worst))
    if args.study == "schemes":
        tables = [compare([trial_row(summary) for summary in summaries])["groups"] for summaries in (batch, single)]
        differences = []
        for group, by_scheme in tables[0].items():
            for scheme in ("paper", "coordinated"):
                for key, value in by_scheme[scheme].items():
                    other = tables[1][group][scheme][key]
                    if value != other and not (isinstance(value, float) and abs(value - other) <= 0.01):
                        differences.append("%s / %s / %s: batch %r, per-trial %r" % (group, scheme, key, value, other))
        print("schemes summary table: %s" % ("the same (medians within 0.01)" if not differences
                                              else "%d entries differ:\n  %s" % (len(differences),
                                                                                "\n  ".join(differences))))


if __name__ == "__main__":
    main()
