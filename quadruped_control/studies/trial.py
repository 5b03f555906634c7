"""One closed-loop trial of the offline simulator, as the studies run it: :class:`TrialSpec` (everything a
trial needs, picklable for worker processes), :func:`run_trial` (build the robot, controller, servo model
and plant, run, summarise the paper's metrics), the files a trial writes, and :func:`run_many`, a study's
trials through the study runner (:mod:`quadruped_control.studies.runner`).
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

from quadruped_common.config import ParameterError, config_path
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.magnetic_heading import true_rotation
from quadruped_control.sim.plants import load_tank_params, make_plant
from quadruped_control.sim.servo_model import load_servo_params, make_servo_model, tank_servo_params
from quadruped_control.sim.simulation import (ClosedLoopSimulation, SimulationError, SimulationResult,
                                              load_simulation_settings)
from quadruped_control.studies.runner import run_trial_batches, run_trials

#: --gains spellings -> gain set of config/controller.yaml
#: ``--engine auto`` runs a study batched from this many trials (all of which the batch can run): below
#: about a hundred trials numpy's per-call overhead makes the per-trial engine faster
#: (``benchmarks/bench_batch.py``: 15 trials batched run at 0.6x the per-trial engine's speed).
AUTO_BATCH_MIN = 100

GAIN_ALIASES = {"sim": "simulation", "simulation": "simulation", "experiment": "experiment", "exp": "experiment"}

__all__ = ["AUTO_BATCH_MIN", "GAIN_ALIASES", "ON_FAILURE", "TrialSetup", "TrialSpec", "batch_unsupported",
           "failed_summary", "format_metrics_table", "format_value",
           "run_batch", "run_many", "run_trial", "stroke_metrics", "trial_setup", "use_batch_engine", "without_trace",
           "write_trial"]


@dataclasses.dataclass(frozen=True)
class TrialSpec:
    """Everything one trial needs (picklable, for worker processes). Angles in degrees."""

    label: str
    setpoint_rpy_deg: Tuple[float, float, float]
    #: the initial attitude as the robot's IMU reports it (the true one unless the tank's IMU turns the heading)
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
    #: plant (:mod:`quadruped_control.sim.plants`): "paper" or "tank"; ``tank_yaml`` replaces config/tank.yaml
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
    #: What a trial whose closed loop cannot go on does (the plant diverged, the kinematics cannot close, or, on
    #: the batched engine, the controller would refuse a measurement): "raise" SimulationError, which stops a
    #: study, or "record" it as a summary with ``failed`` (the reason) and no metrics (:func:`failed_summary`):
    #: an identification scores such a parameter set and goes on.
    on_failure: str = "raise"


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


@dataclasses.dataclass
class TrialSetup:
    """What :func:`run_trial` and :func:`run_batch` build from a spec: robot, controller configuration,
    servo parameters (speed scaled as the spec's robot and tank say) and the plant model (None: the paper's)."""

    robot: Any
    config: Any
    servo_params: Any
    model: Any
    #: the plant's initial attitude: the spec's, which is what the robot's IMU reported (Table 1's theta_init
    #: and psi_init), turned back to the true heading when the tank's IMU turns it
    #: (:func:`~quadruped_control.sim.magnetic_heading.true_rotation`)
    initial_R: Any = None


def trial_setup(spec: TrialSpec) -> TrialSetup:
    """The robot, controller configuration, servo parameters and plant of ``spec`` (files and overrides)."""
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
        tank = tank.for_trial(spec.seed)  # a disturbed tank: each trial seed another draw of its disturbance
        model = make_plant(spec.plant, robot, tank)
        servo_params = tank_servo_params(servo_params, tank)
    initial_R = rpy_to_rot(*np.radians(spec.initial_rpy_deg))
    if model is not None and model.imu_field_residual is not None:
        initial_R = true_rotation(initial_R, model.imu_field_residual)
    return TrialSetup(robot=robot, config=config, servo_params=servo_params, model=model, initial_R=initial_R)


ON_FAILURE = ("raise", "record")


def _check_on_failure(spec: TrialSpec) -> None:
    if spec.on_failure not in ON_FAILURE:
        raise ValueError("trial %r: on_failure must be 'raise' or 'record', got %r" % (spec.label, spec.on_failure))


def failed_summary(spec: TrialSpec, reason: str, engine: str) -> Dict[str, Any]:
    """The summary of a trial that could not run to its end (``spec.on_failure`` "record"): what identifies
    it, ``failed`` (why) and ``metrics`` None."""
    return {"label": spec.label, "setpoint_rpy_deg": list(spec.setpoint_rpy_deg),
            "initial_rpy_deg": list(spec.initial_rpy_deg), "plant": spec.plant, "engine": engine,
            "failed": reason, "metrics": None}


def trial_simulation(spec: TrialSpec, setup: Optional[TrialSetup] = None) -> ClosedLoopSimulation:
    """The closed loop of ``spec`` (its :func:`trial_setup` unless given), at its start: what
    :func:`run_trial` runs, for a study that changes the setpoint during the run."""
    setup = setup if setup is not None else trial_setup(spec)
    if spec.controller not in ("on", "off"):
        raise ValueError("controller must be 'on' or 'off', got %r" % (spec.controller,))
    return ClosedLoopSimulation(
        setup.robot, setup.config, make_servo_model(spec.servo_model, setup.servo_params),
        initial_R=setup.initial_R,
        setpoint_R=rpy_to_rot(*np.radians(spec.setpoint_rpy_deg)),
        restoring_offset=spec.restoring_offset, seed=spec.seed,
        attitude_noise=math.radians(spec.attitude_noise_deg), gyro_noise=spec.gyro_noise,
        model=setup.model, controller_enabled=spec.controller == "on")


def run_trial(spec: TrialSpec) -> Dict[str, Any]:
    """Run one trial; writes its files if ``spec.out_dir``; returns a summary with metrics and the
    traces needed for figures (t, rpy, setpoint, geodesic as lists). A closed loop that cannot go on
    raises :class:`~quadruped_control.sim.simulation.SimulationError`, or with ``spec.on_failure``
    "record" returns :func:`failed_summary`."""
    _check_on_failure(spec)
    setup = trial_setup(spec)
    robot = setup.robot
    sim = trial_simulation(spec, setup)
    try:
        result = sim.run(spec.duration, progress=_progress_printer(spec.label, spec.quiet))
    except SimulationError as exc:
        if spec.on_failure == "record":
            return failed_summary(spec, str(exc), "trial")
        raise
    metrics = result.metrics()
    summary = _summary(spec, setup, metrics, result.info, result.wall_time, result.real_time_factor)
    if spec.scheme_metrics:
        summary["scheme_metrics"] = stroke_metrics(result, robot)
    if spec.out_dir:
        write_trial(result, metrics, spec.out_dir, title=spec.label)
        summary["out_dir"] = spec.out_dir
    if spec.keep_trace:
        summary["trace"] = _trace(spec, result.t, result.rpy, result.setpoint_rpy, result.geodesic)
    return summary


def _summary(spec: TrialSpec, setup: TrialSetup, metrics: Dict[str, Any], info: Dict[str, Any], wall_time: float,
             real_time_factor: float) -> Dict[str, Any]:
    """The summary of one trial that both engines return."""
    return {
        "label": spec.label,
        "setpoint_rpy_deg": list(spec.setpoint_rpy_deg),
        "initial_rpy_deg": list(spec.initial_rpy_deg),
        "gains": GAIN_ALIASES.get(spec.gains, spec.gains),
        "scheme": setup.config.stroke_scheme,
        "plant": spec.plant,
        "robot_yaml": spec.robot_yaml or config_path("robot.yaml"),
        "nominal_foot_leg": [float(v) for v in setup.robot.nominal_foot_leg],
        "metrics": metrics,
        "info": info,
        "engine": info.get("engine", "trial"),
        "wall_time": wall_time,
        "real_time_factor": real_time_factor,
    }


def _trace(spec: TrialSpec, t: np.ndarray, rpy: np.ndarray, setpoint_rpy: np.ndarray,
           geodesic: np.ndarray) -> Dict[str, Any]:
    """Every ``trace_stride``-th sample of the attitude traces (figures)."""
    k = max(1, int(spec.trace_stride))
    return {"t": t[::k], "rpy": rpy[::k], "setpoint": setpoint_rpy, "geodesic": geodesic[::k]}


def batch_unsupported(spec: TrialSpec) -> Optional[str]:
    """Why the batched engine (:mod:`quadruped_control.sim.batch`) cannot run ``spec``, or None if it can."""
    if spec.plant not in ("paper", "tank"):
        return "plant %r" % spec.plant
    if spec.out_dir:
        return "per-trial files (time series, figures)"
    return None


def _batch_group(spec: TrialSpec) -> Tuple[Any, ...]:
    """Specs with the same key share a robot, a period, a duration and a plant: one batch. The paper's
    scheme with the controller on runs the compiled controller loop, anything else the controller
    objects (:class:`~quadruped_control.sim.batch.BatchSimulation`): kept apart so the former stay fast."""
    compiled = spec.scheme in (None, "paper") and spec.controller == "on"
    return (spec.robot_yaml, spec.robot_overrides, spec.controller_yaml, spec.simulation_yaml, spec.duration,
            spec.plant, compiled)


def run_batch(specs: Sequence[TrialSpec]) -> List[Dict[str, Any]]:
    """Run ``specs`` on the batched engine, one batch per group of specs that share a robot, files and
    duration; returns the summaries :func:`run_trial` would (``engine`` 'batch', ``info`` with what the
    batch knows, the group's aggregate ``real_time_factor``). ValueError names a spec the batch cannot
    run (:func:`batch_unsupported`). A trial whose plant failed (where :func:`run_trial` raises) or whose
    measurement the robot's controller would refuse (where the per-trial controller holds, which the
    batch does not model) raises :class:`~quadruped_control.sim.simulation.SimulationError`, or with
    ``on_failure`` "record" returns :func:`failed_summary` (the other trials of its batch run on): the
    batch never returns metrics that differ from the per-trial engine's."""
    from quadruped_control.sim.batch import BatchSimulation, BatchTrial

    for spec in specs:
        _check_on_failure(spec)
        reason = batch_unsupported(spec)
        if reason is not None:
            raise ValueError("trial %r cannot run batched: %s" % (spec.label, reason))
    summaries: List[Optional[Dict[str, Any]]] = [None] * len(specs)
    groups: Dict[Tuple[Any, ...], List[int]] = {}
    for i, spec in enumerate(specs):
        groups.setdefault(_batch_group(spec), []).append(i)
    for indices in groups.values():
        setups = [trial_setup(specs[i]) for i in indices]
        trials = [BatchTrial(config=setup.config, setpoint=rpy_to_rot(*np.radians(specs[i].setpoint_rpy_deg)),
                             initial=setup.initial_R,
                             servo_model=specs[i].servo_model, servo_params=setup.servo_params,
                             restoring_offset=specs[i].restoring_offset,
                             tank=setup.model.tank if setup.model is not None else None, seed=specs[i].seed,
                             attitude_noise=math.radians(specs[i].attitude_noise_deg), gyro_noise=specs[i].gyro_noise,
                             controller_enabled=specs[i].controller == "on")
                  for i, setup in zip(indices, setups)]
        robot = setups[0].robot
        result = BatchSimulation(robot, trials).run(specs[indices[0]].duration,
                                                    stroke_metrics=any(specs[i].scheme_metrics for i in indices))
        for row, (i, setup) in enumerate(zip(indices, setups)):
            spec = specs[i]
            if not result.trusted(row):
                reason = "the controller would refuse a measurement (the batch has no hold)"
                if result.failed[row]:
                    reason = result.failure_reasons.get(row, "plant step failed (kinematics or a non-finite state)")
                if spec.on_failure == "record":
                    summaries[i] = failed_summary(spec, reason, "batch")
                    continue
                raise SimulationError("trial %r: %s" % (spec.label, reason))
            metrics = result.metrics(row)
            config = setup.config
            info = {"dt": config.dt, "duration": spec.duration, "servo_model": spec.servo_model,
                    "plant": spec.plant, "engine": "batch", "batch_size": len(indices),
                    "gains": dataclasses.asdict(config.gains), "tau_max": config.tau_max,
                    "t_rec": config.t_rec, "t_pow_max": config.t_pow_max,
                    "ik_fallbacks": int(result.ik_fallbacks[row]), "seed": spec.seed,
                    "attitude_noise_deg": spec.attitude_noise_deg, "gyro_noise": spec.gyro_noise,
                    "controller": spec.controller}
            summary = _summary(spec, setup, metrics, info, result.wall_time, result.real_time_factor)
            if spec.scheme_metrics:
                summary["scheme_metrics"] = result.stroke_metrics[row]
            if spec.keep_trace:
                summary["trace"] = _trace(spec, result.t, result.rpy[row], result.setpoint_rpy[row],
                                          result.geodesic[row])
            summaries[i] = summary
    return summaries  # type: ignore[return-value]


