"""Offline closed-loop simulator CLI (no ROS needed): ``python3 -m quadruped_control.simulate``.

Single trial (defaults: the paper's simulation gains and ideal servos, RK4 at dt = 0.01 s)::

    python3 -m quadruped_control.simulate --rpy 45 45 45 --duration 120 --out /tmp/trial

writes ``DIR/timeseries.csv``, ``DIR/metrics.json`` and ``DIR/attitude.png`` and prints a metrics table.

Studies:

- ``--study paper-sim``: the paper's section "Simulation Validation": setpoints 15, 45 and 75 degrees
  applied simultaneously to roll, pitch and yaw, simulation gains (K_p = 5, K_i = 0.15, K_d = 1,
  K_aw = 0.25, t_rec = 1.5 s), RK4 at 0.01 s. The paper gives neither the initial attitude nor the
  trial length: level at rest and 120 s (``paper_sim`` in config/simulation.yaml). Writes
  ``DIR/paper_sim.png`` (three trials in one figure), ``DIR/study.json`` and each trial's files in
  ``DIR/trial_<deg>/``.
- ``--study robustness``: the same setpoints under +-0.5 degree initial-attitude perturbations
  (several seeds), with the experiment gains (ideal and rate-limited servos), with the normalised force
  direction, with the rate-limited servo, and with the estimated robot parameters that matter varied
  (paw net buoyancy, leg pairing, nominal foot height): ``DIR/robustness.json`` and ``DIR/robustness.md``.

``--robot-yaml PATH`` replaces config/robot.yaml for plant and controller alike (single trials and both
studies; the robustness study varies its estimates around that file), e.g. to compare candidate
estimates without editing the package configuration.

Trials of a study run through :mod:`quadruped_control.studies` on worker processes (``--jobs``, default:
the number of CPUs, max 2 here) or on an existing Dask cluster (``--dask-scheduler ADDRESS``), with a
progress bar and ETA on stderr. Each finished trial is kept in ``DIR/trials/``; rerunning a study with the
same ``--out`` skips the trials already finished (``--no-resume`` runs them all again).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_control.controller_config import load_controller_config
from quadruped_control.params import ParameterError, config_path, load_robot_params
from quadruped_control.plants import PLANTS, load_tank_params, make_plant
from quadruped_control.servo_model import load_servo_params, make_servo_model
from quadruped_control.simulation import (ClosedLoopSimulation, SimulationError, SimulationResult, load_simulation_settings,
                                          load_simulation_tree)
from quadruped_control.so3 import rpy_to_rot
from quadruped_control.studies import StudyError, run_trials
from quadruped_control.strokes import SCHEMES

GAIN_ALIASES = {"sim": "simulation", "simulation": "simulation", "experiment": "experiment", "exp": "experiment"}

__all__ = ["TrialSpec", "main", "run_trial", "format_metrics_table"]


@dataclasses.dataclass(frozen=True)
class TrialSpec:
    """Everything one trial needs (picklable, for worker processes). Angles in degrees."""

    label: str
    setpoint_rpy_deg: Tuple[float, float, float]
    initial_rpy_deg: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    duration: float = 120.0
    gains: str = "simulation"
    servo_model: str = "ideal"
    seed: int = 0
    normalize_force: bool = False
    restoring_offset: Optional[Tuple[float, float, float]] = None
    attitude_noise_deg: float = 0.0
    gyro_noise: float = 0.0
    out_dir: Optional[str] = None
    robot_yaml: Optional[str] = None
    controller_yaml: Optional[str] = None
    simulation_yaml: Optional[str] = None
    quiet: bool = False
    #: plant (:mod:`quadruped_control.plants`): "paper" or "tank"; ``tank_yaml`` replaces config/tank.yaml
    plant: str = "paper"
    tank_yaml: Optional[str] = None
    #: (field, value) pairs replaced in TankParams (identification).
    tank_overrides: Tuple[Tuple[str, Any], ...] = ()
    #: "on", or "off": legs held at the nominal pose (passive dynamics)
    controller: str = "on"
    #: keep the attitude traces in the summary (figures); studies that only need metrics drop them.
    keep_trace: bool = True
    #: keep every n-th sample of the traces (long studies)
    trace_stride: int = 1
    #: (field, value) pairs replaced in RobotParams / ControllerConfig (sensitivity studies).
    robot_overrides: Tuple[Tuple[str, Any], ...] = ()
    config_overrides: Tuple[Tuple[str, Any], ...] = ()
    #: Stroke scheme ('paper', 'coordinated'); None keeps config/controller.yaml's stroke.scheme.
    scheme: Optional[str] = None
    #: Also compute the stroke-scheme figures (torque delivered vs commanded, power fraction).
    scheme_metrics: bool = False


def _progress_printer(label: str, quiet: bool):
    if quiet:
        return None
    start = time.perf_counter()

    def report(t: float, duration: float) -> None:
        elapsed = time.perf_counter() - start
        rate = t / elapsed if elapsed > 0 else 0.0
        sys.stderr.write("[%s] %6.1f / %.1f s simulated (%.0fx real time)\n" % (label, t, duration, rate))
        sys.stderr.flush()
    return report


def run_trial(spec: TrialSpec) -> Dict[str, Any]:
    """Run one trial; writes its files if ``spec.out_dir``; returns a summary with metrics and the
    traces needed for figures (t, rpy, setpoint, geodesic as lists)."""
    robot = load_robot_params(spec.robot_yaml)
    if spec.robot_overrides:
        robot = dataclasses.replace(robot, **{k: (np.array(v, dtype=float) if isinstance(v, tuple) else v)
                                              for k, v in spec.robot_overrides})
    config = load_controller_config(spec.controller_yaml, GAIN_ALIASES.get(spec.gains, spec.gains))
    if spec.normalize_force:
        config = dataclasses.replace(config, normalize_force_direction=True)
    if spec.config_overrides:
        config = dataclasses.replace(config, **dict(spec.config_overrides))
    if spec.scheme is not None:
        config = config.replace(stroke_scheme=spec.scheme)
    settings = load_simulation_settings(spec.simulation_yaml)
    if abs(settings.dt - config.dt) > 1e-12:
        raise ParameterError("simulation dt %g s differs from the controller period %g s" % (settings.dt, config.dt))
    # The servo speed is robot.yaml's (after overrides: identification varies servo_no_load_speed).
    servo_params = load_servo_params(spec.simulation_yaml, robot_yaml=spec.robot_yaml)
    nominal_speed = load_robot_params(spec.robot_yaml).servo_no_load_speed
    servo_params = dataclasses.replace(servo_params,
                                       max_speed=servo_params.max_speed * robot.servo_no_load_speed / nominal_speed)
    model = None
    if spec.plant != "paper":
        tank = load_tank_params(spec.tank_yaml)
        if spec.tank_overrides:
            tank = tank.with_values(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in spec.tank_overrides})
        model = make_plant(spec.plant, robot, tank)
        servo_params = dataclasses.replace(servo_params, max_speed=servo_params.max_speed * tank.servo_speed_scale)
    servo = make_servo_model(spec.servo_model, servo_params)
    if spec.controller not in ("on", "off"):
        raise ValueError("controller must be 'on' or 'off', got %r" % (spec.controller,))
    sim = ClosedLoopSimulation(
        robot, config, servo,
        initial_R=rpy_to_rot(*np.radians(spec.initial_rpy_deg)),
        setpoint_R=rpy_to_rot(*np.radians(spec.setpoint_rpy_deg)),
        restoring_offset=spec.restoring_offset, seed=spec.seed,
        attitude_noise=math.radians(spec.attitude_noise_deg), gyro_noise=spec.gyro_noise,
        model=model, controller_enabled=spec.controller == "on")
    result = sim.run(spec.duration, progress=_progress_printer(spec.label, spec.quiet))
    metrics = result.metrics()
    summary: Dict[str, Any] = {
        "label": spec.label,
        "setpoint_rpy_deg": list(spec.setpoint_rpy_deg),
        "initial_rpy_deg": list(spec.initial_rpy_deg),
        "gains": GAIN_ALIASES.get(spec.gains, spec.gains),
        "scheme": config.stroke_scheme,
        "plant": spec.plant,
        "robot_yaml": spec.robot_yaml or config_path("robot.yaml"),
        "nominal_foot_leg": [float(v) for v in robot.nominal_foot_leg],
        "metrics": metrics,
        "info": result.info,
        "wall_time": result.wall_time,
        "real_time_factor": result.real_time_factor,
    }
    if spec.scheme_metrics:
        summary["scheme_metrics"] = stroke_metrics(result, robot)
    if spec.out_dir:
        write_trial(result, metrics, spec.out_dir, title=spec.label)
        summary["out_dir"] = spec.out_dir
    if spec.keep_trace:
        k = max(1, int(spec.trace_stride))
        summary["trace"] = {"t": result.t[::k], "rpy": result.rpy[::k], "setpoint": result.setpoint_rpy,
                            "geodesic": result.geodesic[::k]}
    return summary


def stroke_metrics(result: SimulationResult, robot: Any, every: int = 5) -> Dict[str, float]:
    """Torque delivered by the paws, eq. (torque_leg) from the simulated joints (every ``every``-th sample,
    joint rates by central differences), against the commanded tau_sat: the mean delivered component along
    tau_sat over the mean |tau_sat| (``torque_ratio``) and the mean delivered component across it over the
    mean |tau_sat| (``torque_sideways``); and the fraction of samples with some pair in power."""
    from quadruped_control.allocation import estimate_body_torque

    n = result.t.size
    q = result.joint_positions.reshape(n, 4, 3)
    q_dot = np.gradient(q, result.t, axis=0)
    along, across, commanded = [], [], []
    for k in range(1, n - 1, every):
        tau_sat = result.tau_sat[k]
        norm = float(np.linalg.norm(tau_sat))
        delivered = estimate_body_torque(q[k], q_dot[k], result.rotation[k], result.omega[k], robot)
        commanded.append(norm)
        if norm > 1e-9:
            unit = tau_sat / norm
            along.append(float(delivered @ unit))
            across.append(float(np.linalg.norm(delivered - (delivered @ unit) * unit)))
    mean_cmd = float(np.mean(commanded)) if commanded else 0.0
    power = np.any(result.pair_phase == "power", axis=1)
    return {"torque_commanded_mean": mean_cmd,
            "torque_ratio": float(np.sum(along) / len(commanded) / mean_cmd) if mean_cmd > 0 else 0.0,
            "torque_sideways": float(np.sum(across) / len(commanded) / mean_cmd) if mean_cmd > 0 else 0.0,
            "power_fraction": float(np.mean(power))}


def write_trial(result: SimulationResult, metrics: Dict[str, Any], out_dir: str, title: str = "") -> None:
    """``timeseries.csv``, ``metrics.json`` and ``attitude.png`` of one trial into ``out_dir``."""
    from quadruped_control.plotting import plot_attitude

    os.makedirs(out_dir, exist_ok=True)
    result.write_csv(os.path.join(out_dir, "timeseries.csv"))
    with open(os.path.join(out_dir, "metrics.json"), "w") as stream:
        json.dump(dict(metrics, info=result.info), stream, indent=2, allow_nan=False)
    plot_attitude(result.t, result.rpy, result.setpoint_rpy, result.geodesic, os.path.join(out_dir, "attitude.png"),
                  title=title or None)


def _fmt(value: Any, spec: str = "%.2f") -> str:
    if value is None:
        return "--"
    return spec % value


def format_metrics_table(metrics: Dict[str, Any], label: str = "") -> str:
    """The paper's metrics as a short text table."""
    lines = []
    if label:
        lines.append(label)
    lines.append("theta_init = %.2f deg, settled = %s (smoothed geodesic error, last 30 s max %.2f deg)"
                 % (metrics["theta_init_deg"], "yes" if metrics["settled"] else "NO",
                    metrics["geodesic"]["max_smoothed_last_30s_deg"]))
    lines.append("axis    cmd[deg]   t_r[s]   t_s[s]  e_ss[deg]   M_p[%]")
    for axis in ("roll", "pitch", "yaw"):
        m = metrics[axis]
        lines.append("%-6s %9.1f %8s %8s %10s %8s" % (axis, m["setpoint_deg"], _fmt(m["t_r"]), _fmt(m["t_s"]),
                                                      _fmt(m["e_ss"]), _fmt(m["M_p"], "%.1f")))
    return "\n".join(lines)


