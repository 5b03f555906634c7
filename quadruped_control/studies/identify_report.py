"""The identification's report: the markdown of identify.md (:func:`report_text`), the figure
(:func:`plot_report`) and what the misses have in common (:func:`timing_bias`, :func:`yaw_first_ratio`).
Reads an identify.json's dict; ``python -m quadruped_control.studies.identify_report REPORT.json OUT.png`` draws
a report's figure again and prints its timing bias.
"""
from __future__ import annotations

import json
import math
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_control.studies import paper_experiments as pe
from quadruped_control.studies.identify_objective import FAILED_CASE_COST, GROUPS, signed_log_ratio
from quadruped_control.studies.identify_parameters import BOUNDS
from quadruped_control.studies.runner import describe_source

__all__ = ["YAW_FIRST_MIN_HEADING_DEG", "format_timing_bias", "plot_report", "report_text", "timing_bias",
           "yaw_first_ratio"]

#: The timing metrics of :func:`timing_bias`: (label, paper or simulation side -> value).
_TIMINGS: Tuple[Tuple[str, Callable[[Dict[str, Any]], Optional[float]]], ...] = (
    ("t_r", lambda side: side["t_r"]), ("t_s", lambda side: side["t_s"]),
    ("yaw t_r", lambda side: side["yaw"]["t_r"]), ("yaw t_s", lambda side: side["yaw"]["t_s"]))


#: Experiments whose heading error is at least this (deg) enter :func:`yaw_first_ratio`: below it yaw's rise
#: time measures little (Table 1: pitch 15 starts 1.5 deg off in heading, roll+pitch 30 0.5 deg).
YAW_FIRST_MIN_HEADING_DEG = 10.0


def _rise_ratio(side: Dict[str, Any]) -> float:
    """ln(yaw t_r / t_r) of one side of a row, the objective's 0.5 s floor on both."""
    return signed_log_ratio(side["yaw"]["t_r"], side["t_r"])


def yaw_first_ratio(rows: Sequence[Dict[str, Any]]) -> Tuple[Optional[float], Optional[float], int]:
    """How much sooner yaw rises than the commanded tilt: the geometric mean of yaw t_r / t_r on the paper's
    side and on the simulation's, over the experiments with a heading error of at least
    :data:`YAW_FIRST_MIN_HEADING_DEG` where both sides report both rise times, and their number. The SO(3)
    controller turns the body about the error's axis, so a plant that resists the three axes alike
    finishes them together (a ratio near 1); the robot finished yaw first (0.38 over Table 1)."""
    both = [r for r in rows if abs(r["paper"].get("psi_init") or 0.0) >= YAW_FIRST_MIN_HEADING_DEG
            and all(r[side]["t_r"] is not None and r[side]["yaw"] is not None and r[side]["yaw"]["t_r"] is not None
                    for side in ("paper", "sim"))]
    if not both:
        return None, None, 0
    paper, sim = ([math.exp(sum(_rise_ratio(r[side]) for r in both) / len(both)) for side in ("paper", "sim")])
    return paper, sim, len(both)


