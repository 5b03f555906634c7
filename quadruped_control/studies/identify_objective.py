"""The identification's objective: what a tank parameter set costs against the paper's Table 1.

Lower is better, summed over the experiments with the weights of :data:`WEIGHTS` (:func:`case_cost`): on the
commanded axis (coupled cases: the worse of roll and pitch) 1 if the settled / not-settled outcome differs,
|ln(t_s ratio)| if both settled, |ln(t_r ratio)| (0.5 s floor; 1 if the simulation never rose), |e_ss
difference| / 5 deg and |M_p difference| / 50 %; on yaw the same t_s and t_r terms (where the paper reports
them) with weight 1/2. With a ``band`` F > 1 each timing term counts only what lies outside a factor F of the
paper's. A slow-recovery check (the paper's t_rec = 1.5 s cases, where the robot did not settle) costs one
outcome if the simulation settles (:func:`slow_recovery_cost`); an experiment whose trial cannot run to its
end costs :data:`FAILED_CASE_COST`. :class:`Evaluator` runs sets on the batched simulator and scores them;
:func:`targets` counts the reproduction targets; :func:`ensemble_prediction` scores an ensemble's median.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from quadruped_control.studies import paper_experiments as pe
from quadruped_control.studies.identify_parameters import tank_overrides
from quadruped_control.studies.paper_experiments import experiment_specs
from quadruped_control.studies.trial import TrialSpec, run_batch, run_many

__all__ = ["FAILED_CASE_COST", "GROUPS", "WEIGHTS", "Evaluator", "case_cost", "coverage", "ensemble_prediction",
           "ensemble_rows", "objective", "signed_log_ratio", "slow_recovery_cost", "targets"]

#: Weights of the objective's terms (module docstring).
WEIGHTS: Dict[str, float] = {"outcome": 1.0, "t_s": 1.0, "t_r": 1.0, "e_ss": 1.0, "M_p": 1.0,
                             "yaw_t_s": 0.5, "yaw_t_r": 0.5, "slow_recovery": 1.0}

#: The three groups of Table 1 (the folds of the cross-validation).
GROUPS = ("roll", "pitch", "roll+pitch")


def signed_log_ratio(a: float, b: float) -> float:
    """ln(a / b) with both times floored at 0.5 s."""
    return math.log(max(a, 0.5) / max(b, 0.5))


def _log_ratio(a: float, b: float, band: float = 1.0) -> float:
    """|ln(a / b)| (0.5 s floor) beyond a factor ``band``: max(0, |ln(a / b)| - ln band); band 1 is
    |ln(a / b)| bit for bit."""
    return max(0.0, abs(signed_log_ratio(a, b)) - math.log(band))


def case_cost(row: Dict[str, Any], weights: Optional[Dict[str, float]] = None, band: float = 1.0) -> float:
    """Cost of one experiment (a row of :func:`paper_experiments.comparison_rows`; module docstring), its
    timing terms counted beyond a factor ``band`` of the paper's (1: all of them)."""
    w = WEIGHTS if weights is None else weights
    p, s = row["paper"], row["sim"]
    cost = 0.0
    if row["settled_paper"] != row["settled_sim"]:
        cost += w["outcome"]
    elif p["t_s"] is not None and s["t_s"] is not None:
        cost += w["t_s"] * _log_ratio(s["t_s"], p["t_s"], band)
    if p["t_r"] is not None and s["t_r"] is not None:
        cost += w["t_r"] * _log_ratio(s["t_r"], p["t_r"], band)
    elif p["t_r"] is not None:
        cost += w["t_r"]  # never rose
    if s["e_ss"] is not None:
        cost += w["e_ss"] * abs(s["e_ss"] - p["e_ss"]) / 5.0
    if s["M_p"] is not None and p["M_p"] is not None:
        cost += w["M_p"] * abs(s["M_p"] - p["M_p"]) / 50.0
    py, sy = p.get("yaw"), s.get("yaw")
    if py is not None and sy is not None:
        if py["t_s"] is not None:
            cost += w["yaw_t_s"] * (_log_ratio(sy["t_s"], py["t_s"], band) if sy["t_s"] is not None else 1.0)
        if py["t_r"] is not None:
            cost += w["yaw_t_r"] * (_log_ratio(sy["t_r"], py["t_r"], band) if sy["t_r"] is not None else 1.0)
    return cost


