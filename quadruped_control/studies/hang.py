"""What a hang tells: the robot hanging unpowered on its rope, legs still, recorded for minutes; its roll and
pitch fitted by a linear model pushed by the tank (:mod:`quadruped_control.analysis.hang`), and the fitted
stiffness set beside the tank.yaml files' own.

    python -m quadruped_control.studies.hang RUN [--skip 60] [--grid 0.1] [--max-gap 0.5] [--tether]
        [--tank-yaml Y] [--compare YAML_OR_DIR ...] [--model-hangs] --out DIR
    python -m quadruped_control.studies.hang --simulated TRUTH_YAML --tank-disturbance SIGMA TAU
        [--duration 660] [--seed 0] [--attitude-noise-deg 0.05] (and the options above)

A RUN is a bag (or a split recording's parts joined by commas) with ``/imu/data``, read by
:func:`quadruped_control.analysis.bag_report.read_bags`, or a folder: a tank day's (its hang run) or one run's
(:mod:`~quadruped_control.studies.day_folder`, which says what it found missing). The attitude's roll and pitch
(Z-Y-X Euler angles, REP 103) go on a ``--grid`` s grid by linear interpolation; samples not finite, quaternions far
from unit length, and gaps of more than ``--max-gap`` s end a stretch; the first ``--skip`` s (the robot let go and
settling) are left out. ``--simulated`` records the tank plant of TRUTH_YAML instead (the robot's own
trial with the controller off, legs at the nominal pose, through :func:`~.trial.run_trial`), in a tank that
pushes with ``--tank-disturbance SIGMA TAU`` and the IMU's attitude noise added: what a hang would tell
about a plant whose values are known, which the report then prints beside the fit.

Per axis the fit gives the restoring stiffness k about the attitude it hangs at, the damping c, the tank's
push sigma and its correlation time tau_d, and the IMU's noise, each with a 95 % interval, for the body's
rotational inertia I of ``--tank-yaml`` (rigid + added, legs at the nominal pose); with ``--tether`` also the
tether's relaxing bend k_r, tau_r (tank.yaml's ``tether`` section), which one hang pins down poorly. Beside it, for
``--tank-yaml`` and each ``--compare`` file (default: the shipped ensemble, config/tank_ensemble), the
plant's own moment at the measured hanging attitude (TankModel.restoring_torque: a model that would hang
there holds none) and its stiffness there (its slope over +-1 deg): a model whose stiffness lies outside
the interval does not hang like the robot. That static slope is not what a hang measures (the rope's swing
and a tether's bend add to it at the body's frequencies): ``--model-hangs`` hangs each compared model in the
simulator with the fitted push and fits it the same way, so that its stiffness is set beside the robot's as
the same instrument reads both. The tank's push goes into tank.yaml's ``disturbance`` section (the report
prints the lines). The legs' pose through the hang is read from the record's ``/joint_states``
(:func:`recorded_legs`), and what it moves in each model against the nominal pose the comparisons hold them at
is reported (:func:`legs_effect`).

Output in ``--out``: ``hang.json`` (the command, the code's fingerprint, the record, the fits, the
comparison), ``hang.md``, and ``hang.png`` (the record, and each axis's spectrum beside the fitted model's).
Docs: docs/identification.md, "What a hang tells".
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, config_path
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.analysis.bag_report import BagReportError, attitude_rpy, covered_by, read_bags, sorted_unique
from quadruped_control.analysis.hang import HangFit, fit_axis, spectral_density
from quadruped_control.model.params import RobotParams, load_robot_params
from quadruped_control.sim.plants.tank import TankModel
from quadruped_control.sim.plants.tank_params import TankParams, load_tank_params
from quadruped_control.sim.simulation import load_simulation_settings, nominal_joint_angles
from quadruped_control.studies import StudyError
from quadruped_control.studies.day_folder import is_folder, missing_text, one_run
from quadruped_control.studies.ensemble import DEFAULT_FOLDER, disturbance_overrides, tank_files
from quadruped_control.studies.runner import code_record, command_line, warn_uncommitted, write_study_report
from quadruped_control.studies.trial import TrialSpec, run_trial

__all__ = ["AXES", "HangRecord", "check_hanging", "compare_tank", "legs_effect", "main", "model_hang",
           "record_from_bag", "recorded_legs", "simulated_record", "tank_push", "tilt_inertia"]

#: The axes a hang measures: (name, index in roll-pitch-yaw and in the body's angular coordinates).
AXES = (("roll", 0), ("pitch", 1))

#: A record whose tilt leaves its mean by more than this (deg) did not hang: the linear model does not apply.
MAX_EXCURSION_DEG = 30.0

#: The slope of a model's restoring torque is taken over +- this (deg) about the hanging attitude.
SLOPE_STEP_DEG = 1.0


class HangRecord:
    """Roll and pitch (rad) on a uniform grid of ``dt`` s with the samples' validity; ``source`` names it."""

    def __init__(self, t: np.ndarray, roll: np.ndarray, pitch: np.ndarray, valid: np.ndarray, dt: float,
                 source: str) -> None:
        self.t, self.roll, self.pitch, self.valid, self.dt, self.source = t, roll, pitch, valid, dt, source

    def axis(self, name: str) -> np.ndarray:
        return self.roll if name == "roll" else self.pitch

    def after(self, skip: float) -> "HangRecord":
        """The record from ``skip`` s after its start."""
        keep = self.t >= self.t[0] + skip - 1e-9
        if np.count_nonzero(keep & self.valid) < 100:
            raise StudyError("hang: %s has fewer than 100 valid samples after the first %g s" % (self.source, skip))
        return HangRecord(self.t[keep], self.roll[keep], self.pitch[keep], self.valid[keep], self.dt, self.source)