def _run_many(specs: Sequence[TrialSpec], args: argparse.Namespace, desc: str) -> List[Dict[str, Any]]:
    """A study's trials through the study runner (executor, progress bar, resume from ``args.out``)."""
    return run_trials(run_trial, specs, args.out, jobs=args.jobs, dask_scheduler=args.dask_scheduler,
                      resume=args.resume, progress=not args.quiet, desc=desc)


def _strip(summary: Dict[str, Any]) -> Dict[str, Any]:
    return {k: v for k, v in summary.items() if k != "trace"}


def _study_config() -> Dict[str, Any]:
    return load_simulation_tree()


def _paper_sim_specs(args: argparse.Namespace, tree: Dict[str, Any], out: Optional[str],
                     label_prefix: str = "", **overrides: Any) -> List[TrialSpec]:
    paper = tree.get("paper_sim", {})
    setpoints = [float(v) for v in paper.get("setpoints_deg", [15.0, 45.0, 75.0])]
    initial = tuple(float(v) for v in paper.get("initial_rpy_deg", [0.0, 0.0, 0.0]))
    duration = args.duration if args.duration_given else float(paper.get("duration", 120.0))
    specs = []
    for amplitude in setpoints:
        fields = dict(label="%s%g deg" % (label_prefix, amplitude), setpoint_rpy_deg=(amplitude,) * 3,
                      initial_rpy_deg=initial, duration=duration, gains=str(paper.get("gains", "simulation")),
                      servo_model="ideal", seed=args.seed,
                      restoring_offset=tuple(args.restoring_offset) if args.restoring_offset else None,
                      out_dir=os.path.join(out, "trial_%g" % amplitude) if out else None,
                      robot_yaml=args.robot_yaml, quiet=True)
        fields.update(overrides)
        specs.append(TrialSpec(**fields))
    return specs