def objective(rows: Sequence[Dict[str, Any]]) -> float:
    return float(sum(case_cost(r) for r in rows))


def targets(rows: Sequence[Dict[str, Any]], failed: Sequence[Dict[str, Any]] = ()) -> Dict[str, int]:
    """The reproduction targets' counts: same settled outcome; t_s, t_r and yaw t_s within a factor 2 of the paper's
    (:func:`paper_experiments.within_factor`: a reported 0.00 is met by a simulated 0.00 alone; yaw over the
    cases where the paper reports one). ``failed``: the Table-1 rows (``paper_experiments.PAPER_TABLE``
    entries) of experiments whose trial could not run to its end, counted among the cases and missed in
    every count."""
    return {"cases": len(rows) + len(failed),
            "same_outcome": sum(r["settled_paper"] == r["settled_sim"] for r in rows),
            "t_s_within_2x": sum(pe.within_factor(r["sim"]["t_s"], r["paper"]["t_s"]) for r in rows),
            "t_r_within_2x": sum(pe.within_factor(r["sim"]["t_r"], r["paper"]["t_r"]) for r in rows),
            "yaw_t_s_within_2x": sum(pe.within_factor(r["sim"]["yaw"]["t_s"], r["paper"]["yaw"]["t_s"])
                                     for r in rows),
            "yaw_t_s_reported": (sum(r["paper"]["yaw"]["t_s"] is not None for r in rows)
                                 + sum(r["yaw_t_s"] is not None for r in failed)),
            "failed": len(failed)}


#: The cost of an experiment (or slow-recovery check) whose trial could not run to its end: its plant
#: diverged, or (batched engine) the robot's controller would have refused a measurement and held. The fits
#: rank sets (CMA-ES by rank; the compass search keeps the lower), so it only has to exceed what an experiment
#: that runs can cost: ln(160 s / 0.5 s) = 5.8 for the outcome or t_s, as much for t_r, 180 deg / 5 = 36 for
#: e_ss, 2 x 2.9 for yaw: 53, and the overshoot's term reaches the rest only past 2,300 % of the command.
FAILED_CASE_COST = 100.0


def slow_recovery_cost(settled: bool, weights: Optional[Dict[str, float]] = None) -> float:
    """Cost of a slow-recovery check (:func:`paper_experiments.slow_recovery_specs`): the real robot did not
    settle with t_rec = 1.5 s, so a simulation that settles costs one outcome, weighted ``slow_recovery``."""
    return (WEIGHTS if weights is None else weights)["slow_recovery"] if settled else 0.0


