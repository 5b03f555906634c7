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
from quadruped_control.sim.plants import load_tank_params, make_plant
from quadruped_control.sim.servo_model import load_servo_params, make_servo_model
from quadruped_control.sim.simulation import ClosedLoopSimulation, SimulationResult, load_simulation_settings
from quadruped_control.studies.runner import run_trials

#: --gains spellings -> gain set of config/controller.yaml
GAIN_ALIASES = {"sim": "simulation", "simulation": "simulation", "experiment": "experiment", "exp": "experiment"}

__all__ = ["GAIN_ALIASES", "TrialSpec", "format_metrics_table", "format_value", "run_many",
           "run_trial", "stroke_metrics", "without_trace", "write_trial"]


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
    from quadruped_control.control.allocation import estimate_body_torque

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


def run_many(specs: Sequence[TrialSpec], args: argparse.Namespace, desc: str) -> List[Dict[str, Any]]:
    """A study's trials through the study runner (executor, progress bar, resume from ``args.out``)."""
    return run_trials(run_trial, specs, args.out, jobs=args.jobs, dask_scheduler=args.dask_scheduler,
                      resume=args.resume, progress=not args.quiet, desc=desc)


def without_trace(summary: Dict[str, Any]) -> Dict[str, Any]:
    """A trial summary without its traces (for a study's JSON)."""
    return {k: v for k, v in summary.items() if k != "trace"}