def study_paper_sim(args: argparse.Namespace) -> int:
    from quadruped_control.plotting import Trace, plot_trials

    os.makedirs(args.out, exist_ok=True)
    tree = _study_config()
    specs = _paper_sim_specs(args, tree, args.out, gains=GAIN_ALIASES[args.gains], servo_model=args.servo_model,
                             normalize_force=args.normalize_force, scheme=args.scheme, plant=args.plant or "paper",
                             tank_yaml=args.tank_yaml)
    start = time.perf_counter()
    summaries = _run_many(specs, args, "paper-sim")
    wall = time.perf_counter() - start
    traces = [Trace(s["trace"]["t"], s["trace"]["rpy"], s["trace"]["setpoint"], s["trace"]["geodesic"],
                    label=s["label"]) for s in summaries]
    figure = os.path.join(args.out, "paper_sim.png")
    plot_trials(traces, figure, title="Closed-loop simulation: setpoints on roll, pitch and yaw (%s gains, %s servos)"
                % (specs[0].gains, specs[0].servo_model))
    study = {"study": "paper-sim", "figure": figure, "wall_time": wall,
             "robot_yaml": args.robot_yaml or config_path("robot.yaml"),
             "all_settled": all(s["metrics"]["settled"] for s in summaries),
             "trials": [_strip(s) for s in summaries]}
    with open(os.path.join(args.out, "study.json"), "w") as stream:
        json.dump(study, stream, indent=2, allow_nan=False)
    for s in summaries:
        print(format_metrics_table(s["metrics"], "trial %s (%.0fx real time)" % (s["label"], s["real_time_factor"])))
        print()
    print("figure: %s\nstudy: %s\nall trials settled: %s (%.1f s wall)"
          % (figure, os.path.join(args.out, "study.json"), study["all_settled"], wall))
    return 0 if study["all_settled"] else 2