class Evaluator:
    """Runs parameter sets on chosen experiments and keeps every result.

    The experiments are numbered as the rows of Table 1 (0-14); with ``slow_recovery`` the paper's t_rec
    observation adds the trials of :func:`paper_experiments.slow_recovery_specs` as 15, 16, ... (their
    costs: :func:`slow_recovery_cost`). Each result holds ``rows`` (the comparison rows of its Table-1
    experiments), ``slow_recovery`` (per check: its label and whether the simulation settled), and
    ``cases`` with their ``costs`` (the objective is their sum), and ``failed``: the experiments whose trial
    could not run to its end (case number, trial label, reason), each costing :data:`FAILED_CASE_COST`. A
    diverging set thus scores badly instead of stopping the study (a screening once stopped at one); :attr:`failed_sets` counts such sets."""

    def __init__(self, args: argparse.Namespace, duration: float, servo: str, slow_recovery: bool = False) -> None:
        self.args, self.duration, self.servo = args, duration, servo
        #: the objective's band (:func:`case_cost`; 1: the plain log-ratios)
        self.band = float(getattr(args, "band", 1.0))
        #: parameter sets run so far per tag: a trial's label numbers its set within its own search, so a
        #: search's labels do not depend on what ran before it, and an earlier run's trials come from the
        #: trial cache when the same command adds a search (a polish) between them
        self.count_of: Dict[str, int] = {}
        self.trials = 0
        #: parameter sets with at least one experiment that could not run to its end, and the first few of
        #: them (values and failures) for the report
        self.failed_sets = 0
        self.failed_examples: List[Dict[str, Any]] = []
        #: every set run, in order: its trials' label prefix (``set``: tag and number), values, objective and
        #: counts, so that an analysis of the kept trials can join each one to the set that produced it
        self.sets: List[Dict[str, Any]] = []
        # the 15 specs once (their initial attitudes take a search); each set replaces label and overrides
        self.base = [dataclasses.replace(spec, on_failure="record") for spec in
                     experiment_specs(args, "tank", "experiment", servo, duration, keep_trace=False)[0]]
        #: check number (15, 16, ...) -> its Table-1 row
        self.check_row: Dict[int, int] = {}
        for row, spec in (pe.slow_recovery_specs(self.base) if slow_recovery else []):
            self.check_row[len(self.base)] = row
            self.base.append(spec)
        # Compile (or load) the batch's loops here once: the worker processes forked for each generation
        # then start with them in memory instead of loading them again.
        run_batch([dataclasses.replace(self.base[0], duration=0.05)])

    def __call__(self, sets: Sequence[Dict[str, float]], cases: Sequence[int], tag: str) -> List[Dict[str, Any]]:
        specs: List[TrialSpec] = []
        prefixes = []
        for values in sets:
            self.count_of[tag] = number = self.count_of.get(tag, 0) + 1
            prefixes.append("%s%05d" % (tag, number))
            overrides = tank_overrides(values)
            specs += [dataclasses.replace(self.base[k], label="%s %s" % (prefixes[-1], self.base[k].label),
                                          tank_overrides=overrides) for k in cases]
        self.trials += len(specs)
        results = run_many(specs, self.args, "identify (%s)" % tag)
        out = []
        for i, values in enumerate(sets):
            chunk = results[len(cases) * i:len(cases) * (i + 1)]
            failed = [{"case": k, "label": r["label"], "reason": r["failed"]}
                      for k, r in zip(cases, chunk) if r.get("failed")]
            ran = [(k, r) for k, r in zip(cases, chunk) if not r.get("failed")]
            # a check compares with its Table-1 row (the paper's values); only its outcome counts
            row_of = dict(zip([k for k, _ in ran], pe.comparison_rows(
                [pe.PAPER_TABLE[self.check_row.get(k, k)] for k, _ in ran], [r for _, r in ran])))
            table = [row_of[k] for k in cases if k in row_of and k not in self.check_row]
            checks = [{"case": "t_rec 1.5 " + row_of[k]["case"], "settled_sim": bool(row_of[k]["settled_sim"])}
                      for k in cases if k in row_of and k in self.check_row]
            costs = [FAILED_CASE_COST if k not in row_of
                     else slow_recovery_cost(bool(row_of[k]["settled_sim"])) if k in self.check_row
                     else case_cost(row_of[k], band=self.band)
                     for k in cases]
            counts = targets(table, [pe.PAPER_TABLE[f["case"]] for f in failed if f["case"] not in self.check_row])
            counts.update(slow_recovery_checks=sum(k in self.check_row for k in cases),
                          slow_recovery_unsettled=sum(not c["settled_sim"] for c in checks))
            out.append({"values": dict(values), "objective": float(sum(costs)), "targets": counts, "rows": table,
                        "slow_recovery": checks, "cases": list(cases), "costs": costs, "failed": failed})
            self.sets.append({"set": prefixes[i], "values": dict(values), "objective": out[-1]["objective"],
                              "cases": list(cases), "targets": counts, "failed": len(failed)})
            if failed:
                self.failed_sets += 1
                if len(self.failed_examples) < 5:
                    self.failed_examples.append({"values": dict(values), "objective": out[-1]["objective"],
                                                 "failed": failed})
        return out

    def cases(self, groups: Sequence[str]) -> List[int]:
        """The experiments of ``groups``: their Table-1 rows, then their slow-recovery checks."""
        table = [k for k, row in enumerate(pe.PAPER_TABLE) if row["set"] in groups]
        return table + [k for k, row in sorted(self.check_row.items()) if pe.PAPER_TABLE[row]["set"] in groups]


