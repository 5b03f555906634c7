"""A profile of one tank parameter: an identification's fit and cross-validation again, with that parameter
held at each of a few values.

    python -m quadruped_control.studies.profile REPORT --parameter NAME --values V [V ...]
        [--evaluations 200] [--cv-evaluations 200] [--sigma 0.1] [--popsize 16] [--jobs 2] [--out DIR]

``REPORT`` is the ``identify.json`` of an identification (:mod:`quadruped_control.studies.identify`). For
each value v, with NAME held at v:

- the full fit: CMA-ES over the report's other identified parameters (scaled to [0, 1], step ``--sigma``)
  on all fifteen experiments, from the report's best set;
- the cross-validation: for each group, the same refit on the other two groups from the report's fold
  fit for that group, predicting the held-out group.

The parameters the report did not identify keep the report's values. The trials, experiments, duration,
servos, seed, objective band and slow-recovery checks are the report's, and every trial runs on this
code. A profile answers two questions. How well does Table 1 pin NAME down? The in-sample objective
against v: a flat profile means the data do not constrain it, whatever the free fit chose. What will the
model predict once NAME is measured? The held-out counts at v. A measured value then enters the tank yaml
(``--tank-yaml`` of the identification) and drops out of the fit. This is the profile likelihood of
Raue et al., "Structural and practical identifiability analysis of partially observed dynamical models
by exploiting the profile likelihood", Bioinformatics 25 (2009), with the objective in place of the
likelihood.

First the report's own best set and fold fits run again on this code: the profile's reference, and a
check that the trials reproduce the report's. ``--tank-yaml`` must be the identification's own (its
parameters' values there are checked against the report's ``nominal``).

Output in ``--out``: ``profile.md`` (the table), ``profile.json`` (everything, each fit's per-case rows
included, the command, the report's sha256 and the code's fingerprint) and ``profile.png`` (the
objective and the held-out counts against v). The trials are kept under ``--out`` as a study's are, so an
interrupted profile resumes.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time
from typing import Any, Dict, List, Optional, Sequence

from quadruped_common.config import ParameterError
from quadruped_control.sim.plants.tank_params import load_tank_params
from quadruped_control.studies import StudyError
from quadruped_control.studies.identify_objective import GROUPS, Evaluator
from quadruped_control.studies.identify_parameters import BOUNDS, nominal_values
from quadruped_control.studies.identify_search import fit
from quadruped_control.studies.runner import code_record, command_line, warn_uncommitted

__all__ = ["COUNTS", "check_base", "check_values", "load_report", "main", "plot_profile", "profile", "profile_point",
           "summed_targets"]

#: The held-out counts of the reproduction targets, summed over the folds.
COUNTS = ("same_outcome", "t_s_within_2x", "t_r_within_2x", "yaw_t_s_within_2x", "yaw_t_s_reported", "cases")


def load_report(path: str) -> Dict[str, Any]:
    """An identification's ``identify.json``, checked for what a profile reads; :class:`StudyError` names
    what is missing."""
    try:
        with open(path) as stream:
            report = json.load(stream)
    except (OSError, ValueError) as exc:
        raise StudyError("profile: cannot read the identification report %s: %s" % (path, exc)) from exc
    if not isinstance(report, dict) or report.get("study") != "identify":
        raise StudyError("profile: %s is not an identification report (identify.json)" % path)
    for key in ("identified", "fit", "cross_validation", "seed", "duration", "servo_model"):
        if key not in report:
            raise StudyError("profile: %s has no %r" % (path, key))
    groups = [fold.get("held_out") for fold in report["cross_validation"]]
    if sorted(groups) != sorted(GROUPS):
        raise StudyError("profile: %s holds out %s, not the three groups %s" % (path, groups, list(GROUPS)))
    return report


def check_values(name: str, values: Sequence[float]) -> None:
    """:class:`StudyError` unless every value is finite and inside ``name``'s bounds (identify.PARAMETERS)."""
    low, high = BOUNDS[name]
    for value in values:
        if not (math.isfinite(value) and low <= value <= high):
            raise StudyError("profile: %s = %r lies outside its bounds %g .. %g" % (name, value, low, high))


def check_base(report: Dict[str, Any], tank_yaml: Optional[str]) -> None:
    """:class:`StudyError` unless ``tank_yaml`` (None: config/tank.yaml) holds the values the report's
    identification started from (its ``nominal``): the profile's trials read that file for everything the
    fit does not set, so another file would profile another model."""
    try:
        nominal = nominal_values(load_tank_params(tank_yaml))
    except (ParameterError, OSError) as exc:
        raise StudyError("profile: cannot load the tank parameters %s: %s" % (tank_yaml, exc)) from exc
    differ = [name for name, value in report.get("nominal", {}).items()
              if name in nominal and not math.isclose(nominal[name], float(value), rel_tol=1e-9, abs_tol=1e-12)]
    if differ:
        raise StudyError("profile: %s is not the tank yaml the identification started from (%s differ from the "
                         "report's nominal values): pass its own --tank-yaml"
                         % (tank_yaml or "config/tank.yaml", ", ".join(sorted(differ))))


