"""``simulate --study schemes``: the paper's stroke scheme against the coordinated one on one ensemble.

Ensemble (:mod:`quadruped_control.studies.cases`): the paper's simulation cases (15/45/75 degrees on all
axes), the 15 experiments of Table 1 (reconstructed initial attitudes, t_rec = 1.0 s where the paper used
it, 180 s), 20 seeded random setpoint / initial-attitude pairs (120 s); each from its initial attitude and
from ``perturbed`` starts with every initial Euler angle perturbed uniformly by +-0.5 degrees (numpy
default_rng(1000 + case index * 10 + repeat)); both gain sets; ideal and rate-limited servos; plant: the
paper's model (default) or the tank (``--plant tank``). Every start runs with both schemes.

Per trial: geodesic settling time (3 s centred average, 6 degree band, held 30 s; ``None`` if it never
settles), the worst smoothed geodesic error over the last 30 s, the torque delivered (eq. torque_leg from
the simulated joints) against tau_sat, and the fraction of time some pair is in power
(:func:`quadruped_control.studies.trial.stroke_metrics`). Writes ``schemes.json``, ``schemes.md`` and
``schemes.png`` into the output folder and prints the summary with its targets (docs/stroke_schemes.md).
"""
from __future__ import annotations

import json
import os
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_control.studies.cases import paper_sim_cases, random_cases, table1_cases
from quadruped_control.studies.runner import code_record
from quadruped_control.studies.trial import TrialSpec, run_many

__all__ = ["build_specs", "compare", "main_study", "trial_row"]

SCHEME_ORDER = ("paper", "coordinated")
PERTURBATION_DEG = 0.5


def build_specs(perturbed: int = 1, gain_sets: Sequence[str] = ("simulation", "experiment"),
                servos: Sequence[str] = ("ideal", "rate-limited"), robot_yaml: Optional[str] = None,
                cases: Optional[list] = None, plant: str = "paper", tank_yaml: Optional[str] = None) -> List[Any]:
    """TrialSpecs of the ensemble (module docstring); labels 'case|start|gains|servo|scheme'."""

    if cases is None:
        cases = paper_sim_cases() + table1_cases() + random_cases()
    specs = []
    for index, case in enumerate(cases):
        starts = [case.initial_rpy_deg]
        for repeat in range(perturbed):
            rng = np.random.default_rng(1000 + index * 10 + repeat)
            starts.append(tuple((np.array(case.initial_rpy_deg)
                                 + rng.uniform(-PERTURBATION_DEG, PERTURBATION_DEG, 3)).tolist()))
        overrides = (("t_rec", case.t_rec),) if case.t_rec is not None else ()
        for start_index, start in enumerate(starts):
            for gains in gain_sets:
                for servo in servos:
                    for scheme in SCHEME_ORDER:
                        specs.append(TrialSpec(
                            label="|".join((case.name, str(start_index), gains, servo, scheme)),
                            setpoint_rpy_deg=case.setpoint_rpy_deg, initial_rpy_deg=start, duration=case.duration,
                            gains=gains, servo_model=servo, quiet=True, robot_yaml=robot_yaml,
                            config_overrides=overrides, scheme=scheme, scheme_metrics=True, keep_trace=False,
                            **({} if plant == "paper" else {"plant": plant, "tank_yaml": tank_yaml})))
    return specs


def trial_row(summary: Dict[str, Any]) -> Dict[str, Any]:
    """One row of the study's table from a trial's summary (label 'case|start|gains|servo|scheme')."""
    case, start, gains, servo, scheme = summary["label"].split("|")
    m = summary["metrics"]
    return dict(case=case, start=int(start), gains=gains, servo=servo, scheme=scheme, settled=m["settled"],
                t_s=m["geodesic"]["t_s"], worst_last_30s=m["geodesic"]["max_smoothed_last_30s_deg"],
                theta_init=m["theta_init_deg"], duration=m["duration"], **summary["scheme_metrics"])


def _settling(row: Dict[str, Any]) -> float:
    """Geodesic settling time, the trial length when it never settles (so medians stay defined)."""
    return row["t_s"] if row["t_s"] is not None else row["duration"]