def _median_or_none(values: Sequence[Optional[float]]) -> Optional[float]:
    """The median of the values that exist, if more than half of them do (the majority has a value); None
    otherwise (most members never rose or never settled)."""
    present = [v for v in values if v is not None]
    return float(np.median(present)) if 2 * len(present) > len(values) else None


def ensemble_rows(members: Sequence[Sequence[Dict[str, Any]]]) -> List[Dict[str, Any]]:
    """The ensemble's prediction of each experiment, as a comparison row (:func:`paper_experiments.
    comparison_rows`) that :func:`targets` and :func:`case_cost` score like a single set's: settled when
    more than half the members settle; each metric (t_r, t_s, e_ss, M_p and yaw's) the median over the
    members that have it, None where most have none. ``members``: each member's rows, the same
    experiments in the same order."""
    out = []
    for rows in zip(*members):
        first = rows[0]
        sims = [r["sim"] for r in rows]
        # the attitudes at the start are the experiment's, the same for every member
        sim = dict(first["sim"], **{k: _median_or_none([s[k] for s in sims]) for k in ("t_r", "t_s", "e_ss", "M_p")})
        sim["yaw"] = {k: _median_or_none([s["yaw"][k] for s in sims]) for k in ("t_r", "t_s", "e_ss", "M_p")}
        if "marks" in sim:  # which axis was the worst differs between members: the median marks none
            sim["marks"] = ""
        # settled, as in comparison_rows, is having a t_s: the median has one when more than half the members do
        out.append(dict(first, sim=sim, settled_sim=sim["t_s"] is not None))
    return out


def _covers(paper: Optional[float], sims: Sequence[Optional[float]]) -> bool:
    """Whether the robot's value lies within the members' spread, a missing value (never rose or settled
    within the trial) counting as later than any: a robot that did not settle is covered by any member
    that did not."""
    finite = [v for v in sims if v is not None]
    if paper is None:
        return len(finite) < len(sims)
    return bool(finite) and min(finite) <= paper and (paper <= max(finite) or len(finite) < len(sims))


def coverage(members: Sequence[Sequence[Dict[str, Any]]]) -> Dict[str, int]:
    """How many experiments the ensemble's spread covers (:func:`_covers`): the robot's t_s (its outcome
    included), t_r and yaw t_s (where the paper reports one) against the members' values. An ensemble that
    covers few is more certain than the model's fit to Table 1 allows."""
    counts = {"cases": 0, "t_s": 0, "t_r": 0, "yaw_t_s": 0, "yaw_t_s_reported": 0}
    for rows in zip(*members):
        paper = rows[0]["paper"]
        counts["cases"] += 1
        counts["t_s"] += _covers(paper["t_s"], [r["sim"]["t_s"] for r in rows])
        counts["t_r"] += _covers(paper["t_r"], [r["sim"]["t_r"] for r in rows])
        if paper["yaw"]["t_s"] is not None:
            counts["yaw_t_s_reported"] += 1
            counts["yaw_t_s"] += _covers(paper["yaw"]["t_s"], [r["sim"]["yaw"]["t_s"] for r in rows])
    return counts


def ensemble_prediction(members: Sequence[Dict[str, Any]], band: float = 1.0) -> Optional[Dict[str, Any]]:
    """An ensemble's members run on the same experiments (:class:`Evaluator` results) -> its prediction
    (:func:`ensemble_rows`) scored like one set's (objective with the timing ``band`` of :func:`case_cost`,
    :func:`targets`), each member's objective and counts, and the spread's :func:`coverage`. The Table-1
    experiments only: the slow-recovery checks stay in each member's own objective. A member with an
    experiment that could not run is left out of the median and the spread (its rows lack that experiment)
    and counted in ``left_out``; None if no member ran every experiment."""
    complete = [m for m in members if not m["failed"]]
    if not complete:
        return None
    member_rows = [m["rows"] for m in complete]
    rows = ensemble_rows(member_rows)
    return {"members": len(complete), "left_out": len(members) - len(complete),
            "objective": float(sum(case_cost(r, band=band) for r in rows)),
            "targets": targets(rows), "rows": rows, "member_objectives": [m["objective"] for m in members],
            "member_targets": [m["targets"] for m in members], "coverage": coverage(member_rows)}
