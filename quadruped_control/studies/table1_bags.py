"""Table 1 from the robot's bags: a tank day's Table-1 runs (docs/tank_day.md), each row run two or three times,
measured as the paper measured it and set beside the paper's row, repeat by repeat, with how much the repeats differ.

    python -m quadruped_control.studies.table1_bags DAY [DAY ...] [--out DIR]

DAY: a tank day's folder (or one Table-1 run's), read by :mod:`~quadruped_control.studies.day_folder`, which says
what it found missing; each run's row and repeat come from its run.yaml, else its folder's name. A run's trial is
its Table-1 setpoint's hold: from the arming to the next setpoint (the day's level hold after it) or the disarm, the
first trial of :func:`~quadruped_control.analysis.bag_report.split_trials`, measured by
:func:`~quadruped_control.analysis.bag_report.trial_metrics` (the paper's metrics, section "Experiments": 3 s
smoothed signals, t_r, t_s, e_ss, M_p; the coupled rows' worse axis, :func:`~.paper_experiments.worst_axis_metrics`).
psi_init is the yaw the controller had to turn at the start, the record's heading less the setpoint's: Table 1's
psi_init in any yaw reference.

Why (docs/identification.md, "Single runs are noisy"): one run per row cannot tell a model's miss from the tank's
own spread; repeats can. The report counts per repeat the rows with the paper's settled / not-settled outcome and
with t_s within 2x of the paper's (:func:`~.paper_experiments.agreement`), and gives per row every repeat's t_s and
M_p, and the runs whose gains were not Table 1's (the experiment gain set, and the row's t_rec).

Output in ``--out``: ``table1_bags.md`` and ``table1_bags.json``.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from quadruped_control.analysis.bag_report import (GAINS_TOPIC, BagReportError, attitude_rpy, gains_in_force,
                                                   gains_text, read_bags, split_trials, trial_metrics)
from quadruped_control.control.attitude_degrees import wrap_degrees
from quadruped_control.studies import StudyError
from quadruped_control.studies.day_folder import DayRun, day_runs, missing_text, say_missing
from quadruped_control.studies.paper_experiments import (PAPER_TABLE, agreement, case_label, comparison_rows,
                                                         format_table)
from quadruped_control.studies.runner import code_record, command_line, describe_source, write_study_report

__all__ = ["PAPER_GAINS", "main", "run_result"]

#: Table 1's gains (paper, section "Experimental Setup"); t_rec is the row's.
PAPER_GAINS = {"k_p": 10.0, "k_i": 3.0, "k_d": 0.5, "k_aw": 0.25}


def run_result(run: DayRun) -> Dict[str, Any]:
    """The run's Table-1 trial (module docstring): ``metrics`` (trial_metrics' without the series), the start's
    ``initial_rpy_deg`` (roll, pitch, psi_init), the ``gains`` in force, ``seconds``; StudyError when the controller
    never acted on a setpoint in the bag."""
    data = read_bags(run.bags)
    trials = split_trials(data)
    if not trials:
        raise StudyError("%s: the controller was never armed in the bag" % run.name)
    trial = trials[0]
    metrics = trial_metrics(data, trial.start, trial.end, trial.setpoint)
    metrics.pop("_series")
    t, rpy = attitude_rpy(data.imu_t, data.imu_q)
    first = rpy[min(int(np.searchsorted(t, trial.start)), len(t) - 1)]
    psi = wrap_degrees(math.degrees(first[2]) - metrics["setpoint_rpy_deg"][2])
    return {"run": run.name, "row": run.row, "repeat": run.repeat, "seconds": trial.end - trial.start,
            "metrics": metrics, "initial_rpy_deg": [math.degrees(first[0]), math.degrees(first[1]), psi],
            "gains": gains_in_force(data, trial.start, trial.end)["gains"]}


def _off_paper_gains(result: Dict[str, Any], t_rec: float) -> Optional[str]:
    """Why the run's gains are not Table 1's (None when they are, or unknown)."""
    gains = result["gains"]
    if not gains:
        return None
    wanted = dict(PAPER_GAINS, t_rec=t_rec)
    off = ["%s %s (Table 1: %s)" % (k, gains.get(k), v) for k, v in wanted.items()
           if gains.get(k) is None or abs(float(gains[k]) - v) > 1e-9]
    return ", ".join(off) or None


def _finite(value: Any) -> Any:
    """``value`` with every NaN or infinity None (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _cell(value: Optional[float]) -> str:
    return "--" if value is None else "%.1f" % value


def _spread_lines(rows: List[Dict[str, Any]]) -> List[str]:
    lines = ["", "### The repeats, row by row", "",
             "Commanded (coupled rows: worse) axis; --: not settled.", "",
             "| row | runs | t_s [s]: paper / each run | settled as the paper | t_s within 2x "
             "| M_p [%]: paper / each run |",
             "|---|---|---|---|---|---|"]
    for row in rows:
        lines.append("| %s | %d | %s / %s | %d of %d | %d of %d | %s / %s |" % (
            row["case"], len(row["runs"]), _cell(row["paper"]["t_s"]), ", ".join(_cell(v) for v in row["t_s"]),
            row["same_outcome"], len(row["runs"]), row["within_2x"], len(row["runs"]), _cell(row["paper"]["M_p"]),
            ", ".join(_cell(v) for v in row["M_p"])))
    return lines


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("days", nargs="+", metavar="DAY", help="a tank day's folder (or a Table-1 run's)")
    parser.add_argument("--out", default="out/table1_bags", help="output folder (default %(default)s)")
    args = parser.parse_args(argv)
    missing: List[str] = []
    results: List[Dict[str, Any]] = []
    try:
        for day in args.days:
            runs, lines = day_runs(day, ("table1",), needs=("/imu/data", "/controller_state"), wants=(GAINS_TOPIC,))
            missing += lines
            for run in runs:
                if not run.row or run.row not in [case_label(r) for r in PAPER_TABLE]:
                    missing.append("%s: no Table-1 row in its record or name: left out" % run.name)
                    continue
                try:
                    results.append(run_result(run))
                except (StudyError, BagReportError, ValueError) as exc:
                    missing.append("%s: not measured: %s" % (run.name, exc))
    except (BagReportError, OSError) as exc:
        sys.stderr.write("table1_bags: error: %s\n" % exc)
        return 1
    say_missing("table1_bags", missing)
    if not results:
        sys.stderr.write("table1_bags: no Table-1 run could be measured in %s\n" % ", ".join(args.days))
        return 1
    repeats = sorted({r["repeat"] for r in results})
    tables, text = [], ["# Table 1 from the robot's bags: %s" % ", ".join(args.days), "",
                        "Command: `%s`  " % " ".join(command_line("quadruped_control.studies.table1_bags", argv)),
                        "Code: %s" % describe_source(code_record()["code_source"]), ""]
    for repeat in repeats:
        pairs = [(row, r) for row in PAPER_TABLE for r in results
                 if r["repeat"] == repeat and r["row"] == case_label(row)]
        rows = comparison_rows([row for row, _ in pairs], [r for _, r in pairs])
        text += [format_table(rows, "Repeat %d (%s)" % (repeat, ", ".join(r["run"] for _, r in pairs)), "this run")]
        counts = agreement(rows)
        for row in rows:
            row["record"] = row.pop("sim")
        tables.append({"repeat": repeat, "rows": rows, "agreement": counts})
    spread = []
    for row in PAPER_TABLE:
        mine = sorted((t["repeat"], entry) for t in tables for entry in t["rows"] if entry["case"] == case_label(row))
        if not mine:
            continue
        entries = [entry for _, entry in mine]
        counts = agreement([dict(e, sim=e["record"]) for e in entries])
        spread.append({"case": case_label(row), "paper": {"t_s": row["t_s"], "M_p": row["M_p"]},
                       "runs": [r["run"] for r in results if r["row"] == case_label(row)],
                       "t_s": [e["record"]["t_s"] for e in entries], "M_p": [e["record"]["M_p"] for e in entries],
                       "same_outcome": counts["same_settled_outcome"], "within_2x": counts["t_s_within_2x"]})
        off = [(r["run"], _off_paper_gains(r, row["t_rec"])) for r in results if r["row"] == case_label(row)]
        missing += ["%s: gains not Table 1's: %s" % (name, why) for name, why in off if why]
        missing += ["%s: gains unknown (no parameter_updates in the bag)" % r["run"] for r in results
                    if r["row"] == case_label(row) and not r["gains"]]
    text += _spread_lines(spread)
    text += ["", "Gains in force at each run's start: %s" % "; ".join(
        "%s: %s" % (r["run"], gains_text(r["gains"])) for r in results)]
    report = _finite({"study": "table1_bags", "command": command_line("quadruped_control.studies.table1_bags", argv),
              **code_record(), "days": list(args.days), "repeats": tables, "rows": spread, "runs": results,
              "missing": missing})
    write_study_report(args.out, "table1_bags", "\n".join(text + missing_text(missing)) + "\n", report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