def study_robustness(args: argparse.Namespace) -> int:
    os.makedirs(args.out, exist_ok=True)
    tree = _study_config()
    robust = tree.get("robustness", {})
    delta = float(robust.get("initial_perturbation_deg", 0.5))
    seeds = [int(s) for s in robust.get("seeds", [1, 2, 3])]
    paper = tree.get("paper_sim", {})
    base_initial = np.array([float(v) for v in paper.get("initial_rpy_deg", [0.0, 0.0, 0.0])])
    variants: List[Tuple[str, List[TrialSpec]]] = []
    variants.append(("baseline (sim gains, ideal servos)", _paper_sim_specs(args, tree, None, "base ")))
    for seed in seeds:
        rng = np.random.default_rng(seed)
        initial = tuple((base_initial + rng.uniform(-delta, delta, 3)).tolist())
        variants.append(("initial +-%g deg, seed %d" % (delta, seed),
                         _paper_sim_specs(args, tree, None, "seed%d " % seed, initial_rpy_deg=initial, seed=seed)))
    variants.append(("experiment gains, ideal servos",
                     _paper_sim_specs(args, tree, None, "exp ", gains="experiment")))
    variants.append(("experiment gains, rate-limited servos",
                     _paper_sim_specs(args, tree, None, "exp-servo ", gains="experiment", servo_model="rate-limited")))
    variants.append(("sim gains, rate-limited servos",
                     _paper_sim_specs(args, tree, None, "servo ", servo_model="rate-limited")))
    variants.append(("sim gains, normalised force direction",
                     _paper_sim_specs(args, tree, None, "norm ", normalize_force=True)))
    # Sensitivity to the estimated parameters of config/robot.yaml (see docs/simulation_study.md).
    robot = load_robot_params(args.robot_yaml)
    neutral_mass = robot.rho * robot.paw_volume
    nominal = np.asarray(robot.nominal_foot_leg, dtype=float)
    variants.append(("paws neutrally buoyant (m_s = rho V_s)",
                     _paper_sim_specs(args, tree, None, "neutral ", robot_overrides=(("paw_mass", neutral_mass),))))
    variants.append(("paws twice as heavy in water",
                     _paper_sim_specs(args, tree, None, "heavy ", robot_overrides=(
                         ("paw_mass", neutral_mass + 2.0 * (robot.paw_mass - neutral_mass)),))))
    variants.append(("paper's literal pairs (1,2), (3,4)",
                     _paper_sim_specs(args, tree, None, "pairs12 ", config_overrides=(("pairs", ((1, 2), (3, 4))),))))
    for dz in (-0.01, 0.01):
        foot = tuple((nominal + np.array([0.0, 0.0, dz])).tolist())
        variants.append(("nominal foot %+.0f cm in z" % (100 * dz),
                         _paper_sim_specs(args, tree, None, "foot%+g " % dz,
                                          robot_overrides=(("nominal_foot_leg", foot),))))
    specs = [dataclasses.replace(spec, keep_trace=False) for _, group in variants for spec in group]
    start = time.perf_counter()
    summaries = _run_many(specs, args, "robustness")
    wall = time.perf_counter() - start
    rows = []
    index = 0
    for name, group in variants:
        for spec in group:
            s = summaries[index]
            index += 1
            m = s["metrics"]
            rows.append({
                "variant": name, "setpoint_deg": spec.setpoint_rpy_deg[0],
                "initial_rpy_deg": list(spec.initial_rpy_deg), "settled": m["settled"],
                "geodesic_max_last_30s_deg": m["geodesic"]["max_smoothed_last_30s_deg"],
                "geodesic_mean_last_10pct_deg": m["geodesic"]["mean_smoothed_last_10pct_deg"],
                "t_s_max": None if any(m[a]["t_s"] is None for a in ("roll", "pitch", "yaw"))
                else max(m[a]["t_s"] for a in ("roll", "pitch", "yaw")),
                "e_ss_deg": [m[a]["e_ss"] for a in ("roll", "pitch", "yaw")],
                "M_p": [m[a]["M_p"] for a in ("roll", "pitch", "yaw")],
                "metrics": m,
            })
    table = ["| variant | setpoint [deg] | settled | max smoothed geodesic error, last 30 s [deg] | "
             "mean, last 10 % [deg] | max t_s [s] | e_ss roll/pitch/yaw [deg] |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        table.append("| %s | %g | %s | %.2f | %.2f | %s | %s |" % (
            r["variant"], r["setpoint_deg"], "yes" if r["settled"] else "no", r["geodesic_max_last_30s_deg"],
            r["geodesic_mean_last_10pct_deg"], _fmt(r["t_s_max"], "%.1f"),
            " / ".join(_fmt(v) for v in r["e_ss_deg"])))
    with open(os.path.join(args.out, "robustness.json"), "w") as stream:
        json.dump({"study": "robustness", "wall_time": wall, "robot_yaml": args.robot_yaml or config_path("robot.yaml"),
                   "nominal_foot_leg": [float(v) for v in robot.nominal_foot_leg], "rows": rows},
                  stream, indent=2, allow_nan=False)
    with open(os.path.join(args.out, "robustness.md"), "w") as stream:
        stream.write("\n".join(table) + "\n")
    print("\n".join(table))
    print("\n%d trials in %.1f s wall; results in %s" % (len(rows), wall, args.out))
    return 0