def record_from_bag(times: Sequence[float], quaternions: Sequence[Sequence[float]], dt: float, max_gap: float,
                    source: str) -> HangRecord:
    """The /imu/data attitude (x, y, z, w quaternions at ``times``) as a :class:`HangRecord` (module
    docstring); StudyError if fewer than two usable samples."""
    t, rpy = attitude_rpy(times, quaternions)
    if t.size < 2:
        raise StudyError("hang: %s has fewer than two usable /imu/data samples" % source)
    roll, pitch = rpy[:, 0], rpy[:, 1]
    t = t - t[0]  # stamps since 1970 would round the grid's steps
    grid = dt * np.arange(int(math.floor(t[-1] / dt + 1e-9)) + 1)
    valid = covered_by(t, grid, max_gap)
    return HangRecord(grid, np.interp(grid, t, np.unwrap(roll)), np.interp(grid, t, pitch), valid, dt,
                      source)


def simulated_record(truth_yaml: str, disturbance: Sequence[float], duration: float, seed: int,
                     noise_deg: float, dt: float, robot_yaml: Optional[str]) -> HangRecord:
    """The hang of the tank plant of ``truth_yaml`` (module docstring): the robot's trial with the controller
    off for ``duration`` s in a tank pushing with ``disturbance`` (sigma N m, tau_d s), drawn by trial
    ``seed``, sampled every ``dt`` s (a multiple of the plant's step), with ``noise_deg`` of attitude
    noise (seeded) added to roll and pitch."""
    step = load_simulation_settings().dt  # the trial's step, config/simulation.yaml
    stride = int(round(dt / step))
    if stride < 1 or abs(stride * step - dt) > 1e-9:
        raise StudyError("hang: --grid must be a multiple of the plant's %g s step, got %r" % (step, dt))
    spec = TrialSpec(label="hang", setpoint_rpy_deg=(0.0, 0.0, 0.0), duration=duration, seed=seed, plant="tank",
                     tank_yaml=truth_yaml, robot_yaml=robot_yaml, controller="off", quiet=True,
                     tank_overrides=disturbance_overrides(disturbance), trace_stride=stride)
    summary = run_trial(spec)
    t = np.asarray(summary["trace"]["t"], dtype=float)
    rpy = np.asarray(summary["trace"]["rpy"], dtype=float)  # rad, as the IMU reports it
    rng = np.random.default_rng([seed, 0x4A6E])  # the IMU's noise, apart from the tank's draw
    noise = math.radians(noise_deg) * rng.standard_normal((t.size, 2))
    return HangRecord(t, rpy[:, 0] + noise[:, 0], rpy[:, 1] + noise[:, 1], np.ones(t.size, dtype=bool), dt,
                      "simulated: %s" % os.path.basename(truth_yaml))