def stroke_metrics(result: SimulationResult, robot: Any, every: int = 5) -> Dict[str, float]:
    """The stroke metrics of one recorded trial
    (:class:`~quadruped_control.sim.stroke_metrics.StrokeTorqueMetrics`, which the batched engine feeds
    as it runs): torque delivered by the paws (eq. torque_leg from the simulated joints, every
    ``every``-th sample) against tau_sat, and the fraction of samples with some pair in power."""
    from quadruped_control.sim.stroke_metrics import StrokeTorqueMetrics

    metrics = StrokeTorqueMetrics(robot, 1, every)
    power = np.any(result.pair_phase == "power", axis=1)
    for k in range(result.t.size):
        metrics.add(result.t[k], result.joint_positions[k], result.rotation[k], result.omega[k], result.tau_sat[k],
                    power[k])
    return metrics.result(0)


def write_trial(result: SimulationResult, metrics: Dict[str, Any], out_dir: str, title: str = "") -> None:
    """``timeseries.csv``, ``metrics.json`` and ``attitude.png`` of one trial into ``out_dir``."""
    from quadruped_control.analysis.plotting import plot_attitude

    os.makedirs(out_dir, exist_ok=True)
    result.write_csv(os.path.join(out_dir, "timeseries.csv"))
    with open(os.path.join(out_dir, "metrics.json"), "w") as stream:
        json.dump(dict(metrics, info=result.info), stream, indent=2, allow_nan=False)
    plot_attitude(result.t, result.rpy, result.setpoint_rpy, result.geodesic, os.path.join(out_dir, "attitude.png"),
                  title=title or None)


