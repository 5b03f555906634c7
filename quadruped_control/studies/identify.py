"""Identification of the tank plant against the paper's Table 1 (``simulate --study identify``): :func:`main_study`.

1. Screening: Morris elementary effects over every coordinate of :data:`~.identify_parameters.PARAMETERS`
   (``--screen`` trajectories); those whose mu* reaches a tenth of the largest are fitted (plus ``--include``;
   or exactly ``--parameters``), the others stay at the ``--tank-yaml`` values.
2. Fit: CMA-ES over the fitted coordinates scaled to [0, 1] (``--evaluations`` sets, seeded) from the screening's
   best set (``--start nominal``: from the nominal values), then optionally a compass search
   (``--polish-evaluations``).
3. Cross-validation: per group of experiments (roll, pitch, coupled), the same fit on the other two predicts the
   held-out one, against a one-factor baseline (the paw drag scale fitted on a grid).
4. Ensemble: the best distinct sets of the full fit written as tank.yaml files; each fold's ensemble predicts its
   held-out group (the members' median) and its spread's coverage is counted.

Writes identify.json, sets.json, identify.md, identify.png and tank_ensemble_NN.yaml to ``--out``. The objective:
:mod:`.identify_objective`; the searches: :mod:`.identify_search`; the report: :mod:`.identify_report`; the
results so far: docs/identification.md.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any, Dict, List, Sequence, Tuple

from quadruped_common.config import config_path
from quadruped_control.sim.plants.tank_params import load_tank_params
from quadruped_control.studies import StudyError
from quadruped_control.studies.identify_objective import WEIGHTS, GROUPS, Evaluator, ensemble_prediction
from quadruped_control.studies.identify_parameters import PARAMETERS, nominal_values, update_tank_yaml
from quadruped_control.studies.identify_report import plot_report, report_text
from quadruped_control.studies.identify_search import (baseline, best_on, distinct_best, fit, improvements, polish,
                                                       screen)
from quadruped_control.studies.runner import code_record

__all__ = ["STARTS", "main_study"]

#: where every fit starts (``--start``): the screening's best set, or the nominal values of --tank-yaml
STARTS = ("screening", "nominal")

def _without_rows(result: Dict[str, Any]) -> Dict[str, Any]:
    return {k: v for k, v in result.items() if k != "rows"}


def main_study(args: argparse.Namespace) -> int:
    """Screen, fit and cross-validate the tank plant against Table 1 (module docstring)."""
    os.makedirs(args.out, exist_ok=True)
    duration = args.duration if args.duration_given else 160.0  # longest paper t_s 128.6 s + 30 s hold
    servo = args.servo_model_given or "rate-limited"
    start_time = time.perf_counter()
    evaluate = Evaluator(args, duration, servo, bool(getattr(args, "slow_recovery_check", False)))
    tank = load_tank_params(args.tank_yaml)
    nominal = nominal_values(tank)
    everything = evaluate.cases(GROUPS)

    screening = screen(evaluate, nominal, args.screen, args.seed, everything)
    largest = max(screening["mu_star"]) or 1.0
    include = set(getattr(args, "include", None) or ())
    exactly = set(getattr(args, "parameters", None) or ())
    chosen = [n for n, m in zip(screening["names"], screening["mu_star"])
              if (n in exactly if exactly else m >= 0.1 * largest or n in include)]
    if len(chosen) < 2:  # pycma does not fit one dimension (pycma issue 86); say so before the fit fails
        raise StudyError("identify: the screening chose %s; CMA-ES fits two or more parameters: add one with "
                         "--include or name them with --parameters" % (", ".join(chosen) or "no parameter"))
    start_from = getattr(args, "start", "screening")
    if start_from not in STARTS:
        raise StudyError("identify: --start is %s, got %r" % (" or ".join(map(repr, STARTS)), start_from))
    # The screening's best set varies every parameter it spans, so it (and every fit from it) changes when a
    # candidate is added to PARAMETERS, even for fits of the same few parameters; the nominal start does not
    # (docs/identification.md).
    start = screening["best"]["values"] if start_from == "screening" else nominal
    fixed = {n: (start[n] if n in chosen else nominal[n]) for n in nominal}
    polish_budget = int(getattr(args, "polish_evaluations", 0))

    def fit_and_polish(fit_start: Dict[str, float], budget: int, seed: int, cases: Sequence[int],
                       tag: str) -> Tuple[List[Dict[str, Any]], Dict[str, Any], Dict[str, Any]]:
        """The CMA-ES fit, then the compass search from its best set: every set, best first; what the
        polish did (its sets, the objective before and after); and how the search went (its sets in the
        order asked, CMA-ES's then the polish's: their number and :func:`improvements`)."""
        asked: List[float] = []

        def recorded(sets: Sequence[Dict[str, float]], cases: Sequence[int], tag: str) -> List[Dict[str, Any]]:
            results = evaluate(sets, cases, tag)
            asked.extend(r["objective"] for r in results)
            return results

        searched = fit(recorded, chosen, fixed, fit_start, budget, args.popsize, seed, cases, tag)
        polished = polish(recorded, chosen, fixed, searched[0], polish_budget, cases, tag + "-pol") \
            if polish_budget else []
        results = sorted(searched + polished, key=lambda r: r["objective"])
        return results, {"evaluations": len(polished), "objective_before": searched[0]["objective"],
                         "objective_after": results[0]["objective"]}, \
            {"sets": len(asked), "improvements": [list(i) for i in improvements(asked)]}

    full, full_polish, full_search = fit_and_polish(start, args.evaluations, args.seed, everything, "fit")
    best = full[0]
    folds = []
    for group in GROUPS:
        train = evaluate.cases([g for g in GROUPS if g != group])
        held = evaluate.cases([group])
        fold_start = best_on(screening["results"], train)["values"] if start_from == "screening" else nominal
        fold_results, fold_polish, fold_search = fit_and_polish(fold_start, args.cv_evaluations, args.seed + 1,
                                                                train, "cv-" + group)
        fold_fit = fold_results[0]
        slow = baseline(evaluate, nominal, train, args.popsize, "base-" + group)
        predicted, slow_predicted = evaluate([fold_fit["values"], slow["values"]], held, "held-" + group)
        # the fold's ensemble, chosen as the full fit's is, on the held-out group: its own tag, so that the
        # labels of the trials above stay as they were before it existed
        members = evaluate([r["values"] for r in distinct_best(fold_results, chosen, args.ensemble)], held,
                           "ens-" + group)
        folds.append({"held_out": group, "fit": _without_rows(fold_fit), "polish": fold_polish, "search": fold_search,
                      "prediction": predicted, "baseline_fit": _without_rows(slow),
                      "baseline_prediction": slow_predicted,
                      "ensemble_prediction": ensemble_prediction(members, evaluate.band)})
    ensemble = distinct_best(full, chosen, args.ensemble)
    wall = time.perf_counter() - start_time
    provenance = code_record()
    note = "simulate --study identify (%d trials, code %s)" % (evaluate.trials, provenance["code"][:12])
    with open(args.tank_yaml or config_path("tank.yaml")) as stream:
        template = stream.read()
    paths = []
    for i, result in enumerate(ensemble):
        path = os.path.join(args.out, "tank_ensemble_%02d.yaml" % i)
        # only the fitted parameters are marked [identified]: the others keep the template's line, which is
        # the value the fit held them at (nominal_values reads it from the same file)
        with open(path, "w") as stream:
            stream.write(update_tank_yaml(template, {name: result["values"][name] for name in chosen},
                                          "%s, ensemble member %d, objective %.2f" % (note, i, result["objective"])))
        paths.append(path)
    report = {"study": "identify", "command": getattr(args, "command", None), **provenance, "duration": duration,
              "servo_model": servo, "seed": args.seed, "start": start_from,
              "slow_recovery_check": bool(evaluate.check_row), "band": evaluate.band,
              "weights": WEIGHTS, "parameters": [list(p) for p in PARAMETERS], "nominal": nominal,
              "screening": {k: v for k, v in screening.items() if k not in ("best", "results")}, "identified": chosen,
              "fit": {"evaluations": len(full), "polish": full_polish, "search": full_search, "best": best,
                      "ensemble": [_without_rows(r) for r in ensemble]},
              "cross_validation": folds, "trials": evaluate.trials, "wall_time": wall, "ensemble_files": paths,
              "failed_sets": evaluate.failed_sets, "failed_examples": evaluate.failed_examples}
    with open(os.path.join(args.out, "identify.json"), "w") as stream:
        json.dump(report, stream, indent=1, allow_nan=False)
    with open(os.path.join(args.out, "sets.json"), "w") as stream:
        json.dump(dict(provenance, sets=evaluate.sets), stream, allow_nan=False)
    plot_report(report, os.path.join(args.out, "identify.png"))
    text = report_text(report, best)
    with open(os.path.join(args.out, "identify.md"), "w") as stream:
        stream.write(text)
    print(text)
    return 0