def check_hanging(record: HangRecord) -> Dict[str, float]:
    """The mean roll and pitch (rad) of a record that hung; StudyError for one whose tilt left its mean by
    more than :data:`MAX_EXCURSION_DEG` (it tumbled, was handled, or drifted far: the linear model does not
    apply)."""
    mean = {}
    for name, _ in AXES:
        y = record.axis(name)[record.valid]
        mean[name] = float(np.mean(y))
        excursion = math.degrees(float(np.max(np.abs(y - mean[name]))))
        if excursion > MAX_EXCURSION_DEG:
            raise StudyError("hang: the %s left its mean by %.0f deg (more than %g): the robot did not hang still, "
                             "and the linear model does not apply" % (name, excursion, MAX_EXCURSION_DEG))
    return mean


def tank_push(fits: Dict[str, HangFit]) -> Optional[Dict[str, Any]]:
    """tank.yaml's ``disturbance`` from a hang: the mean of sigma and of tau_d over the axes that pin both
    down (an interval for each), with the axes used; None if no axis does."""
    used = [name for name, _ in AXES if fits[name].intervals["torque_std"] and fits[name].intervals["correlation_time"]]
    if not used:
        return None
    return {"torque_std": float(np.mean([fits[n].model.torque_std for n in used])),
            "correlation_time": float(np.mean([fits[n].model.correlation_time for n in used])), "axes": used}


def tilt_inertia(robot: RobotParams, tank: TankParams) -> Tuple[float, float]:
    """The body's rotational inertia about roll and pitch (kg m^2; rigid + added, legs at the nominal pose):
    the plant's mass matrix, whose angular block the hang model's I stands for."""
    model = TankModel(robot, tank)
    legs = model.leg_input(nominal_joint_angles(robot), np.zeros((4, 3)))
    mass = model.mass_matrix(legs.foot_positions.tolist())
    return float(mass[3, 3]), float(mass[4, 4])


def compare_tank(robot: RobotParams, tank: TankParams, roll: float, pitch: float,
                 legs: Optional[np.ndarray] = None) -> Dict[str, Dict[str, float]]:
    """A tank.yaml's plant at the measured hanging attitude (rad): per axis, the moment it would need held
    there (N m, body axes; TankModel.restoring_torque, its opposite) and its stiffness there (N m/rad, minus
    the slope of the moment over +-SLOPE_STEP_DEG, the tether's bend that never relaxes included; positive:
    restores), and its tether's relaxing bend (k_r N m/rad, tau_r s), which a slow tilt does not feel. The
    legs at the nominal pose, or at ``legs`` (4 x 3 joint angles, rad)."""
    model = TankModel(robot, tank)
    q = nominal_joint_angles(robot) if legs is None else np.asarray(legs, dtype=float).reshape(4, 3)
    step = math.radians(SLOPE_STEP_DEG)
    out: Dict[str, Dict[str, float]] = {}
    for name, index in AXES:
        def moment(offset: float) -> float:
            angles = [roll, pitch, 0.0]
            angles[index] += offset
            return float(model.restoring_torque(rpy_to_rot(*angles), q)[index])
        out[name] = {"torque": moment(0.0),
                     "stiffness": -(moment(step) - moment(-step)) / (2.0 * step),
                     "relaxing_stiffness": tank.tether_relaxing_stiffness,
                     "relaxation_time": tank.tether_relaxation_time}
    return out


