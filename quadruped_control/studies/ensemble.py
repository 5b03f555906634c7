"""Table 1 on every member of a fitted tank ensemble: what the tank plant predicts for the paper's experiments,
and how much the sets Table 1 cannot tell apart disagree.

    python -m quadruped_control.simulate --study ensemble [--tank-ensemble DIR] [--draws N [--seed S]]
        [--tank-disturbance SIGMA TAU] [--jobs 2] --out OUT

``DIR`` (default: the package's ``config/tank_ensemble/``, docs/tank_model.md "Fitted to Table 1") holds the
members, one tank.yaml each. Every member runs the paper's 15 experiments as the Table-1 study does
(:mod:`quadruped_control.studies.paper_experiments`: Table 1's initial attitudes, experiment gains with
the paper's t_rec, rate-limited servos, 180 s), all members in one batch. ``OUT/ensemble.md`` and
``OUT/ensemble.json`` report
- per member, the identification's four counts (:func:`quadruped_control.studies.identify.targets`): the
  same settled / not-settled outcome as the robot, and t_s, t_r and yaw t_s within a factor 2 of its;
- per experiment, the robot's t_r, t_s, M_p and yaw t_s beside the members' median and range (t_s over the
  members that settle, with how many do).

A figure the members agree on is one Table 1 pins down; a wide range is a value only a measurement on the
robot can settle. Neither makes the ensemble a validated model of the robot (the note at the report's end).

A tank that is not still (tank.yaml's ``disturbance``, or ``--tank-disturbance SIGMA TAU`` on every member:
a torque of standard deviation SIGMA N m per world axis with correlation time TAU s) makes each run one draw
of a noisy model, and Table 1 is one run of each experiment on the robot. ``--draws N`` runs every member
with the trial seeds ``--seed`` to ``--seed + N - 1`` (seed 0: the tank's own draw; the same seed pushes
every member alike, so members differ by their parameters, not their luck). Then the report gives each
member's counts as the median and range over its draws, the spread over every run, and the coverage: in
how many experiments the robot's value lies inside the range of the runs (all of them, and each member's
own draws), per metric (docs/identification.md, "What the model misses, and why", judges the shipped members so).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

from quadruped_common.config import ParameterError, config_path
from quadruped_control.sim.plants import VALIDITY_NOTE, TankParams, load_tank_params
from quadruped_control.studies import StudyError
from quadruped_control.studies.identify_objective import targets
from quadruped_control.studies.paper_experiments import (DURATION, PAPER_TABLE, case_label, comparison_rows,
                                                         experiment_specs)
from quadruped_control.studies.runner import code_record
from quadruped_control.studies.trial import run_many

__all__ = ["COUNT_KEYS", "DEFAULT_FOLDER", "case_spread", "count_spread", "coverage", "disturbance_overrides",
           "format_report", "main_study", "member_files", "member_tanks", "tank_files"]

#: The package's ensemble (config_files.TANK_ENSEMBLE lists its files).
DEFAULT_FOLDER = "tank_ensemble"

#: The metrics of the per-experiment table: (label, the value of a comparison row's side).
_METRICS = (("t_r", lambda side: side["t_r"]), ("t_s", lambda side: side["t_s"]), ("M_p", lambda side: side["M_p"]),
            ("yaw t_s", lambda side: side["yaw"]["t_s"]))

#: The identification's four counts (:func:`~.identify.targets`), in the report's order.
COUNT_KEYS = ("same_outcome", "t_s_within_2x", "t_r_within_2x", "yaw_t_s_within_2x")


def member_files(folder: Optional[str]) -> List[str]:
    """The ``*.yaml`` files of ``folder`` (default the package's config/tank_ensemble), sorted (:func:`member_tanks`
    loads them); StudyError for a folder that is missing or holds none."""
    folder = folder or config_path(DEFAULT_FOLDER)
    if not os.path.isdir(folder):
        raise StudyError("--tank-ensemble %s: no such folder" % folder)
    paths = sorted(os.path.join(folder, name) for name in os.listdir(folder) if name.endswith((".yaml", ".yml")))
    if not paths:
        raise StudyError("--tank-ensemble %s: no tank.yaml files (*.yaml) in it" % folder)
    return paths


def tank_files(paths: Sequence[str]) -> List[str]:
    """The tank.yaml files named by ``paths``, each a file or a folder of them (:func:`member_files`), each once
    in the order given: the models a study sets beside a record (``--compare``)."""
    files: List[str] = []
    for path in paths:
        files += member_files(path) if os.path.isdir(path) else [path]
    return sorted(set(files), key=files.index)


def disturbance_overrides(disturbance: Optional[Sequence[float]]) -> Tuple[Tuple[str, Any], ...]:
    """The tank overrides of ``--tank-disturbance SIGMA TAU`` (none without it)."""
    if disturbance is None:
        return ()
    sigma, tau = disturbance
    return (("disturbance_torque_std", float(sigma)), ("disturbance_correlation_time", float(tau)))


def member_tanks(paths: Sequence[str], overrides: Tuple[Tuple[str, Any], ...], draws: int) -> List[TankParams]:
    """Each member's tank with ``overrides`` applied, checked before any trial runs: the loader's
    ParameterError naming a broken member file, StudyError for an override out of its bounds (the loader's
    message) and for ``draws`` > 1 on a member whose tank is still, whose draws would all be the same run."""
    if draws < 1:
        raise StudyError("--draws must be at least 1, got %d" % draws)
    tanks = []
    for path in paths:
        tank = load_tank_params(path)
        try:
            tank = tank.with_values(**dict(overrides))
        except ParameterError as exc:
            raise StudyError("--tank-disturbance: %s" % exc) from None
        if draws > 1 and not tank.disturbed:
            raise StudyError("--draws %d: %s is a still tank (no disturbance), so its draws would all be the same "
                             "run; give --tank-disturbance SIGMA TAU or members with a disturbance section"
                             % (draws, os.path.basename(path)))
        tanks.append(tank)
    return tanks


def _stats(values: Sequence[float]) -> Optional[Dict[str, float]]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)} if values else None


def case_spread(rows_by_run: Sequence[Sequence[Dict[str, Any]]]) -> List[Dict[str, Any]]:
    """Per experiment (each run's :func:`~.paper_experiments.comparison_rows`, in Table 1's order; a run is a
    member's draw): the robot's value of each metric and the runs' median, min and max over the runs that
    have one (None if none has), and how many runs settle."""
    out = []
    for case_rows in zip(*rows_by_run):
        first = case_rows[0]
        entry: Dict[str, Any] = {"case": first["case"], "set": first["set"], "cmd_deg": first["cmd_deg"],
                                 "settled_paper": first["settled_paper"],
                                 "runs_settled": sum(bool(r["settled_sim"]) for r in case_rows),
                                 "runs": len(case_rows)}
        for label, value in _METRICS:
            simulated = [value(r["sim"]) for r in case_rows]
            entry[label] = {"paper": value(first["paper"]), "sim": _stats([v for v in simulated if v is not None])}
        out.append(entry)
    return out


def _covered(label: str, case_rows: Sequence[Dict[str, Any]]) -> Optional[bool]:
    """Does the robot's ``label`` lie inside the runs' range in this experiment? None where Table 1 gives no
    value to judge (no M_p or yaw t_s reported). The robot's t_s is judged with its outcome: not settled is
    covered by a run that does not settle either; a settling time by the range of the runs that settle."""
    value = dict(_METRICS)[label]
    paper = value(case_rows[0]["paper"])
    if label == "t_s" and not case_rows[0]["settled_paper"]:
        return any(not r["settled_sim"] for r in case_rows)
    if paper is None:
        return None
    simulated = [v for v in (value(r["sim"]) for r in case_rows) if v is not None]
    return bool(simulated) and min(simulated) <= paper <= max(simulated)


def coverage(rows_by_run: Sequence[Sequence[Dict[str, Any]]]) -> Dict[str, Dict[str, Any]]:
    """Per metric: in how many experiments the robot's value lies inside the range of the runs
    (:func:`_covered`), of how many Table 1 can judge, and which experiments miss. Judged so, a noisy model
    is wrong where the robot lies outside the range of many draws, not where one draw misses it."""
    out = {}
    for label, _ in _METRICS:
        verdicts = [(rows[0]["case"], _covered(label, rows)) for rows in zip(*rows_by_run)]
        judged = [(case, ok) for case, ok in verdicts if ok is not None]
        out[label] = {"covered": sum(ok for _, ok in judged), "of": len(judged),
                      "outside": [case for case, ok in judged if not ok]}
    return out


def count_spread(counts_by_draw: Sequence[Dict[str, int]]) -> Dict[str, Dict[str, float]]:
    """A member's four counts over its draws: median, min and max of each (:data:`COUNT_KEYS`)."""
    return {key: _stats([c[key] for c in counts_by_draw]) for key in COUNT_KEYS}  # type: ignore[misc]


def _spread_cell(paper: Optional[float], sim: Optional[Dict[str, float]], fmt: str) -> str:
    text = "--" if paper is None else fmt % paper
    if sim is None:
        return text + " / --"
    return "%s / %s (%s-%s)" % (text, fmt % sim["median"], fmt % sim["min"], fmt % sim["max"])


def _count_cell(spread: Dict[str, float]) -> str:
    if spread["min"] == spread["max"]:
        return "%g" % spread["median"]
    return "%g (%g-%g)" % (spread["median"], spread["min"], spread["max"])


def _coverage_cells(cover: Dict[str, Dict[str, Any]]) -> str:
    return " | ".join("%d of %d" % (cover[label]["covered"], cover[label]["of"]) for label, _ in _METRICS)


def format_report(folder: str, members: Sequence[str], counts: Sequence[Sequence[Dict[str, int]]],
                  spread: Sequence[Dict[str, Any]], title: str,
                  cover: Optional[Dict[str, Any]] = None) -> str:
    """Markdown: the per-member counts (``counts``: each member's, per draw; with more than one draw their
    median and range), the per-experiment spread over every run and, given ``cover`` (``{"runs": ...,
    "members": [...]}``, :func:`coverage`), in how many experiments the runs' range holds the robot's value."""
    draws = len(counts[0])
    runs = "members" if draws == 1 else "runs (%d members x %d draws)" % (len(members), draws)
    lines = ["## Table 1 on the tank ensemble %s (%d members): %s" % (folder, len(members), title), "",
             "Per member: experiments with the robot's settled / not-settled outcome, and with t_s, t_r and yaw t_s "
             "within a factor 2 of the robot's (the identification's counts)%s." % (
                 "" if draws == 1 else "; the median (min-max) over the member's %d draws" % draws), "",
             "| member | same outcome | t_s within 2x | t_r within 2x | yaw t_s within 2x |", "|---|---|---|---|---|"]
    for path, member_counts in zip(members, counts):
        c = count_spread(member_counts)
        first = member_counts[0]
        lines.append("| %s | %s of %d | %s | %s | %s of %d |" % (
            os.path.basename(path), _count_cell(c["same_outcome"]), first["cases"], _count_cell(c["t_s_within_2x"]),
            _count_cell(c["t_r_within_2x"]), _count_cell(c["yaw_t_s_within_2x"]), first["yaw_t_s_reported"]))
    lines += ["", "Per experiment: the robot's value / the median (min-max) of the %s; t_s over the runs that "
              "settle. Coupled cases: worst of roll and pitch." % runs, "",
              "| set | cmd [deg] | t_r [s] | t_s [s] | runs settled | M_p [%] | yaw t_s [s] |",
              "|---|---|---|---|---|---|---|"]
    for e in spread:
        lines.append("| %s | %d | %s | %s | %d of %d%s | %s | %s |" % (
            e["set"], e["cmd_deg"], _spread_cell(e["t_r"]["paper"], e["t_r"]["sim"], "%.1f"),
            _spread_cell(e["t_s"]["paper"], e["t_s"]["sim"], "%.1f"), e["runs_settled"], e["runs"],
            "" if e["settled_paper"] else " (robot: not settled)",
            _spread_cell(e["M_p"]["paper"], e["M_p"]["sim"], "%.1f"),
            _spread_cell(e["yaw t_s"]["paper"], e["yaw t_s"]["sim"], "%.1f")))
    if cover is not None:
        intro = ("Coverage: experiments whose robot value lies inside the range (min-max) of the runs, of those "
                 "Table 1 gives a value to judge (t_s: a robot that did not settle is covered by a run that does "
                 "not). Outside the range of every run, the robot did what no member and no draw does.")
        if draws > 1:  # N exchangeable draws and one more: the newcomer is the extreme with chance 2 / (N + 1)
            intro += (" Were the robot one more draw of a member, the member's %d draws would hold its value in about "
                      "(N - 1) / (N + 1) = %.0f %% of the experiments." % (draws, 100.0 * (draws - 1) / (draws + 1)))
        lines += ["", intro, "", "| runs | t_r | t_s | M_p | yaw t_s |", "|---|---|---|---|---|",
                  "| all %s | %s |" % (runs, _coverage_cells(cover["runs"]))]
        if draws > 1:
            for path, member_cover in zip(members, cover["members"]):
                lines.append("| %s, its %d draws | %s |" % (os.path.basename(path), draws,
                                                              _coverage_cells(member_cover)))
        lines += ["", "Outside the range of all runs: " + "; ".join(
            "%s: %s" % (label, ", ".join(cover["runs"][label]["outside"]) or "none") for label, _ in _METRICS) + "."]
    lines += ["", "Note: %s." % VALIDITY_NOTE]
    return "\n".join(lines) + "\n"


def main_study(args: argparse.Namespace) -> int:
    """The study of the module docstring with the CLI's arguments (``tank_ensemble``, ``draws``,
    ``tank_disturbance``, ``seed``, ``out``, ``jobs``, ``duration`` if given, and the study runner's).
    Exit status 0."""
    if (args.plant or "tank") != "tank":
        raise StudyError("the ensemble study runs the tank plant; --plant %s is not one" % args.plant)
    if args.tank_yaml:
        raise StudyError("--tank-yaml names one tank, --tank-ensemble a folder of them: give the folder")
    members = member_files(args.tank_ensemble)
    draws = getattr(args, "draws", 1)
    disturbance = getattr(args, "tank_disturbance", None)
    overrides = disturbance_overrides(disturbance)
    member_tanks(members, overrides, draws)
    seeds = [args.seed + k for k in range(draws)]
    folder = args.tank_ensemble or "config/%s" % DEFAULT_FOLDER  # as given: a report names no path of the machine
    duration = args.duration if args.duration_given else DURATION
    os.makedirs(args.out, exist_ok=True)
    specs: List[Any] = []
    for path in members:
        tag = os.path.splitext(os.path.basename(path))[0]
        for seed in seeds:
            draw_args = argparse.Namespace(**dict(vars(args), tank_yaml=path, seed=seed))
            specs += experiment_specs(draw_args, "tank", "experiment", "rate-limited", duration,
                                      tag=tag if draws == 1 else "%s seed %d" % (tag, seed),
                                      tank_overrides=overrides, keep_trace=False)[0]
    start = time.perf_counter()
    results = run_many(specs, args, "ensemble")
    wall = time.perf_counter() - start
    cases = len(PAPER_TABLE)
    rows = [[comparison_rows(PAPER_TABLE, results[(m * draws + k) * cases:(m * draws + k + 1) * cases])
             for k in range(draws)] for m in range(len(members))]
    counts = [[targets(draw_rows) for draw_rows in member_rows] for member_rows in rows]
    every_run = [draw_rows for member_rows in rows for draw_rows in member_rows]
    spread = case_spread(every_run)
    cover = {"runs": coverage(every_run), "members": [coverage(member_rows) for member_rows in rows]}
    title = "experiment gains, rate-limited servos, %g s trials" % duration
    if disturbance is not None:
        title += ", a disturbance of %g N m (correlation time %g s) on every member" % tuple(disturbance)
    if draws > 1:
        title += ", %d draws (trial seeds %d-%d)" % (draws, seeds[0], seeds[-1])
    text = format_report(folder, members, counts, spread, title, cover)
    with open(os.path.join(args.out, "ensemble.md"), "w") as stream:
        stream.write(text)
    report = {"study": "ensemble", "command": getattr(args, "command", None), **code_record(), "folder": folder,
              "members": [os.path.basename(p) for p in members], "duration": duration, "wall_time": wall,
              "draws": draws, "seeds": seeds, "tank_overrides": [list(item) for item in overrides],
              "counts": counts, "member_counts": [count_spread(c) for c in counts],
              "cases": [case_label(row) for row in PAPER_TABLE], "spread": spread, "coverage": cover, "rows": rows}
    with open(os.path.join(args.out, "ensemble.json"), "w") as stream:
        json.dump(report, stream, indent=1, allow_nan=False)
    print(text)
    print("%d trials in %.1f s wall; %s/{ensemble.md, ensemble.json}" % (len(specs), wall, args.out))
    return 0