def summed_targets(folds: Sequence[Dict[str, Any]]) -> Dict[str, int]:
    """The held-out counts (:data:`COUNTS`) summed over the folds' predictions."""
    return {key: sum(int(fold["prediction"]["targets"][key]) for fold in folds) for key in COUNTS}


def profile_point(evaluate: Any, report: Dict[str, Any], name: str, value: float, evaluations: int,
                  cv_evaluations: int, popsize: int, sigma: float) -> Dict[str, Any]:
    """The full fit and the three folds with ``name`` held at ``value`` (module docstring)."""
    names = [n for n in report["identified"] if n != name]
    if len(names) < 2:  # pycma does not fit one dimension (pycma issue 86)
        raise StudyError("profile: holding %s leaves %s to fit; CMA-ES fits two or more parameters"
                         % (name, ", ".join(names) or "no parameter"))
    seed = int(report["seed"])
    tag = "pro%s=%g" % (name, value)
    start = dict(report["fit"]["best"]["values"], **{name: value})
    full = fit(evaluate, names, start, start, evaluations, popsize, seed, evaluate.cases(GROUPS), tag, sigma)
    folds = []
    for fold in report["cross_validation"]:
        group = fold["held_out"]
        train = evaluate.cases([g for g in GROUPS if g != group])
        fold_start = dict(fold["fit"]["values"], **{name: value})
        fold_fit = fit(evaluate, names, fold_start, fold_start, cv_evaluations, popsize, seed + 1, train,
                       tag + " cv-" + group, sigma)[0]
        predicted = evaluate([fold_fit["values"]], evaluate.cases([group]), tag + " held-" + group)[0]
        folds.append({"held_out": group, "fit": {k: v for k, v in fold_fit.items() if k != "rows"},
                      "prediction": predicted})
    return {"value": value, "fit": {"evaluations": len(full), "best": full[0]}, "cross_validation": folds,
            "held_out": summed_targets(folds),
            "held_out_objective": float(sum(fold["prediction"]["objective"] for fold in folds))}


def profile(evaluate: Any, report: Dict[str, Any], name: str, values: Sequence[float], evaluations: int,
            cv_evaluations: int, popsize: int, sigma: float) -> List[Dict[str, Any]]:
    """:func:`profile_point` at each of ``values``, after checking them against ``name``'s bounds."""
    check_values(name, values)
    return [profile_point(evaluate, report, name, float(v), evaluations, cv_evaluations, popsize, sigma)
            for v in values]