def recorded_legs(times: Sequence[float], joints: Sequence[Sequence[float]], skip: float,
                  robot: RobotParams) -> Optional[np.ndarray]:
    """The legs' pose through a hang: each joint's median (rad, 4 x 3, JOINT_NAMES order) over the joint feedback
    (/joint_states, which the feedback node publishes unarmed too) from ``skip`` s after its first sample, readings
    outside the joint's servo range left out (a feedback potentiometer without its supply reads nonsense); None
    without a reading of every joint there."""
    t, rows = sorted_unique(times, np.asarray(joints, dtype=float).reshape(-1, 12))
    if t.size == 0:
        return None
    rows = rows[t >= t[0] + skip - 1e-9]
    limits = np.tile(robot.joint_limits.as_array(), (4, 1))  # (12, 2): low, high per joint
    rows = np.where((rows >= limits[:, 0]) & (rows <= limits[:, 1]), rows, np.nan)
    if rows.shape[0] == 0 or not np.all(np.any(np.isfinite(rows), axis=0)):
        return None
    return np.nanmedian(rows, axis=0).reshape(4, 3)


def legs_effect(robot: RobotParams, tank: TankParams, roll: float, pitch: float,
                legs: np.ndarray) -> Dict[str, Dict[str, float]]:
    """What the legs' recorded pose changes against the nominal pose the comparisons and ``--model-hangs`` hold
    them at, per axis at the hanging attitude on a tank.yaml's plant: the moment the paws and links set
    elsewhere add (N m) and the tilt that moves the hang by at the plant's stiffness there (rad; None where the
    plant does not restore)."""
    nominal = compare_tank(robot, tank, roll, pitch)
    recorded = compare_tank(robot, tank, roll, pitch, legs)
    out = {}
    for name, _ in AXES:
        moment = recorded[name]["torque"] - nominal[name]["torque"]
        stiffness = nominal[name]["stiffness"]
        out[name] = {"moment": moment, "tilt": moment / stiffness if stiffness > 0.0 else None}
    return out


def model_hang(path: str, push: Optional[Dict[str, Any]], record: HangRecord, skip: float, seed: int,
               noise_deg: float, inertia: Dict[str, float], interval: Dict[str, Optional[Tuple[float, float]]],
               tether: bool, robot_yaml: Optional[str]) -> Dict[str, Any]:
    """The tank.yaml ``path`` hung in the simulator as the robot was recorded (the fitted ``push``, the same
    length, ``skip`` and grid, the fitted IMU noise, trial ``seed``) and fitted the same way: its stiffness as a
    hang measures it, the rope's swing and a tether's bend included, set against the robot's ``interval``.
    ``{"hangs": False, "why": ...}`` for a model that tumbles, and None-valued figures without a push."""
    if push is None:
        return {"hangs": None, "why": "the robot's record pins no push to hang the model in"}
    duration = float(record.t[-1] - record.t[0]) + skip + record.dt
    simulated = simulated_record(path, (push["torque_std"], push["correlation_time"]), duration, seed, noise_deg,
                                 record.dt, robot_yaml).after(skip)
    try:
        mean = check_hanging(simulated)
    except StudyError as exc:
        return {"hangs": False, "why": str(exc).replace("hang: ", "", 1).replace("the robot did not", "it did not")}
    out: Dict[str, Any] = {"hangs": True, "mean_deg": {name: math.degrees(mean[name]) for name, _ in AXES}}
    for name, _ in AXES:
        fit = fit_axis(simulated.axis(name), simulated.dt, inertia[name], simulated.valid, tether=tether)
        out[name] = {"stiffness": fit.model.stiffness, "verdict": _verdict(fit.model.stiffness, interval[name])}
    return out


def _verdict(stiffness: float, interval: Optional[Tuple[float, float]]) -> str:
    if interval is None:
        return "not judged (k not pinned)"
    if stiffness < interval[0]:
        return "softer" if stiffness > 0.0 else "pushes away (k < 0)"
    return "stiffer" if stiffness > interval[1] else "inside"


def _interval_text(value: float, interval: Optional[Tuple[float, float]], scale: float, fmt: str) -> str:
    text = fmt % (value * scale)
    if interval is None:
        return text + " (not pinned)"
    return "%s (%s-%s)" % (text, fmt % (interval[0] * scale), fmt % (interval[1] * scale))


