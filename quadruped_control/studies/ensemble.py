"""Table 1 on every member of a fitted tank ensemble: what the tank plant predicts for the paper's experiments,
and how much the sets Table 1 cannot tell apart disagree.

    python -m quadruped_control.simulate --study ensemble [--tank-ensemble DIR] [--jobs 2] --out OUT

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
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from typing import Any, Dict, List, Optional, Sequence

from quadruped_common.config import config_path
from quadruped_control.sim.plants import VALIDITY_NOTE, load_tank_params
from quadruped_control.studies import StudyError
from quadruped_control.studies.identify import targets
from quadruped_control.studies.paper_experiments import (DURATION, PAPER_TABLE, case_label, comparison_rows,
                                                         experiment_specs)
from quadruped_control.studies.runner import code_record
from quadruped_control.studies.trial import run_many

__all__ = ["DEFAULT_FOLDER", "case_spread", "format_report", "main_study", "member_files"]

#: The package's ensemble (config_files.TANK_ENSEMBLE lists its files).
DEFAULT_FOLDER = "tank_ensemble"

#: The metrics of the per-experiment table: (label, the value of a comparison row's side).
_METRICS = (("t_r", lambda side: side["t_r"]), ("t_s", lambda side: side["t_s"]), ("M_p", lambda side: side["M_p"]),
            ("yaw t_s", lambda side: side["yaw"]["t_s"]))


def member_files(folder: Optional[str]) -> List[str]:
    """The ``*.yaml`` files of ``folder`` (default the package's config/tank_ensemble), sorted, each loaded
    once so that a broken member stops the study before any trial (ParameterError naming the file);
    StudyError for a folder that is missing or holds none."""
    folder = folder or config_path(DEFAULT_FOLDER)
    if not os.path.isdir(folder):
        raise StudyError("--tank-ensemble %s: no such folder" % folder)
    paths = sorted(os.path.join(folder, name) for name in os.listdir(folder) if name.endswith((".yaml", ".yml")))
    if not paths:
        raise StudyError("--tank-ensemble %s: no tank.yaml files (*.yaml) in it" % folder)
    for path in paths:
        load_tank_params(path)
    return paths


def _stats(values: Sequence[float]) -> Optional[Dict[str, float]]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)} if values else None


def case_spread(rows_by_member: Sequence[Sequence[Dict[str, Any]]]) -> List[Dict[str, Any]]:
    """Per experiment (the members' :func:`~.paper_experiments.comparison_rows`, in Table 1's order): the
    robot's value of each metric and the members' median, min and max over the members that have one
    (None if none has), and how many members settle."""
    out = []
    for case_rows in zip(*rows_by_member):
        first = case_rows[0]
        entry: Dict[str, Any] = {"case": first["case"], "set": first["set"], "cmd_deg": first["cmd_deg"],
                                 "settled_paper": first["settled_paper"],
                                 "members_settled": sum(bool(r["settled_sim"]) for r in case_rows),
                                 "members": len(case_rows)}
        for label, value in _METRICS:
            simulated = [value(r["sim"]) for r in case_rows]
            entry[label] = {"paper": value(first["paper"]), "sim": _stats([v for v in simulated if v is not None])}
        out.append(entry)
    return out


def _spread_cell(paper: Optional[float], sim: Optional[Dict[str, float]], fmt: str) -> str:
    text = "--" if paper is None else fmt % paper
    if sim is None:
        return text + " / --"
    return "%s / %s (%s-%s)" % (text, fmt % sim["median"], fmt % sim["min"], fmt % sim["max"])


def format_report(folder: str, members: Sequence[str], counts: Sequence[Dict[str, int]],
                  spread: Sequence[Dict[str, Any]], title: str) -> str:
    """Markdown: the per-member counts and the per-experiment spread."""
    lines = ["## Table 1 on the tank ensemble %s (%d members): %s" % (folder, len(members), title), "",
             "Per member: experiments with the robot's settled / not-settled outcome, and with t_s, t_r and yaw t_s "
             "within a factor 2 of the robot's (the identification's counts).", "",
             "| member | same outcome | t_s within 2x | t_r within 2x | yaw t_s within 2x |", "|---|---|---|---|---|"]
    for path, c in zip(members, counts):
        lines.append("| %s | %d of %d | %d | %d | %d of %d |" % (
            os.path.basename(path), c["same_outcome"], c["cases"], c["t_s_within_2x"], c["t_r_within_2x"],
            c["yaw_t_s_within_2x"], c["yaw_t_s_reported"]))
    lines += ["", "Per experiment: the robot's value / the members' median (min-max); t_s over the members that "
              "settle. Coupled cases: worst of roll and pitch.", "",
              "| set | cmd [deg] | t_r [s] | t_s [s] | members settled | M_p [%] | yaw t_s [s] |",
              "|---|---|---|---|---|---|---|"]
    for e in spread:
        lines.append("| %s | %d | %s | %s | %d of %d%s | %s | %s |" % (
            e["set"], e["cmd_deg"], _spread_cell(e["t_r"]["paper"], e["t_r"]["sim"], "%.1f"),
            _spread_cell(e["t_s"]["paper"], e["t_s"]["sim"], "%.1f"), e["members_settled"], e["members"],
            "" if e["settled_paper"] else " (robot: not settled)",
            _spread_cell(e["M_p"]["paper"], e["M_p"]["sim"], "%.1f"),
            _spread_cell(e["yaw t_s"]["paper"], e["yaw t_s"]["sim"], "%.1f")))
    lines += ["", "Note: %s." % VALIDITY_NOTE]
    return "\n".join(lines) + "\n"


def main_study(args: argparse.Namespace) -> int:
    """The study of the module docstring with the CLI's arguments (``tank_ensemble``, ``out``, ``jobs``,
    ``duration`` if given, and the study runner's). Exit status 0."""
    if (args.plant or "tank") != "tank":
        raise StudyError("the ensemble study runs the tank plant; --plant %s is not one" % args.plant)
    if args.tank_yaml:
        raise StudyError("--tank-yaml names one tank, --tank-ensemble a folder of them: give the folder")
    members = member_files(args.tank_ensemble)
    folder = args.tank_ensemble or "config/%s" % DEFAULT_FOLDER  # as given: a report names no path of the machine
    duration = args.duration if args.duration_given else DURATION
    os.makedirs(args.out, exist_ok=True)
    specs: List[Any] = []
    for path in members:
        member_args = argparse.Namespace(**dict(vars(args), tank_yaml=path))
        specs += experiment_specs(member_args, "tank", "experiment", "rate-limited", duration,
                                  tag=os.path.splitext(os.path.basename(path))[0], keep_trace=False)[0]
    start = time.perf_counter()
    results = run_many(specs, args, "ensemble")
    wall = time.perf_counter() - start
    cases = len(PAPER_TABLE)
    rows_by_member = [comparison_rows(PAPER_TABLE, results[k * cases:(k + 1) * cases]) for k in range(len(members))]
    counts = [targets(rows) for rows in rows_by_member]
    spread = case_spread(rows_by_member)
    title = "experiment gains, rate-limited servos, %g s trials" % duration
    text = format_report(folder, members, counts, spread, title)
    with open(os.path.join(args.out, "ensemble.md"), "w") as stream:
        stream.write(text)
    report = {"study": "ensemble", "command": getattr(args, "command", None), **code_record(), "folder": folder,
              "members": [os.path.basename(p) for p in members], "duration": duration, "wall_time": wall,
              "counts": counts, "cases": [case_label(row) for row in PAPER_TABLE], "spread": spread,
              "rows": rows_by_member}
    with open(os.path.join(args.out, "ensemble.json"), "w") as stream:
        json.dump(report, stream, indent=1, allow_nan=False)
    print(text)
    print("%d trials in %.1f s wall; %s/{ensemble.md, ensemble.json}" % (len(specs), wall, args.out))
    return 0