def compare(rows: Sequence[Dict[str, Any]]) -> Dict[str, Any]:
    """Pairs each coordinated trial with the paper trial of the same start; figures and targets."""
    by_key: Dict[Tuple[str, int, str, str], Dict[str, Dict[str, Any]]] = {}
    for row in rows:
        by_key.setdefault((row["case"], row["start"], row["gains"], row["servo"]), {})[row["scheme"]] = row
    pairs = [(k, v["paper"], v["coordinated"]) for k, v in sorted(by_key.items())
             if "paper" in v and "coordinated" in v]
    worse = []
    for key, paper, coord in pairs:
        # worse by more than 10 %: settles later, or a larger worst error over the last 30 s
        if _settling(coord) > 1.1 * _settling(paper) + 1e-9 or coord["worst_last_30s"] > 1.1 * paper["worst_last_30s"]:
            worse.append("%s start %d %s gains %s servos: t_s %.1f vs %.1f s, worst %.2f vs %.2f deg"
                         % (key[0], key[1], key[2], key[3], _settling(coord), _settling(paper),
                            coord["worst_last_30s"], paper["worst_last_30s"]))

    def summary(selection: Sequence[Tuple[Any, Dict[str, Any], Dict[str, Any]]]) -> Dict[str, Any]:
        out: Dict[str, Any] = {"trials": len(selection)}
        for position, scheme in ((1, "paper"), (2, "coordinated")):
            chosen = [p[position] for p in selection]
            out[scheme] = {
                "settled": sum(r["settled"] for r in chosen),
                "median_t_s": float(np.median([_settling(r) for r in chosen])) if chosen else None,
                "median_worst_last_30s": float(np.median([r["worst_last_30s"] for r in chosen])) if chosen else None,
                "median_torque_ratio": float(np.median([r["torque_ratio"] for r in chosen])) if chosen else None,
                "median_torque_sideways": float(np.median([r["torque_sideways"] for r in chosen])) if chosen else None,
                "median_power_fraction": float(np.median([r["power_fraction"] for r in chosen])) if chosen else None,
            }
        return out

    groups = {"all": summary(pairs)}
    for gains in sorted({p[0][2] for p in pairs}):
        for servo in sorted({p[0][3] for p in pairs}):
            groups["%s gains, %s servos" % (gains, servo)] = summary(
                [p for p in pairs if p[0][2] == gains and p[0][3] == servo])
    overall = groups["all"]
    coord, paper = overall["coordinated"], overall["paper"]
    targets = {
        "coordinated settles every case": coord["settled"] == overall["trials"],
        "median t_s <= half the paper's": bool(coord["median_t_s"] <= 0.5 * paper["median_t_s"]),
        "median worst error last 30 s <= 2 deg": bool(coord["median_worst_last_30s"] <= 2.0),
        "no case more than 10 % worse": not worse,
    }
    return {"groups": groups, "worse_cases": worse, "targets": targets, "all_met": all(targets.values())}


def _markdown(result: Dict[str, Any], rows: Sequence[Dict[str, Any]]) -> str:
    lines = ["| group | trials | scheme | settled | median t_s [s] | median worst error, last 30 s [deg] | "
             "median torque along / across tau_sat | median time with a pair in power |",
             "|---|---|---|---|---|---|---|---|"]
    for name, group in result["groups"].items():
        for scheme in SCHEME_ORDER:
            g = group[scheme]
            lines.append("| %s | %d | %s | %d | %.1f | %.2f | %.2f / %.2f | %.0f %% |" % (
                name, group["trials"], scheme, g["settled"], g["median_t_s"], g["median_worst_last_30s"],
                g["median_torque_ratio"], g["median_torque_sideways"], 100.0 * g["median_power_fraction"]))
    lines += ["", "Targets: " + "; ".join("%s: %s" % (k, "met" if v else "NOT met")
                                                    for k, v in result["targets"].items()),
              "", "Cases where the coordinated scheme is more than 10 %% worse: %d of %d"
              % (len(result["worse_cases"]), result["groups"]["all"]["trials"])]
    lines += ["- " + w for w in result["worse_cases"][:40]]
    if len(result["worse_cases"]) > 40:
        lines.append("- ... (%d more in schemes.json)" % (len(result["worse_cases"]) - 40))
    lines += ["", "## Per trial", "", "| case | start | gains | servos | scheme | settled | t_s [s] | worst last 30 s "
              "[deg] | torque along | power |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| %s | %d | %s | %s | %s | %s | %s | %.2f | %.2f | %.0f %% |" % (
            r["case"], r["start"], r["gains"], r["servo"], r["scheme"], "yes" if r["settled"] else "no",
            "--" if r["t_s"] is None else "%.1f" % r["t_s"], r["worst_last_30s"], r["torque_ratio"],
            100.0 * r["power_fraction"]))
    return "\n".join(lines) + "\n"