def _legs_text(report: Dict[str, Any]) -> str:
    """The legs' pose through the hang, and what it moves in each model, against the nominal pose the
    comparisons and the models' hangs hold them at."""
    legs = report["legs"]
    if legs is None:
        return ("The legs' pose is not known (the record has no joint feedback that reads every joint, or the hang "
                "is simulated); the comparisons assume them at the nominal pose.")
    moved = [entry["legs_as_recorded"] for entry in report["comparison"] if "why" not in entry["legs_as_recorded"]]
    if not moved:
        return ("The legs (the joint feedback's median after the skip) stood up to %.1f deg from the nominal pose, in "
                "a pose the models' legs cannot take (%s); the comparisons assume them at the nominal pose."
                % (legs["from_nominal_deg"], report["comparison"][0]["legs_as_recorded"]["why"]))
    parts = []
    for name, _ in AXES:
        moments = [abs(m[name]["moment"]) for m in moved]
        tilts = [abs(m[name]["tilt"]) for m in moved if m[name]["tilt"] is not None]
        parts.append("%s %.3g mN m%s" % (name, 1e3 * max(moments),
                                          ", %.2f deg" % math.degrees(max(tilts)) if tilts else ""))
    return ("The legs (the joint feedback's median after the skip) stood up to %.1f deg from the nominal pose, where "
            "the comparisons above and the models' hangs hold them. In the models that moves the hanging moment, and "
            "the attitude a model would hang at, by up to: %s. Compare it with the fitted push and the hang's tilt: "
            "a shift that is not small beside them says to repeat the hang with the legs at the nominal pose."
            % (legs["from_nominal_deg"], "; ".join(parts)))