def timing_bias(rows: Sequence[Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """How much slower the robot is than the model, per group of experiments: for each timing metric the
    geometric mean of paper / simulation (the 0.5 s floor of the objective) over the experiments where
    both report one (> 1: the robot is slower), with their number, the median overshoot M_p of each
    side (%) and each side's :func:`yaw_first_ratio` ("yaw first": paper, simulation, number). A bias that
    stays in every fit, in sample as well as held out, is what the fitted parameters cannot remove."""
    out: Dict[str, Dict[str, Any]] = {}
    for group in GROUPS:
        members = [r for r in rows if r["set"] == group]
        if not members:
            continue
        entry: Dict[str, Any] = {}
        for label, get in _TIMINGS:
            logs = [signed_log_ratio(get(r["paper"]), get(r["sim"])) for r in members
                    if get(r["paper"]) is not None and get(r["sim"]) is not None]
            entry[label] = (math.exp(sum(logs) / len(logs)) if logs else None, len(logs))
        for side in ("paper", "sim"):
            overshoots = [r[side]["M_p"] for r in members if r[side]["M_p"] is not None]
            entry["M_p " + side] = float(np.median(overshoots)) if overshoots else None
        entry["yaw first"] = yaw_first_ratio(members)
        out[group] = entry
    return out


def format_timing_bias(report: Dict[str, Any]) -> str:
    """Markdown: :func:`timing_bias` of the full fit's best set (in sample) and of the cross-validation's
    predictions (held out)."""
    lines = ["How much slower the robot is than the model: geometric mean of paper / simulation per group "
             "(> 1: the robot is slower; in brackets the number of experiments), the median overshoot, and how "
             "much sooner yaw rises than the tilt (geometric mean of yaw t_r / t_r, paper / simulation, over "
             "the experiments with a heading error of %g deg or more)." % YAW_FIRST_MIN_HEADING_DEG, "",
             "| fit | group | t_r | t_s | yaw t_r | yaw t_s | M_p paper / sim [%] | yaw t_r / t_r paper / sim |",
             "|---|---|---|---|---|---|---|---|"]
    held = [r for fold in report["cross_validation"] for r in fold["prediction"]["rows"]]
    for title, rows in (("full fit, in sample", report["fit"]["best"]["rows"]), ("held out", held)):
        for group, entry in timing_bias(rows).items():
            cells = ["--" if entry[label][0] is None else "%.2f (%d)" % entry[label] for label, _ in _TIMINGS]
            overshoot = " / ".join("--" if entry["M_p " + side] is None else "%.0f" % entry["M_p " + side]
                                   for side in ("paper", "sim"))
            paper, sim, count = entry["yaw first"]
            first = "--" if paper is None else "%.2f / %.2f (%d)" % (paper, sim, count)
            lines.append("| %s | %s | %s | %s | %s |" % (title, group, " | ".join(cells), overshoot, first))
    return "\n".join(lines) + "\n"


def plot_report(report: Dict[str, Any], path: str) -> None:
    """Simulated against the paper's t_r, t_s and yaw t_s (log-log, the factor-2 band shaded): the full
    fit's best set on all 15 experiments, the cross-validation's predictions of the held-out groups, and
    the one-factor baseline's predictions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = [("full fit (all 15)", report["fit"]["best"]["rows"], "o", "tab:blue"),
              ("cross-validation, held out", [r for f in report["cross_validation"] for r in f["prediction"]["rows"]],
               "s", "tab:green"),
              ("baseline (paw drag scale), held out",
               [r for f in report["cross_validation"] for r in f["baseline_prediction"]["rows"]], "x", "tab:red")]
    figure, axes = plt.subplots(1, 3, figsize=(15, 5))
    for ax, (title, get) in zip(axes, (("rise time t_r [s]", lambda side: side["t_r"]),
                                       ("settling time t_s [s]", lambda side: side["t_s"]),
                                       ("yaw settling time [s]", lambda side: side["yaw"]["t_s"]))):
        for label, rows, marker, colour in series:
            pairs = [(get(r["paper"]), get(r["sim"])) for r in rows]
            pairs = [(a, b) for a, b in pairs if a and b]
            if pairs:
                ax.scatter(*zip(*pairs), marker=marker, color=colour, label=label)
        line = np.geomspace(0.1, 300.0, 10)
        ax.plot(line, line, "k-", lw=0.8)
        ax.fill_between(line, line / 2.0, line * 2.0, color="0.85", label="within a factor 2", zorder=0)
        ax.set(xscale="log", yscale="log", xlim=(0.5, 300.0), ylim=(0.05, 300.0), xlabel="paper [s]",
               ylabel="simulated [s]", title=title)
    axes[0].legend(fontsize=8, loc="upper left")
    figure.suptitle("Tank plant against Table 1 (cases settled in both; not settled ones are not drawn)")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _ensemble_prediction_text(folds: Sequence[Dict[str, Any]]) -> List[str]:
    """The folds' ensembles on their held-out groups (:func:`ensemble_prediction`), and the sums over the
    folds; nothing for reports before the folds' ensembles existed."""
    if not any(f.get("ensemble_prediction") for f in folds):
        return []
    lines = ["", "The folds' ensembles on their held-out groups (each fold's best distinct sets, chosen as the full "
             "fit's; prediction: the members' median per experiment, settled if most members settle; spread: "
             "experiments whose robot value lies within the members' values, a member that never settles "
             "counting as later than any):", "",
             "| held out | members | objective | same outcome | t_s within 2x | t_r within 2x | yaw t_s within 2x "
             "| members' t_s within 2x | spread covers t_s / t_r / yaw t_s |", "|---|---|---|---|---|---|---|---|---|"]
    total = {k: 0 for k in ("same_outcome", "t_s_within_2x", "t_r_within_2x", "yaw_t_s_within_2x", "cases",
                            "yaw_t_s_reported", "t_s", "t_r", "yaw_t_s")}
    objective_sum = 0.0
    for fold in folds:
        e = fold.get("ensemble_prediction")
        if not e:
            lines.append("| %s | no member ran every experiment | | | | | | | |" % fold["held_out"])
            continue
        t, c = e["targets"], e["coverage"]
        member_counts = [m["t_s_within_2x"] for m in e["member_targets"]]
        objective_sum += e["objective"]
        for k in ("same_outcome", "t_s_within_2x", "t_r_within_2x", "yaw_t_s_within_2x", "cases", "yaw_t_s_reported"):
            total[k] += t[k]
        for k in ("t_s", "t_r", "yaw_t_s"):
            total[k] += c[k]
        lines.append("| %s | %d%s | %.2f | %d of %d | %d | %d | %d of %d | %d-%d | %d / %d / %d of %d |" % (
            fold["held_out"], e["members"], " (%d left out)" % e["left_out"] if e["left_out"] else "",
            e["objective"], t["same_outcome"], t["cases"], t["t_s_within_2x"], t["t_r_within_2x"],
            t["yaw_t_s_within_2x"], t["yaw_t_s_reported"], min(member_counts), max(member_counts),
            c["t_s"], c["t_r"], c["yaw_t_s"], c["cases"]))
    lines.append("| sum | | %.2f | %d of %d | %d | %d | %d of %d | | %d / %d / %d |" % (
        objective_sum, total["same_outcome"], total["cases"], total["t_s_within_2x"], total["t_r_within_2x"],
        total["yaw_t_s_within_2x"], total["yaw_t_s_reported"], total["t_s"], total["t_r"], total["yaw_t_s"]))
    return lines


def report_text(report: Dict[str, Any], best: Dict[str, Any]) -> str:
    screening = report["screening"]
    lines = ["## Identification: %d trials, %.0f s wall" % (report["trials"], report["wall_time"]), ""]
    if report.get("command"):  # reports before the command and code were recorded have neither
        source = " (%s)" % describe_source(report["code_source"]) if "code_source" in report else ""
        lines += ["    " + " ".join(report["command"]), "", "Code %s%s." % (report["code"], source), ""]
    lines += ["Screening (Morris, %d sets): mu* (sigma) of each parameter; identified: %s." % (
        screening["sets"], ", ".join(report["identified"])), "",
        "| parameter | low | high | mu* | sigma | best (full fit) |", "|---|---|---|---|---|---|"]
    for name, mu, sigma in zip(screening["names"], screening["mu_star"], screening["sigma"]):
        low, high = BOUNDS[name]
        lines.append("| %s | %g | %g | %.2f | %s | %.4g |" % (name, low, high, mu, "--" if sigma is None else
                                                                "%.2f" % sigma, best["values"][name]))
    dropped = screening.get("trajectories_dropped", 0)  # reports before failures were recorded have none
    if dropped:
        lines += ["", "%d of the screening's %d trajectories are left out of mu* and sigma: a set of theirs could "
                  "not run every experiment." % (dropped, screening["trajectories"])]
    if report.get("failed_sets"):
        first = report["failed_examples"][0]["failed"][0]
        lines += ["", "%d parameter set(s) could not run every experiment (each such experiment costs %g); the "
                  "first: %s, %s. identify.json's failed_examples holds up to five with their values." % (
                      report["failed_sets"], FAILED_CASE_COST, first["label"], first["reason"])]
    t = best["targets"]
    checks = report.get("slow_recovery_check", False)

    def unsettled(counts: Dict[str, int]) -> str:
        return "%d of %d" % (counts["slow_recovery_unsettled"], counts["slow_recovery_checks"])

    band = report.get("band", 1.0)  # reports before --band have none: the plain log-ratios
    lines += ["", "Timing terms counted beyond a factor %g of the paper's (--band)." % band] if band != 1.0 else []
    polish_report = report["fit"].get("polish") or {"evaluations": 0}  # reports before the polish have none
    search = "CMA-ES, %d sets" % report["fit"]["evaluations"]
    if report.get("start") == "nominal":  # reports before --start all started from the screening's best
        search += ", from the nominal values"
    if polish_report["evaluations"]:
        search += ", of which %d of the compass search from CMA-ES's best (%.2f)" % (
            polish_report["evaluations"], polish_report["objective_before"])
    lines += ["", "Full fit (%s): objective %.2f; same outcome %d of 15, t_s within 2x %d, t_r "
              "within 2x %d, yaw t_s within 2x %d of %d%s." % (
                  search, best["objective"], t["same_outcome"], t["t_s_within_2x"],
                  t["t_r_within_2x"], t["yaw_t_s_within_2x"], t["yaw_t_s_reported"],
                  "; with t_rec = 1.5 s not settled (as the paper's robot): " + unsettled(t) if checks else ""), "",
              "Cross-validation (fit on two groups, predict the third):", "",
              "| held out | objective (fit / baseline) | same outcome | t_s within 2x | t_r within 2x | "
              "yaw t_s within 2x |" + (" t_rec 1.5 s not settled |" if checks else ""),
              "|---|---|---|---|---|---|" + ("---|" if checks else "")]
    for fold in report["cross_validation"]:
        p, b = fold["prediction"], fold["baseline_prediction"]
        tp, tb = p["targets"], b["targets"]
        lines.append("| %s | %.2f / %.2f | %d / %d of %d | %d / %d | %d / %d | %d / %d of %d |" % (
            fold["held_out"], p["objective"], b["objective"], tp["same_outcome"], tb["same_outcome"], tp["cases"],
            tp["t_s_within_2x"], tb["t_s_within_2x"], tp["t_r_within_2x"], tb["t_r_within_2x"],
            tp["yaw_t_s_within_2x"], tb["yaw_t_s_within_2x"], tp["yaw_t_s_reported"])
            + (" %d / %s |" % (tp["slow_recovery_unsettled"], unsettled(tb)) if checks else ""))
    lines += _ensemble_prediction_text(report["cross_validation"])
    polished_folds = [f for f in report["cross_validation"] if (f.get("polish") or {}).get("evaluations")]
    if polished_folds:
        lines += ["", "The folds' training objectives, CMA-ES's best -> after the compass search: " + ", ".join(
            "%s %.2f -> %.2f (%d sets)" % (f["held_out"], f["polish"]["objective_before"],
                                           f["polish"]["objective_after"], f["polish"]["evaluations"])
            for f in polished_folds) + "."]
    searches = [("full fit", report["fit"].get("search"))] + [  # reports before the search record have none
        ("%s fold" % f["held_out"], f.get("search")) for f in report["cross_validation"]]
    if all(record for _, record in searches):
        lines += ["", "Where each search found its best (set number of the sets asked, CMA-ES's then the compass "
                  "search's; a best in the last generation: still improving): " + ", ".join(
                      "%s %d of %d" % (name, record["improvements"][-1][0], record["sets"])
                      for name, record in searches) + "."]
    lines += ["", format_timing_bias(report),
              pe.format_table(best["rows"], "Best parameter set of the full fit: tank plant, experiment gains, "
                              "%s servos" % report["servo_model"])]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # python -m ... REPORT.json OUT.png: an identify.json's figure again, and its timing bias
    import sys

    with open(sys.argv[1]) as stream:
        loaded = json.load(stream)
    plot_report(loaded, sys.argv[2])
    print(format_timing_bias(loaded), end="")