def plot_profile(result: Dict[str, Any], path: str) -> None:
    """The in-sample and summed held-out objectives, and the held-out counts, against the held value; the
    report's free fit marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points = sorted(result["points"], key=lambda p: p["value"])
    values = [p["value"] for p in points]
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    left.plot(values, [p["fit"]["best"]["objective"] for p in points], "o-", label="full fit, in sample")
    left.plot(values, [p["held_out_objective"] for p in points], "s-", label="held out, summed over the folds")
    free = result["free"]
    left.plot([free["value"]], [free["objective"]], "k*", ms=12, label="the report's free fit, in sample")
    left.plot([free["value"]], [free["held_out_objective"]], "kP", ms=10, label="the report's free fit, held out")
    left.set(xlabel=result["parameter"], ylabel="objective (lower is better)")
    left.legend(fontsize=8)
    for key, label, target in (("same_outcome", "same outcome", 13), ("t_s_within_2x", "t_s within 2x", 10),
                               ("t_r_within_2x", "t_r within 2x", 10), ("yaw_t_s_within_2x", "yaw t_s within 2x", 8)):
        line, = right.plot(values, [p["held_out"][key] for p in points], "o-", label=label)
        right.axhline(target, color=line.get_color(), ls=":", lw=1)
    right.set(xlabel=result["parameter"], ylabel="held out, of 15 (yaw: of those reported)",
              title="held-out counts (dotted: the targets)")
    right.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _text(result: Dict[str, Any]) -> str:
    free = result["free"]
    lines = ["## Profile of %s: %d trials, %.0f s wall" % (result["parameter"], result["trials"], result["wall_time"]),
             "",
             "Held at each value, the other identified parameters (%s) refitted: full fit %d sets, each fold %d "
             "sets, CMA-ES step %g. The report's free fit: %s = %.4g, objective %.2f in sample, %.2f held out."
             % (", ".join(n for n in result["identified"] if n != result["parameter"]), result["evaluations"],
                result["cv_evaluations"], result["sigma"], result["parameter"], free["value"], free["objective"],
                free["held_out_objective"]), "",
             "| %s | objective in sample | outcome / t_s / t_r / yaw t_s in sample | objective held out | "
             "held out: outcome | t_s within 2x | t_r within 2x | yaw t_s within 2x |" % result["parameter"],
             "|---|---|---|---|---|---|---|---|"]
    for point in sorted(result["points"], key=lambda p: p["value"]):
        best, held = point["fit"]["best"], point["held_out"]
        t = best["targets"]
        lines.append("| %.4g | %.2f | %d / %d / %d / %d | %.2f | %d of %d | %d | %d | %d of %d |" % (
            point["value"], best["objective"], t["same_outcome"], t["t_s_within_2x"], t["t_r_within_2x"],
            t["yaw_t_s_within_2x"], point["held_out_objective"], held["same_outcome"], held["cases"],
            held["t_s_within_2x"], held["t_r_within_2x"], held["yaw_t_s_within_2x"], held["yaw_t_s_reported"]))
    return "\n".join(lines) + "\n"


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("report", help="an identification's identify.json")
    parser.add_argument("--parameter", required=True, choices=sorted(BOUNDS), metavar="NAME",
                        help="the parameter to hold (one of identify.PARAMETERS)")
    parser.add_argument("--values", required=True, nargs="+", type=float, metavar="V", help="values to hold it at")
    parser.add_argument("--evaluations", type=int, default=200, help="sets per full fit (default %(default)s)")
    parser.add_argument("--cv-evaluations", type=int, default=200, help="sets per fold (default %(default)s)")
    parser.add_argument("--sigma", type=float, default=0.1,
                        help="CMA-ES step, of each parameter's range (default %(default)s: a refit near the "
                             "report's sets)")
    parser.add_argument("--popsize", type=int, default=16, help="CMA-ES population (default %(default)s)")
    parser.add_argument("--tank-yaml", default=None,
                        help="the identification's base tank parameters (default: config/tank.yaml)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default %(default)s)")
    parser.add_argument("--out", default="out/profile", help="output folder (default %(default)s)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    if args.evaluations < 1 or args.cv_evaluations < 1 or args.popsize < 2 or args.jobs < 1:
        parser.error("--evaluations and --cv-evaluations must be >= 1, --popsize >= 2, --jobs >= 1")
    if not (math.isfinite(args.sigma) and 0.0 < args.sigma <= 0.5):
        parser.error("--sigma must lie in (0, 0.5], a step of the scaled [0, 1] range; got %r" % args.sigma)
    warn_uncommitted()  # before any trial runs: a dirty tree's figures name no commit
    try:
        report = load_report(args.report)
        check_values(args.parameter, args.values)  # before any trial runs
        check_base(report, args.tank_yaml)
        os.makedirs(args.out, exist_ok=True)
        start_time = time.perf_counter()
        study = argparse.Namespace(seed=int(report["seed"]), tank_yaml=args.tank_yaml, robot_yaml=None,
                                   band=float(report.get("band", 1.0)), engine="auto", batch_size=1500,
                                   jobs=args.jobs, dask_scheduler=None, resume=True, quiet=args.quiet, out=args.out)
        evaluate = Evaluator(study, float(report["duration"]), str(report["servo_model"]),
                             bool(report.get("slow_recovery_check", False)))
        # the report's free fit again on this code: the profile's reference, and a check that the trials
        # reproduce the report's
        free_best = report["fit"]["best"]["values"]
        free = evaluate([free_best], evaluate.cases(GROUPS), "free")[0]
        free_folds = [{"held_out": fold["held_out"],
                       "prediction": evaluate([fold["fit"]["values"]], evaluate.cases([fold["held_out"]]),
                                              "free held-" + fold["held_out"])[0]}
                      for fold in report["cross_validation"]]
        points = profile(evaluate, report, args.parameter, args.values, args.evaluations, args.cv_evaluations,
                         args.popsize, args.sigma)
    except StudyError as exc:
        print(str(exc), file=sys.stderr)
        return 1
    with open(args.report, "rb") as stream:
        report_sha = hashlib.sha256(stream.read()).hexdigest()
    result = {"study": "profile", "command": command_line("quadruped_control.studies.profile", argv),
              "report": os.path.abspath(args.report), "report_sha256": report_sha, **code_record(),
              "parameter": args.parameter, "identified": list(report["identified"]),
              "evaluations": args.evaluations, "cv_evaluations": args.cv_evaluations, "sigma": args.sigma,
              "popsize": args.popsize,
              "free": {"value": float(free_best[args.parameter]), "objective": free["objective"],
                       "report_objective": float(report["fit"]["best"]["objective"]), "targets": free["targets"],
                       "held_out": summed_targets(free_folds),
                       "held_out_objective": float(sum(f["prediction"]["objective"] for f in free_folds)),
                       "report_held_out_objective": float(sum(f["prediction"]["objective"]
                                                              for f in report["cross_validation"]))},
              "points": points, "trials": evaluate.trials, "wall_time": time.perf_counter() - start_time}
    with open(os.path.join(args.out, "profile.json"), "w") as stream:
        json.dump(result, stream, indent=1, allow_nan=False)
    plot_profile(result, os.path.join(args.out, "profile.png"))
    text = _text(result)
    with open(os.path.join(args.out, "profile.md"), "w") as stream:
        stream.write(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