def _text(report: Dict[str, Any]) -> str:
    lines = ["## A hang: %s" % report["source"], "",
             "%d s on a %g s grid after the first %g s; mean roll %.2f deg, pitch %.2f deg. Fitted per axis about "
             "that attitude (95 %% intervals; I from %s)." % (
                 report["seconds"], report["grid"], report["skip"], report["mean_deg"]["roll"],
                 report["mean_deg"]["pitch"], report["tank_yaml"]), "",
             "| axis | I [kg m^2] | k [mN m/rad] | c [mN m s/rad] | sigma [mN m] | tau_d [s] | noise [deg] | "
             "tilt std [deg] | c / k [s] |", "|---|---|---|---|---|---|---|---|---|"]
    for name, _ in AXES:
        fit = report["fits"][name]
        v, iv = fit["values"], fit["intervals"]
        lines.append("| %s | %.4f | %s | %s | %s | %s | %s | %.2f | %.3g |" % (
            name, fit["inertia"], _interval_text(v["stiffness"], iv["stiffness"], 1e3, "%.3g"),
            _interval_text(v["damping"], iv["damping"], 1e3, "%.3g"),
            _interval_text(v["torque_std"], iv["torque_std"], 1e3, "%.3g"),
            _interval_text(v["correlation_time"], iv["correlation_time"], 1.0, "%.3g"),
            _interval_text(v["noise_std"], iv["noise_std"], math.degrees(1.0), "%.3g"),
            math.degrees(fit["record_std"]), v["damping"] / v["stiffness"]))
        if fit["on_bound"]:
            lines.append("| | on a search bound: %s | | | | | | | |" % ", ".join(fit["on_bound"]))
    if report["tether"]:
        lines += ["", "The tether's relaxing bend (--tether; a slow tilt does not feel it):", "",
                  "| axis | k_r [mN m/rad] | tau_r [s] |", "|---|---|---|"]
        for name, _ in AXES:
            v, iv = report["fits"][name]["values"], report["fits"][name]["intervals"]
            lines.append("| %s | %s | %s |" % (
                name, _interval_text(v["relaxing_stiffness"], iv["relaxing_stiffness"], 1e3, "%.3g"),
                _interval_text(v["relaxation_time"], iv["relaxation_time"], 1.0, "%.3g")))
    if report.get("truth"):
        truth = report["truth"]
        lines += ["", "Truth (--simulated %s): sigma %.3g mN m, tau_d %.3g s; the truth's own stiffness at the "
                  "measured attitude: roll %.3g, pitch %.3g mN m/rad." % (
                      truth["tank_yaml"], truth["torque_std"] * 1e3, truth["correlation_time"],
                      truth["stiffness"]["roll"] * 1e3, truth["stiffness"]["pitch"] * 1e3)]
    push = report["disturbance"]
    if push is None:
        lines += ["", "The tank's push: no axis pins down both sigma and tau_d; a longer hang would (at least ten "
                  "times the longer of tau_d and the body's relaxation time c / k)."]
    else:
        lines += ["", "The tank's push for tank.yaml (the mean over %s):" % " and ".join(push["axes"]), "", "```yaml",
                  "disturbance:",
                  "  disturbance_torque_std: %.3g  # N m, from a hang (%s)" % (push["torque_std"], report["source"]),
                  "  disturbance_correlation_time: %.3g  # s" % push["correlation_time"], "```"]
    lines += ["", "Each model at the measured attitude: the moment it would need held there (a model that hangs there "
              "needs none) and its stiffness there, against the fitted interval.", "",
              "| tank.yaml | roll: held [mN m] | roll: k [mN m/rad] | pitch: held [mN m] | pitch: k [mN m/rad] "
              "| tether: k_r [mN m/rad], tau_r [s] |", "|---|---|---|---|---|---|"]
    for entry in report["comparison"]:
        cells = []
        for name, _ in AXES:
            side = entry[name]
            cells += ["%.3g" % (-side["torque"] * 1e3), "%.3g (%s)" % (side["stiffness"] * 1e3, side["verdict"])]
        cells.append("%.3g, %.3g" % (entry["roll"]["relaxing_stiffness"] * 1e3, entry["roll"]["relaxation_time"]))
        lines.append("| %s | %s |" % (entry["tank_yaml"], " | ".join(cells)))
    lines += ["", _legs_text(report)] + missing_text(report.get("missing", []))
    own = [entry for entry in report["comparison"] if "own_hang" in entry]
    if own:
        lines += ["", "Each model hung in the simulator with the fitted push (--model-hangs; trial seed %d) and fitted "
                  "the same way: its stiffness as a hang measures it (the rope's swing and a tether included), "
                  "against the robot's interval." % (report["seed"] + 1), "",
                  "| tank.yaml | hangs at roll, pitch [deg] | roll: k [mN m/rad] | pitch: k [mN m/rad] |",
                  "|---|---|---|---|"]
        for entry in own:
            hang_ = entry["own_hang"]
            if not hang_["hangs"]:
                lines.append("| %s | no: %s | | |" % (entry["tank_yaml"], hang_["why"]))
                continue
            lines.append("| %s | %.2f, %.2f | %s | %s |" % (
                entry["tank_yaml"], hang_["mean_deg"]["roll"], hang_["mean_deg"]["pitch"],
                *("%.3g (%s)" % (hang_[n]["stiffness"] * 1e3, hang_[n]["verdict"]) for n, _ in AXES)))
    return "\n".join(lines) + "\n"