def study_paper_experiments(args: argparse.Namespace) -> int:
    """The paper's 15 experiments (Table 1) on the chosen plant and gains: table (markdown + JSON) with
    the paper's values beside the simulated ones, and figures shaped like the paper's."""
    from quadruped_control.studies import paper_experiments as pe

    os.makedirs(args.out, exist_ok=True)
    plant = args.plant or "tank"
    gains = GAIN_ALIASES[args.gains]
    # The tank stands for the real robot: its servos are rate-limited; the paper's plant keeps the
    # configured default (the paper's ideal servos) unless --servo-model says otherwise.
    servo = args.servo_model_given or ("rate-limited" if plant == "tank" else args.servo_model)
    duration = args.duration if args.duration_given else pe.DURATION
    rows = list(pe.PAPER_TABLE)
    specs, tilts = _experiment_specs(args, plant, gains, servo, duration)
    start = time.perf_counter()
    results = _run_many(specs, args, "paper-experiments")
    wall = time.perf_counter() - start
    for result, tilt in zip(results, tilts):
        result["tilt_deg"] = tilt
    table_rows = pe.comparison_rows(rows, results)
    title = "%s plant, %s gains, %s servos, %g s trials" % (plant, gains, servo, duration)
    figures = pe.plot_sets(results, rows, os.path.join(args.out, "paper_experiments"), title)
    markdown = pe.format_table(table_rows, title)
    with open(os.path.join(args.out, "paper_experiments.md"), "w") as stream:
        stream.write(markdown)
    with open(os.path.join(args.out, "paper_experiments.json"), "w") as stream:
        json.dump({"study": "paper-experiments", "plant": plant, "gains": gains, "servo_model": servo,
                   "duration": duration, "wall_time": wall, "agreement": pe.agreement(table_rows),
                   "figures": figures, "rows": table_rows}, stream, indent=2, allow_nan=False)
    print(markdown)
    print("figures: %s\n%d trials in %.1f s wall" % (", ".join(figures), len(specs), wall))
    return 0