def format_value(value: Any, spec: str = "%.2f") -> str:
    """``spec % value``, or '--' for a metric that is undefined (None)."""
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
        lines.append("%-6s %9.1f %8s %8s %10s %8s" % (axis, m["setpoint_deg"], format_value(m["t_r"]), format_value(m["t_s"]),
                                                      format_value(m["e_ss"]), format_value(m["M_p"], "%.1f")))
    return "\n".join(lines)


def use_batch_engine(specs: Sequence[TrialSpec], engine: str) -> bool:
    """Whether a study's ``specs`` run on the batched engine: ``engine`` 'batch' (ParameterError naming a
    spec it cannot run), 'trial' (never) or 'auto' (when the batch can run every spec and there are at
    least :data:`AUTO_BATCH_MIN` of them)."""
    if engine == "trial":
        return False
    reasons = [(spec.label, batch_unsupported(spec)) for spec in specs]
    refused = [(label, reason) for label, reason in reasons if reason is not None]
    if engine == "batch":
        if refused:
            raise ParameterError("--engine batch cannot run trial %r: %s" % refused[0])
        return True
    if engine != "auto":
        raise ParameterError("engine must be 'auto', 'trial' or 'batch', got %r" % (engine,))
    return not refused and len(specs) >= AUTO_BATCH_MIN


def run_many(specs: Sequence[TrialSpec], args: argparse.Namespace, desc: str) -> List[Dict[str, Any]]:
    """A study's trials through the study runner (executor, progress bar, resume from ``args.out``), on
    the batched engine when ``args.engine`` asks for it (:func:`use_batch_engine`)."""
    if use_batch_engine(specs, getattr(args, "engine", "trial")):
        return run_trial_batches(run_batch, list(specs), args.out, batch_size=getattr(args, "batch_size", 1500),
                                 jobs=args.jobs, dask_scheduler=args.dask_scheduler, resume=args.resume,
                                 progress=not args.quiet, desc=desc + " (batched)")
    return run_trials(run_trial, specs, args.out, jobs=args.jobs, dask_scheduler=args.dask_scheduler,
                      resume=args.resume, progress=not args.quiet, desc=desc)


def without_trace(summary: Dict[str, Any]) -> Dict[str, Any]:
    """A trial summary without its traces (for a study's JSON)."""
    return {k: v for k, v in summary.items() if k != "trace"}