def _plot(path: str, record: HangRecord, fits: Dict[str, HangFit]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.signal import welch

    figure, axes = plt.subplots(2, 1, figsize=(8, 7))
    for name, _ in AXES:
        axes[0].plot(record.t, np.degrees(record.axis(name)), lw=0.7, label=name)
    axes[0].set_xlabel("t [s]")
    axes[0].set_ylabel("attitude [deg]")
    axes[0].legend()
    for name, _ in AXES:
        y = record.axis(name)[record.valid]
        frequency, density = welch(y - y.mean(), fs=1.0 / record.dt, nperseg=min(y.size, 2048))
        model = fits[name].model
        floor = 2.0 * model.noise_std ** 2 * record.dt
        line, = axes[1].loglog(frequency[1:], density[1:], lw=0.7, label="%s: record (Welch)" % name)
        axes[1].loglog(frequency[1:], spectral_density(model, frequency[1:]) + floor, color=line.get_color(),
                       ls="--", label="%s: fitted model" % name)
    axes[1].set_xlabel("frequency [Hz]")
    axes[1].set_ylabel("PSD [rad^2/Hz]")
    axes[1].legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", nargs="?", metavar="RUN", help="the recorded hang: a bag, a split recording's "
                        "parts joined by commas, or a tank day's folder (its hang run)")
    parser.add_argument("--skip", type=float, default=60.0, help="leave out the first so many s (default %(default)s)")
    parser.add_argument("--grid", type=float, default=0.1, help="grid step, s (default %(default)s)")
    parser.add_argument("--max-gap", type=float, default=0.5,
                        help="a longer gap (s) in /imu/data ends a stretch (default %(default)s)")
    parser.add_argument("--tank-yaml", default=None, help="the body's inertia, and a model to compare "
                        "(default: config/tank.yaml)")
    parser.add_argument("--robot-yaml", default=None, help="robot parameters (default: config/robot.yaml)")
    parser.add_argument("--compare", nargs="*", default=None, metavar="YAML_OR_DIR",
                        help="tank.yaml files or folders of them to set beside the fit (default: the shipped "
                             "ensemble, config/%s)" % DEFAULT_FOLDER)
    parser.add_argument("--tether", action="store_true",
                        help="fit the tether's relaxing bend too (k_r, tau_r: tank.yaml's tether section)")
    parser.add_argument("--model-hangs", action="store_true",
                        help="hang each compared tank.yaml in the simulator with the fitted push and fit it the same "
                             "way: its stiffness as a hang measures it beside the robot's (about 30 s a model)")
    parser.add_argument("--simulated", metavar="TRUTH_YAML", help="fit a simulated hang on this tank.yaml instead")
    parser.add_argument("--tank-disturbance", nargs=2, type=float, metavar=("SIGMA", "TAU"),
                        help="--simulated: the tank's push, N m and s")
    parser.add_argument("--duration", type=float, default=660.0, help="--simulated: seconds (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="--simulated: the push's draw and the noise's seed")
    parser.add_argument("--attitude-noise-deg", type=float, default=0.05,
                        help="--simulated: the IMU's attitude noise, deg (default %(default)s)")
    parser.add_argument("--out", default="out/hang", help="output folder (default %(default)s)")
    args = parser.parse_args(argv)
    for flag, value in (("--grid", args.grid), ("--max-gap", args.max_gap), ("--duration", args.duration)):
        if not (math.isfinite(value) and value > 0.0):
            parser.error("%s must be a positive number of seconds, got %r" % (flag, value))
    if not (math.isfinite(args.skip) and args.skip >= 0.0):
        parser.error("--skip must be a number of seconds >= 0, got %r" % (args.skip,))
    if not (math.isfinite(args.attitude_noise_deg) and args.attitude_noise_deg > 0.0):
        parser.error("--attitude-noise-deg must be > 0 (a real IMU has some), got %r" % (args.attitude_noise_deg,))
    if bool(args.simulated) == bool(args.run):
        parser.error("give one recorded RUN or --simulated TRUTH_YAML")
    if args.simulated and args.tank_disturbance is None:
        parser.error("--simulated needs --tank-disturbance SIGMA TAU: a still tank does not move a hanging robot")
    if not args.simulated and args.tank_disturbance is not None:
        parser.error("--tank-disturbance belongs to --simulated")
    warn_uncommitted()
    try:
        robot = load_robot_params(args.robot_yaml)
        compare = [args.tank_yaml or config_path("tank.yaml")] + tank_files(
            args.compare if args.compare is not None else [config_path(DEFAULT_FOLDER)])
        compare = sorted(set(compare), key=compare.index)  # each file once, --tank-yaml's first
        tanks = [load_tank_params(path) for path in compare]
        tank = tanks[0]  # --tank-yaml's: the body's inertia
        legs = None  # a simulated hang holds the legs at the nominal pose
        missing: List[str] = []
        if args.simulated:
            truth_tank = load_tank_params(args.simulated)
            truth_tank.with_values(**dict(disturbance_overrides(args.tank_disturbance)))  # the push's bounds
            record = simulated_record(args.simulated, args.tank_disturbance, args.duration, args.seed,
                                      args.attitude_noise_deg, args.grid, args.robot_yaml)
        else:
            source = args.run
            if is_folder(args.run):
                run, missing = one_run(args.run, "hang", "hang", needs=("/imu/data",), wants=("/joint_states",))
                source = run.source
            paths = [part for part in source.split(",") if part]
            for path in paths:
                if not os.path.isfile(path):
                    raise StudyError("hang: no such bag: %s" % path)
            data = read_bags(paths)
            if not data.imu_t:
                raise StudyError("hang: %s has no /imu/data" % args.run)
            record = record_from_bag(data.imu_t, data.imu_q, args.grid, args.max_gap, source)
            legs = recorded_legs(data.joint_t, data.joint_q, args.skip, robot)
        record = record.after(args.skip)
        inertia = dict(zip(("roll", "pitch"), tilt_inertia(robot, tank)))
        fits: Dict[str, HangFit] = {}
        mean = check_hanging(record)
        for name, _ in AXES:
            fits[name] = fit_axis(record.axis(name), record.dt, inertia[name], record.valid, tether=args.tether)
        push = tank_push(fits)
        interval = {name: fits[name].intervals["stiffness"] for name, _ in AXES}
        noise_deg = math.degrees(float(np.mean([fits[name].model.noise_std for name, _ in AXES])))
        comparison = []
        for path, model in zip(compare, tanks):
            sides = compare_tank(robot, model, mean["roll"], mean["pitch"])
            for name, _ in AXES:
                sides[name]["verdict"] = _verdict(sides[name]["stiffness"], interval[name])
            entry: Dict[str, Any] = {"tank_yaml": os.path.basename(path), **sides}
            if legs is not None:
                try:
                    entry["legs_as_recorded"] = legs_effect(robot, model, mean["roll"], mean["pitch"], legs)
                except ValueError as exc:  # a pose the five-bar cannot take: said, and the study goes on
                    entry["legs_as_recorded"] = {"why": str(exc)}
            if args.model_hangs:
                entry["own_hang"] = model_hang(path, push, record, args.skip, args.seed + 1, noise_deg, inertia,
                                               interval, args.tether, args.robot_yaml)
            comparison.append(entry)
    except (ParameterError, BagReportError, ValueError) as exc:
        sys.stderr.write("hang: error: %s\n" % exc)
        return 1
    except StudyError as exc:
        sys.stderr.write("%s\n" % exc)
        return 1
    report: Dict[str, Any] = {
        "study": "hang", "command": command_line("quadruped_control.studies.hang", argv), **code_record(),
        "source": record.source, "seconds": float(record.t[-1] - record.t[0]), "grid": record.dt, "skip": args.skip,
        "tank_yaml": os.path.basename(args.tank_yaml or "tank.yaml"),
        "mean_deg": {name: math.degrees(mean[name]) for name, _ in AXES},
        "fits": {name: fits[name].as_dict() for name, _ in AXES},
        "disturbance": push,
        "comparison": comparison, "tether": args.tether, "seed": args.seed, "missing": missing,
        "legs": None if legs is None else {
            "joint_angles": legs.tolist(),
            "from_nominal_deg": math.degrees(float(np.max(np.abs(legs - nominal_joint_angles(robot)))))}}
    if args.simulated:
        truth = compare_tank(robot, truth_tank, mean["roll"], mean["pitch"])
        report["truth"] = {"tank_yaml": os.path.basename(args.simulated), "torque_std": args.tank_disturbance[0],
                           "correlation_time": args.tank_disturbance[1],
                           "stiffness": {name: truth[name]["stiffness"] for name, _ in AXES}}
    write_study_report(args.out, "hang", _text(report), report, lambda path: _plot(path, record, fits))
    return 0


if __name__ == "__main__":
    sys.exit(main())