def _experiment_specs(args: argparse.Namespace, plant: str, gains: str, servo: str, duration: float,
                      tag: str = "", tank_overrides: Tuple[Tuple[str, Any], ...] = (),
                      keep_trace: bool = True) -> Tuple[List[TrialSpec], List[float]]:
    """The 15 trials of Table 1 (see :mod:`quadruped_control.studies.paper_experiments`) and their tilts."""
    from quadruped_control.studies import paper_experiments as pe

    specs, tilts = [], []
    for row in pe.PAPER_TABLE:
        initial, tilt = pe.initial_attitude(pe.setpoint_rpy_deg(row), row["theta_init"], row["psi_init"])
        tilts.append(tilt)
        overrides = (("t_rec", float(row["t_rec"])),) if gains == "experiment" and row["t_rec"] != 1.5 else ()
        specs.append(TrialSpec(label=(tag + " " if tag else "") + pe.case_label(row),
                               setpoint_rpy_deg=pe.setpoint_rpy_deg(row),
                               initial_rpy_deg=tuple(round(v, 9) for v in initial), duration=duration,
                               gains=gains, servo_model=servo, seed=args.seed, plant=plant, tank_yaml=args.tank_yaml,
                               robot_yaml=args.robot_yaml, quiet=True, config_overrides=overrides,
                               trace_stride=5, tank_overrides=tank_overrides, keep_trace=keep_trace))
    return specs, tilts