def _figure(rows: Sequence[Dict[str, Any]], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_key: Dict[Tuple[Any, ...], Dict[str, Dict[str, Any]]] = {}
    for row in rows:
        by_key.setdefault((row["case"], row["start"], row["gains"], row["servo"]), {})[row["scheme"]] = row
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    styles = {("simulation", "ideal"): "o", ("simulation", "rate-limited"): "s",
              ("experiment", "ideal"): "^", ("experiment", "rate-limited"): "v"}
    for (gains, servo), marker in styles.items():
        pts = [(v["paper"], v["coordinated"]) for k, v in by_key.items()
               if k[2] == gains and k[3] == servo and len(v) == 2]
        if not pts:
            continue
        axes[0].scatter([_settling(p) for p, _ in pts], [_settling(c) for _, c in pts], marker=marker, s=18,
                        alpha=0.7, label="%s gains, %s servos" % (gains, servo))
        axes[1].scatter([p["worst_last_30s"] for p, _ in pts], [c["worst_last_30s"] for _, c in pts], marker=marker,
                        s=18, alpha=0.7)
    for ax, title, unit in ((axes[0], "geodesic settling time (unsettled = trial length)", "s"),
                            (axes[1], "worst smoothed geodesic error, last 30 s", "deg")):
        lim = max(ax.get_xlim()[1], ax.get_ylim()[1])
        ax.plot([0, lim], [0, lim], "k-", lw=0.8)
        ax.plot([0, lim], [0, 0.5 * lim], "k:", lw=0.8)
        ax.set_xlabel("paper scheme [%s]" % unit)
        ax.set_ylabel("coordinated scheme [%s]" % unit)
        ax.set_title(title, fontsize=10)
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_yscale("symlog", linthresh=1.0)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main_study(args: Any) -> int:
    """The study of the module docstring with the CLI's arguments (``out``, ``jobs``, ``perturbed``,
    ``robot_yaml``, and the study runner's ``dask_scheduler``, ``resume``, ``quiet``); trials run through
    :func:`quadruped_control.studies.run_trials` (executor, progress bar, resume from ``out/trials``).

    Exit status: 0 when every target of the comparison is met, 2 when one is not (the results are
    written either way), so a script can tell; a ``set -e`` script that runs several studies should not
    take 2 for a failed run."""

    out = args.out
    os.makedirs(out, exist_ok=True)
    plant = args.plant or "paper"
    groups = args.scheme_groups.split(",")
    cases = [c for c in paper_sim_cases() + table1_cases() + random_cases() if c.group in groups]
    if not cases:
        raise ValueError("--scheme-groups %r selects no case (groups: paper-sim, table1, random)" % args.scheme_groups)
    specs = build_specs(args.perturbed, gain_sets=args.scheme_gains.split(","), servos=args.scheme_servos.split(","),
                        robot_yaml=args.robot_yaml, cases=cases, plant=plant, tank_yaml=args.tank_yaml)
    start = time.perf_counter()
    summaries = run_many(specs, args, "schemes")
    wall = time.perf_counter() - start
    rows = sorted((trial_row(s) for s in summaries), key=lambda r: (r["case"], r["start"], r["gains"], r["servo"],
                                                                r["scheme"]))
    result = compare(rows)
    # what produced it: the command, the code's fingerprint and, on the tank plant, which tank.yaml (as
    # given, so that a result kept in the repository names no path of the machine that ran it)
    result.update(study="schemes", command=getattr(args, "command", None), **code_record(), wall_time=wall,
                  trials=len(rows), perturbed_starts=args.perturbed, perturbation_deg=PERTURBATION_DEG, plant=plant,
                  tank_yaml=(args.tank_yaml or "config/tank.yaml") if plant == "tank" else None, rows=rows)
    with open(os.path.join(out, "schemes.json"), "w") as stream:
        json.dump(result, stream, indent=1, allow_nan=False)
    text = _markdown(result, rows)
    with open(os.path.join(out, "schemes.md"), "w") as stream:
        stream.write(text)
    _figure(rows, os.path.join(out, "schemes.png"))
    print(text.split("\n## Per trial")[0])
    print("%d trials in %.0f s wall; %s/{schemes.json, schemes.md, schemes.png}" % (len(rows), wall, out))
    return 0 if result["all_met"] else 2


def plot_stroke_timelines(path: str, setpoint_deg: Tuple[float, float, float] = (45.0, 45.0, 45.0),
                          window: Tuple[float, float] = (2.0, 8.0), leg: int = 1) -> None:
    """Figure of both schemes on one trial (simulation gains, rate-limited servos): the phase timeline
    of the two pairs (power intervals) and the commanded path of one foot in the body frame."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from quadruped_control.control.controller_config import load_controller_config
    from quadruped_control.model.params import load_robot_params
    from quadruped_control.sim.simulation import ClosedLoopSimulation
    from quadruped_common.so3 import rpy_to_rot

    robot = load_robot_params()
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), gridspec_kw={"height_ratios": [1, 2]})
    for column, scheme in enumerate(SCHEME_ORDER):
        config = load_controller_config().replace(stroke_scheme=scheme)
        sim = ClosedLoopSimulation(robot, config, "rate-limited", setpoint_R=rpy_to_rot(*np.radians(setpoint_deg)))
        feet = []
        phases = []
        times = []
        for _ in range(int(round(window[1] / sim.dt)) + 1):
            times.append(sim.time)
            _, output = sim.step()
            feet.append(output.state.foot_targets[leg - 1].copy())
            phases.append(output.state.pair_phase)
        t = np.array(times)
        phase = np.array(phases)
        ax = axes[0, column]
        for index, pair in enumerate(config.pairs):
            power = phase[:, index] == "power"
            edges = np.diff(np.concatenate(([0], power.astype(int), [0])))
            starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
            ax.broken_barh([(t[s], t[min(e, len(t) - 1)] - t[s]) for s, e in zip(starts, ends)],
                           (index + 0.6, 0.8), color="C%d" % index)
        none = ~np.any(phase == "power", axis=1)
        ax.fill_between(t, 0.4, 2.6, where=none, color="0.85", step="post", label="no pair in power")
        ax.set_xlim(*window)
        ax.set_yticks([1, 2])
        ax.set_yticklabels(["pair %s" % (config.pairs[0],), "pair %s" % (config.pairs[1],)])
        ax.set_title("%s scheme: power strokes (%.0f %% of the time some pair is in power)"
                     % (scheme, 100.0 * np.mean(~none)), fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
        ax.set_xlabel("t [s]")
        ax = axes[1, column]
        f = np.array(feet)
        sel = (t >= window[0]) & (t <= window[1])
        ax.plot(f[sel, 0], f[sel, 2], "-", lw=0.8, color="C0", label="x-z")
        ax.plot(f[sel, 1] + 0.0, f[sel, 2], "-", lw=0.8, color="C3", label="y-z")
        nominal = robot.nominal_foot_body(leg)
        ax.plot([nominal[0]], [nominal[2]], "k+", ms=12, label="nominal (x-z)")
        ax.plot([nominal[1]], [nominal[2]], "kx", ms=8, label="nominal (y-z)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x or y, body frame [m]")
        ax.set_ylabel("z [m]")
        ax.set_title("commanded path of foot %d, t = %g..%g s" % (leg, window[0], window[1]), fontsize=9)
        ax.legend(fontsize=7)
    fig.suptitle("Setpoint %g/%g/%g deg roll/pitch/yaw, simulation gains, rate-limited servos" % setpoint_deg,
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