def study_identify(args: argparse.Namespace) -> int:
    """Fit the tank plant's uncertain parameters to Table 1 (:mod:`quadruped_control.studies.identify`)."""
    from quadruped_control.studies import identify as idf
    from quadruped_control.studies import paper_experiments as pe

    os.makedirs(args.out, exist_ok=True)
    duration = args.duration if args.duration_given else 160.0  # longest paper t_s 128.6 s + 30 s hold
    servo = args.servo_model_given or "rate-limited"
    rows = list(pe.PAPER_TABLE)
    start = time.perf_counter()

    def evaluate(points: List[Dict[str, float]], tag: str) -> List[Dict[str, Any]]:
        specs: List[TrialSpec] = []
        for i, values in enumerate(points):
            specs += _experiment_specs(args, "tank", "experiment", servo, duration, "%s%02d" % (tag, i),
                                       idf.tank_overrides(values), keep_trace=False)[0]
        results = _run_many(specs, args, "identify (%s)" % tag)
        out = []
        for i, values in enumerate(points):
            table = pe.comparison_rows(rows, results[15 * i:15 * (i + 1)])
            out.append({"values": values, "objective": idf.objective(table), "agreement": pe.agreement(table),
                        "rows": table})
        return out

    hypercube = evaluate(idf.latin_hypercube(args.points, args.seed), "lhs")
    costs = [e["objective"] for e in hypercube]
    sensitivity = {name: idf.spearman([e["values"][name] for e in hypercube], costs)
                   for name, _, _, _ in idf.PARAMETERS}
    best = min(hypercube, key=lambda e: e["objective"])
    ranked = sorted(sensitivity, key=lambda n: -abs(sensitivity[n]))[:args.refine]
    refine_points = []
    for name, _, low, high in idf.PARAMETERS:
        if name in ranked:
            for sign in (-1.0, 1.0):
                values = dict(best["values"])
                values[name] = min(high, max(low, values[name] + sign * (high - low) / 8.0))
                refine_points.append(values)
    refined = evaluate(refine_points, "ref") if refine_points else []
    steps = {}
    for e in refined:
        changed = [n for n in e["values"] if e["values"][n] != best["values"][n]]
        if changed:
            steps.setdefault(changed[0], []).append((e["values"][changed[0]], e["objective"] - best["objective"]))
    final = min([best] + refined, key=lambda e: e["objective"])
    wall = time.perf_counter() - start
    trials = 15 * (len(hypercube) + len(refined))
    note = "simulate --study identify (%d trials)" % trials
    with open(config_path("tank.yaml")) as stream:
        identified = idf.update_tank_yaml(stream.read(), final["values"], note)
    with open(os.path.join(args.out, "tank_identified.yaml"), "w") as stream:
        stream.write(identified)
    if args.write_config:
        with open(config_path("tank.yaml"), "w") as stream:
            stream.write(identified)
    report = {"study": "identify", "duration": duration, "servo_model": servo, "points": args.points,
              "refine": ranked, "trials": trials, "wall_time": wall, "best": final, "sensitivity_rank": sensitivity,
              "refinement_steps": steps, "hypercube": [{k: e[k] for k in ("values", "objective", "agreement")}
                                                       for e in hypercube]}
    with open(os.path.join(args.out, "identify.json"), "w") as stream:
        json.dump(report, stream, indent=2, allow_nan=False)
    lines = ["## Identification: %d trials (%d parameter sets x 15 experiments, %g s each), %.0f s wall"
             % (trials, len(hypercube) + len(refined), duration, wall), "",
             "Best objective %.2f: same settled outcome %d of 15, t_s within 2x %d of 15." % (
                 final["objective"], final["agreement"]["same_settled_outcome"], final["agreement"]["t_s_within_2x"]),
             "", "| parameter | low | high | best | rank correlation with the objective (hypercube) "
             "| objective change, refinement step down / up |", "|---|---|---|---|---|---|"]
    for name, _, low, high in idf.PARAMETERS:
        step = steps.get(name, [])
        lines.append("| %s | %g | %g | %.4g | %+.2f | %s |" % (
            name, low, high, final["values"][name], sensitivity[name],
            " / ".join("%+.2f" % d for _, d in sorted(step)) if step else "--"))
    lines += ["", pe.format_table(final["rows"], "Best parameter set: tank plant, experiment gains, %s servos" % servo)]
    with open(os.path.join(args.out, "identify.md"), "w") as stream:
        stream.write("\n".join(lines))
    print("\n".join(lines))
    print("results: %s; identified parameters: %s%s" % (args.out, os.path.join(args.out, "tank_identified.yaml"),
                                                        " (written to config/tank.yaml)" if args.write_config else ""))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python3 -m quadruped_control.simulate",
                                     description="Offline closed-loop simulation of the underwater quadruped's "
                                                 "attitude controller (the paper's model, no ROS).")
    parser.add_argument("--rpy", nargs=3, type=float, metavar=("R", "P", "Y"), default=[45.0, 45.0, 45.0],
                        help="setpoint roll pitch yaw, degrees (default 45 45 45)")
    parser.add_argument("--initial-rpy", nargs=3, type=float, metavar=("R", "P", "Y"), default=[0.0, 0.0, 0.0],
                        help="initial roll pitch yaw, degrees (default level)")
    parser.add_argument("--duration", type=float, default=None, help="trial length, s (default 120)")
    parser.add_argument("--gains", choices=("sim", "experiment"), default=None,
                        help="paper gain set: sim (K_p 5, K_i 0.15, K_d 1) or experiment (K_p 10, K_i 3, K_d 0.5); "
                             "default sim, experiment for --study paper-experiments")
    parser.add_argument("--servo-model", choices=("ideal", "rate-limited"), default=None,
                        help="servo model (default from config/simulation.yaml: ideal, the paper's)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the IMU noise (default 0)")
    parser.add_argument("--attitude-noise", type=float, default=None, metavar="DEG",
                        help="IMU attitude noise std, degrees (default from config: 0)")
    parser.add_argument("--gyro-noise", type=float, default=None, metavar="RAD_S",
                        help="gyro noise std per axis, rad/s (default from config: 0)")
    parser.add_argument("--normalize-force", action="store_true",
                        help="normalise the allocation's force direction tau_hat x r_hat (not in the paper)")
    parser.add_argument("--restoring-offset", nargs=3, type=float, metavar=("X", "Y", "Z"), default=None,
                        help="centre of buoyancy relative to the centre of mass, body frame, m (default: none)")
    parser.add_argument("--plant", choices=PLANTS, default=None,
                        help="plant model: paper (the paper's idealised model; default) or tank (the robot on "
                             "its rope in the test tank, config/tank.yaml)")
    parser.add_argument("--tank-yaml", default=None, metavar="PATH",
                        help="tank parameters for --plant tank (default: the package's config/tank.yaml)")
    parser.add_argument("--controller", choices=("on", "off"), default="on",
                        help="off holds the legs at the nominal pose (passive dynamics, ballast checks)")
    parser.add_argument("--robot-yaml", default=None, metavar="PATH",
                        help="robot model parameters for plant and controller (default: the package's "
                             "config/robot.yaml); the robustness study varies its estimates around this file")
    parser.add_argument("--scheme", choices=SCHEMES, default=None,
                        help="stroke scheme (default: stroke.scheme of config/controller.yaml, 'paper')")
    parser.add_argument("--points", type=int, default=12, help="identify: Latin hypercube size (default 12)")
    parser.add_argument("--refine", type=int, default=2,
                        help="identify: parameters refined around the best point (default 2)")
    parser.add_argument("--write-config", action="store_true",
                        help="identify: write the identified values into the package's config/tank.yaml")
    parser.add_argument("--study", choices=("paper-sim", "robustness", "schemes", "paper-experiments", "identify"),
                        default=None,
                        help="run a study (paper-experiments: Table 1's 15 experiments, default on the tank plant "
                             "with the experiment gains and rate-limited servos)")
    parser.add_argument("--perturbed", type=int, default=1,
                        help="schemes study: perturbed (+-0.5 deg) starts per case besides the nominal one (default 1)")
    parser.add_argument("--scheme-groups", default="paper-sim,table1,random",
                        help="schemes study: case groups (default %(default)s)")
    parser.add_argument("--scheme-gains", default="simulation,experiment",
                        help="schemes study: gain sets (default %(default)s)")
    parser.add_argument("--scheme-servos", default="ideal,rate-limited",
                        help="schemes study: servo models (default %(default)s)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                        help="worker processes for studies (default %(default)s)")
    parser.add_argument("--dask-scheduler", default=None, metavar="ADDRESS",
                        help="run a study's trials on an existing Dask cluster (e.g. tcp://host:8786) "
                             "instead of local processes")
    parser.add_argument("--no-resume", dest="resume", action="store_false",
                        help="run every trial of a study again instead of reusing DIR/trials/*.json")
    parser.add_argument("--out", default="simulation_output", help="output directory (default %(default)s)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.duration_given = args.duration is not None
    if args.gains is None:
        args.gains = "experiment" if args.study == "paper-experiments" else "sim"
    args.servo_model_given = args.servo_model
    if args.duration is None:
        args.duration = 120.0
    if not (math.isfinite(args.duration) and args.duration > 0.0):
        parser.error("--duration must be a positive number of seconds")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.plant == "tank" and args.restoring_offset is not None:
        parser.error("--restoring-offset is the paper plant's option; the tank plant's centre of buoyancy "
                     "is hydrostatics.center_of_buoyancy in config/tank.yaml (--tank-yaml)")
    for name in ("rpy", "initial_rpy", "restoring_offset"):
        value = getattr(args, name)
        if value is not None and not all(math.isfinite(v) for v in value):
            parser.error("--%s needs finite numbers" % name.replace("_", "-"))
    try:
        if args.robot_yaml is not None:
            args.robot_yaml = os.path.abspath(args.robot_yaml)
            load_robot_params(args.robot_yaml)  # fail early (exit 1) on a missing or invalid file
        settings = load_simulation_settings()
        if args.servo_model is None:
            args.servo_model = settings.servo_model
        attitude_noise = math.degrees(settings.attitude_noise) if args.attitude_noise is None else args.attitude_noise
        gyro_noise = settings.gyro_noise if args.gyro_noise is None else args.gyro_noise
        if attitude_noise < 0.0 or gyro_noise < 0.0 or not (math.isfinite(attitude_noise) and math.isfinite(gyro_noise)):
            parser.error("noise levels must be finite and non-negative")
        if args.study == "paper-sim":
            return study_paper_sim(args)
        if args.study == "robustness":
            return study_robustness(args)
        if args.study == "schemes":
            from quadruped_control.studies.schemes import main_study
            return main_study(args)
        if args.study == "paper-experiments":
            return study_paper_experiments(args)
        if args.study == "identify":
            if args.points < 2 or args.refine < 0:
                parser.error("--points must be >= 2 and --refine >= 0")
            return study_identify(args)
        spec = TrialSpec(label="setpoint %s deg" % " ".join("%g" % v for v in args.rpy),
                         setpoint_rpy_deg=tuple(args.rpy), initial_rpy_deg=tuple(args.initial_rpy),
                         duration=args.duration, gains=GAIN_ALIASES[args.gains], servo_model=args.servo_model,
                         seed=args.seed, normalize_force=args.normalize_force,
                         restoring_offset=tuple(args.restoring_offset) if args.restoring_offset else None,
                         attitude_noise_deg=attitude_noise, gyro_noise=gyro_noise, out_dir=args.out,
                         robot_yaml=args.robot_yaml, quiet=args.quiet, scheme=args.scheme, plant=args.plant or "paper",
                         tank_yaml=args.tank_yaml, controller=args.controller)
        summary = run_trial(spec)
    except (ParameterError, SimulationError, StudyError, ValueError) as exc:
        sys.stderr.write("simulate: error: %s\n" % exc)
        return 1
    print(format_metrics_table(summary["metrics"], "%s, %s plant, %s gains, %s servos, %s strokes, %.0f s (%.0fx real time)"
                               % (spec.label, spec.plant, spec.gains, spec.servo_model, summary["scheme"], spec.duration,
                                  summary["real_time_factor"])))
    print("wrote %s/{timeseries.csv, metrics.json, attitude.png}" % args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
