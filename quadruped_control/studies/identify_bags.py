"""Identify the tank plant from recorded runs: the measured joint angles replayed open loop through the
plant, its parameters fitted to the recorded attitude, and checked on runs held out of the fit.

    python -m quadruped_control.studies.identify_bags RUN [RUN ...] [--hold-out RUN ...] --out DIR
        [--tank-yaml Y] [--parameters P ...] [--window 10] [--stride 5] [--lead-in 5] [--every 10]
        [--max-gap 0.1] [--joint-filter-hz 10] [--evaluations 600] [--popsize 16] [--sigma 0.25] [--seed 0]
    python -m quadruped_control.studies.identify_bags --simulated TRUTH_YAML --rpy R P Y [--rpy ...]
        [--hold-out-rpy R P Y ...] [--initial-rpy R P Y] [--duration 120] [--gains experiment]
        [--attitude-noise-deg 0.2] [--joint-noise-deg 0.3] (and the options above)

A RUN is a recorded bag, the parts of one split recording joined by commas (``a_0.bag,a_1.bag``), or a folder: a
tank day's, whose armed runs (step test and Table 1) it stands for, and whose last round of Table-1 runs (the last
repeat, when there are two or more) is held out unless ``--hold-out`` names runs; or one run's
(:func:`expand_folders`; what the folder is missing is said, :mod:`~quadruped_control.studies.day_folder`).
Each is read with :func:`quadruped_control.analysis.bag_report.read_bags` (``/imu/data`` attitude and
body rate, ``/joint_states`` the ADS1115 feedback) and put on the plant's 10 ms grid
(:func:`record_from_bag`), and its joint angles are low-passed without delay at ``--joint-filter-hz``
(:func:`smoothed`: the replay differentiates them). Joint samples that are not finite, outside the servo
ranges or that the five-bar cannot close are skipped (:func:`quadruped_control.analysis.strokes.foot_paths`);
a gap of more than ``--max-gap`` s in either stream makes its samples invalid, and no window crosses them.

Why (docs/identification.md, "Identification from recorded runs"): Table 1 gives fifteen rows of summary
metrics, and fits to it leave the plant's physics undecided. A recorded run gives the attitude and every
joint angle at 100-200 Hz. Replayed with the measured joints (:mod:`quadruped_control.sim.replay`), the
plant runs without the controller and the servo model, so the servos' parameters (speed, lag, load) do
not enter it and ``--parameters`` refuses them: what the fit explains is the body's response to its legs'
motion. The servos have their own half (below).

Objective: the root mean square, over every window of ``--window`` s (one every ``--stride`` s) and every
``--every``-th step in it, of the geodesic angle between the replayed and the recorded attitude, in
degrees. Each window starts from the recorded attitude and body rate. The states no sensor measures (the
body's drift on its rope or in open water, the wakes, the floating block) come from a lead-in of
``--lead-in`` s before the window, in which the plant's attitude and body rate are held to the record's
(:func:`quadruped_control.sim.replay.replay`); 0 starts them at rest. Why: a free-floating body swims,
and a window that starts it at rest costs 2-3 deg of its error (docs/identification.md). Fit: CMA-ES over
the named parameters scaled into their bounds (:data:`quadruped_control.studies.identify_parameters.PARAMETERS`,
with their physical reasons), from the base tank.yaml's values, seeded
(:func:`quadruped_control.studies.identify_search.fit`). Reported on the training runs and the held-out runs
alike, beside two references: the base tank.yaml, and "still", a model that predicts no motion (the
attitude held at each window's start). A plant that does not beat "still" on held-out runs predicts
nothing.

The servos' half: where the runs recorded the controller's commands (``/servo_command``), the robot's
servo model (the rate-limited lag of config/simulation.yaml and robot.yaml, scaled by ``servo_speed_scale``
and ``servo_lag_scale``, with the dead band ``servo_dead_band``) is driven by the recorded commands from the
measured joints at each window start and compared with the measured joints
(:func:`quadruped_control.sim.replay.replay_servos`); the three are fitted on a grid over their bounds
(:func:`fit_servos`), beside the paper's ideal servo and the base's values. The two halves meet only in
the measured joints: the plant's fit does not depend on the servo model, nor the servos' on the plant.

``--simulated TRUTH_YAML`` replaces the bags with runs of the simulated robot on the tank plant of
TRUTH_YAML (the robot's controller, the ``--gains`` set and rate-limited servos, from ``--initial-rpy`` to
``--rpy``, one run per ``--rpy``, for ``--duration`` s) with the IMU's attitude noise and the feedback's
joint noise added (``--attitude-noise-deg``, ``--joint-noise-deg``, seeded): what a recorded run would
tell about a plant whose parameters are known. The report then adds the truth's values and objective.

Output in ``--out``: ``identify_bags.json`` (everything: the command, the code's fingerprint, each run's
source and windows, the values and objectives), ``identify_bags.md``, ``identify_bags.png`` (the first
held-out run, else the first run: recorded attitude and the replayed windows of the fit and the base)
and ``tank_fitted.yaml``, the base tank.yaml with the fitted values.
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
from quadruped_common.so3 import exp_so3, rpy_to_rot
from quadruped_control.analysis.bag_report import BagData, BagReportError, covered_by, read_bags, sorted_unique
from quadruped_control.analysis.strokes import foot_paths
from quadruped_control.model.params import RobotParams, load_robot_params
from quadruped_control.sim.magnetic_heading import reported_rotation
from quadruped_control.sim.plants.tank_params import TankParams, load_tank_params
from quadruped_control.sim.replay import (Record, attitude_errors, joint_errors, replay, replay_servos,
                                          sample_index, still_errors, window_starts)
from quadruped_control.sim.servo_model import ServoParams, load_servo_params
from quadruped_control.studies import StudyError
from quadruped_control.studies.day_folder import day_runs, is_folder, missing_text, say_missing
from quadruped_control.studies.identify_parameters import (BOUNDS, PARAMETERS, nominal_values, tank_overrides,
                                                           update_tank_yaml)
from quadruped_control.studies.identify_search import fit
from quadruped_control.studies.runner import code_record, command_line, describe_source, warn_uncommitted

__all__ = ["PLANT_PARAMETERS", "SERVO_FITTED", "SERVO_GRID", "SERVO_PARAMETERS", "ReplayObjective", "ServoObjective",
           "expand_folders", "fit_servos", "main", "read_run", "record_from_bag", "simulated_record", "smoothed"]

#: The identification's parameters of the servo model: the replay drives the plant with the measured
#: joints, so these do not enter it.
SERVO_PARAMETERS = ("servo_speed_scale", "servo_lag_scale", "servo_stall_torque_inverse", "servo_dead_band")
#: The heading the IMU reports (a residual field at it): a property of the sensor, not of the plant. The
#: replay starts each window from the recorded attitude as if it were the true one and compares the plant's
#: true attitude with the record, so it cannot fit them.
SENSOR_PARAMETERS = ("imu_field_residual_x", "imu_field_residual_y", "imu_field_residual_z")
#: Every parameter of :data:`~quadruped_control.studies.identify_parameters.PARAMETERS` that the replay can fit.
PLANT_PARAMETERS = tuple(name for name, _, _ in PARAMETERS if name not in SERVO_PARAMETERS + SENSOR_PARAMETERS)

#: The plant's step (s): the controller's period, on which the closed-loop engines hold the joints.
GRID_DT = 0.01


# --------------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------------

def _sorted_rows(t: Sequence[float], rows: Sequence[Sequence[float]], name: str) -> Tuple[np.ndarray, np.ndarray]:
    """The samples of one stream in stamp order, repeated stamps dropped (the bag report's
    :func:`~quadruped_control.analysis.bag_report.sorted_unique`), as (times, rows) arrays; StudyError if
    fewer than two remain."""
    times, kept = sorted_unique(t, rows)
    if times.size < 2:
        raise StudyError("identify_bags: the record has fewer than two %s samples" % name)
    return times, np.asarray(kept, dtype=float).reshape(times.size, -1)


def record_from_bag(data: BagData, robot: RobotParams, dt: float = GRID_DT, max_gap: float = 0.1,
                    source: str = "") -> Tuple[Record, int]:
    """A :class:`~quadruped_control.sim.replay.Record` of a read bag on a ``dt`` grid over the span both
    streams cover (module docstring): attitude by spherical interpolation of the IMU's quaternions, body
    rate and joints linearly; and the number of joint samples skipped as corrupt. StudyError if the bag
    lacks a stream or the streams do not overlap."""
    from scipy.spatial.transform import Rotation, Slerp

    if not data.imu_t or not data.joint_t:
        raise StudyError("identify_bags: %s has no %s" % (source or "the record", "/imu/data" if not data.imu_t
                                                          else "/joint_states"))
    imu_t, imu = _sorted_rows(data.imu_t, [tuple(q) + tuple(w) for q, w in zip(data.imu_q, data.imu_w)], "/imu/data")
    joint_t, joints = _sorted_rows(data.joint_t, data.joint_q, "/joint_states")
    quaternions, rates = imu[:, :4], imu[:, 4:]
    good_imu = np.all(np.isfinite(imu), axis=1) & (np.linalg.norm(np.nan_to_num(quaternions), axis=1) > 0.5)
    imu_t, quaternions, rates = imu_t[good_imu], quaternions[good_imu], rates[good_imu]
    _, good = foot_paths(joints, robot)
    skipped = int(np.count_nonzero(~good))
    joint_t, joints = joint_t[good], joints[good]
    if imu_t.size < 2 or joint_t.size < 2:
        raise StudyError("identify_bags: %s has fewer than two usable %s samples"
                         % (source or "the record", "/imu/data" if imu_t.size < 2 else "/joint_states"))
    start, end = max(imu_t[0], joint_t[0]), min(imu_t[-1], joint_t[-1])
    if end - start < 2.0 * dt:
        raise StudyError("identify_bags: the /imu/data and /joint_states of %s do not overlap"
                         % (source or "the record"))
    # times from the grid's start: stamps since 1970 would round the grid's steps
    imu_t, joint_t = imu_t - start, joint_t - start
    grid = dt * np.arange(int(math.floor((end - start) / dt + 1e-9)) + 1)
    rotation = Slerp(imu_t, Rotation.from_quat(quaternions))(np.clip(grid, imu_t[0], imu_t[-1])).as_matrix()
    omega = np.column_stack([np.interp(grid, imu_t, rates[:, axis]) for axis in range(3)])
    angles = np.column_stack([np.interp(grid, joint_t, joints[:, j]) for j in range(12)]).reshape(-1, 4, 3)
    valid = covered_by(imu_t, grid, max_gap) & covered_by(joint_t, grid, max_gap)
    return Record(t=grid, rotation=rotation, omega=omega, joints=angles, valid=valid, dt=dt, source=source,
                  commands=_held_commands(data, start, grid, max_gap)), skipped


def _held_commands(data: BagData, start: float, grid: np.ndarray, max_gap: float) -> Optional[np.ndarray]:
    """The /servo_command joint targets on the grid, each held from its stamp to the next (as the servos
    hold them); NaN before the first, after a gap of more than ``max_gap`` s, and where a target is not
    finite. None when the record has no commands."""
    if len(data.command_t) < 2:
        return None
    times, targets = _sorted_rows(data.command_t, data.command_q, "/servo_command")
    times = times - start
    index = np.searchsorted(times, grid + 1e-9, side="right") - 1  # the last command at or before each sample
    held = targets[np.clip(index, 0, None)].copy()
    stale = (index < 0) | (grid - times[np.clip(index, 0, None)] > max_gap)
    held[stale] = math.nan
    return held.reshape(-1, 4, 3)


def smoothed(record: Record, cutoff_hz: float) -> Record:
    """``record`` with its joint angles low-passed at ``cutoff_hz`` (0: unchanged) without delay: a
    second-order Butterworth run forwards and backwards (scipy's ``sosfiltfilt``) over each stretch of
    valid samples. Why: the replay holds the joints with their finite-difference rate over each 10 ms step,
    which turns a feedback noise of 0.3 deg into 40 deg/s of paw motion, and the paws' quadratic drag
    rectifies it into torque; the servos' own motion stays below about 10 Hz (a power stroke lasts
    0.1-0.3 s). A stretch too short to filter is marked invalid."""
    from scipy.signal import butter, sosfiltfilt

    if cutoff_hz == 0.0:
        return record
    nyquist = 0.5 / record.dt
    if not (math.isfinite(cutoff_hz) and 0.0 < cutoff_hz < nyquist):
        raise StudyError("identify_bags: the joint filter's cutoff must lie in (0, %g) Hz, got %r"
                         % (nyquist, cutoff_hz))
    sos = butter(2, cutoff_hz, fs=1.0 / record.dt, output="sos")
    joints, valid = record.joints.copy(), record.valid.astype(bool).copy()
    edges = np.flatnonzero(np.diff(np.concatenate(([0], valid.astype(int), [0]))))
    for first, end in zip(edges[::2], edges[1::2]):
        try:
            joints[first:end] = sosfiltfilt(sos, joints[first:end], axis=0)
        except ValueError:  # shorter than the filter's padding
            valid[first:end] = False
    return dataclasses.replace(record, joints=joints, valid=valid)


def read_run(run: str, robot: RobotParams, max_gap: float) -> Tuple[Record, int]:
    """The record of RUN (a bag, or the parts of one recording joined by commas)."""
    paths = [part for part in run.split(",") if part]
    for path in paths:
        if not os.path.isfile(path):
            raise StudyError("identify_bags: no such bag: %s" % path)
    try:
        data = read_bags(paths)
    except BagReportError as exc:
        raise StudyError("identify_bags: %s" % exc) from None
    return record_from_bag(data, robot, max_gap=max_gap, source=run)


def simulated_record(truth_yaml: str, setpoint_rpy_deg: Sequence[float], initial_rpy_deg: Sequence[float],
                     duration: float, gains: str = "experiment", attitude_noise_deg: float = 0.0,
                     joint_noise_deg: float = 0.0, seed: int = 0) -> Record:
    """A run of the simulated robot on the tank plant of ``truth_yaml`` (module docstring) as a bag would
    record it: the attitude the IMU reports (the true one, with the heading turned where the truth has a
    residual field at the IMU, :mod:`~quadruped_control.sim.magnetic_heading`) turned by an isotropic
    rotation-vector noise of ``attitude_noise_deg`` (std), the true body rate, and the servos' angles plus a
    noise of ``joint_noise_deg`` (std). The run starts where the IMU reports ``initial_rpy_deg``, as a
    Table-1 trial does (:class:`~quadruped_control.studies.trial.TrialSetup`'s ``initial_R``)."""
    from quadruped_control.sim.batch import BatchSimulation, BatchTrial
    from quadruped_control.studies.trial import TrialSpec, trial_setup

    spec = TrialSpec(label="simulated", setpoint_rpy_deg=tuple(setpoint_rpy_deg),
                     initial_rpy_deg=tuple(initial_rpy_deg), duration=duration, gains=gains,
                     servo_model="rate-limited", plant="tank", tank_yaml=truth_yaml)
    setup = trial_setup(spec)
    trial = BatchTrial(config=setup.config, setpoint=rpy_to_rot(*np.radians(spec.setpoint_rpy_deg)),
                       initial=setup.initial_R, servo_model="rate-limited",
                       servo_params=setup.servo_params, tank=setup.model.tank)
    simulation = BatchSimulation(setup.robot, [trial])
    samples = int(round(duration / simulation.dt)) + 1
    result = simulation.run(duration, record_states=samples)
    if not result.trusted(0):
        raise StudyError("identify_bags: the simulated run on %s failed" % truth_yaml)
    states = result.states
    rotation, omega, joints = states["rotation"][0].copy(), states["omega"][0].copy(), states["joints"][0].copy()
    if setup.model.imu_field_residual is not None:  # the bag holds what the IMU reported
        rotation = reported_rotation(rotation, setup.model.imu_field_residual)
    commands = np.full_like(joints, math.nan)
    commands[:-1] = states["targets"][0]  # none after the last step
    rng = np.random.default_rng(seed)
    if attitude_noise_deg > 0.0:
        noise = rng.normal(0.0, math.radians(attitude_noise_deg), size=(samples, 3))
        rotation = np.array([R @ exp_so3(n) for R, n in zip(rotation, noise)])
    if joint_noise_deg > 0.0:
        joints += rng.normal(0.0, math.radians(joint_noise_deg), size=joints.shape)
    return Record(t=result.t - result.t[0], rotation=rotation, omega=omega, joints=joints,
                  valid=np.ones(samples, dtype=bool), dt=simulation.dt, commands=commands,
                  source="simulated: %s, rpy %s from %s, %g s" % (truth_yaml, list(setpoint_rpy_deg),
                                                                 list(initial_rpy_deg), duration))


# --------------------------------------------------------------------------------------------------
# The objective
# --------------------------------------------------------------------------------------------------

class ReplayObjective:
    """The replay's objective (module docstring) over ``records``' windows of ``steps`` steps, one every
    ``stride`` samples, sampled every ``every`` steps, each after a lead-in of ``lead`` steps; parameter
    sets are partial: the rest is ``nominal`` (the base tank.yaml's values), applied to ``base``. Callable as
    :func:`~quadruped_control.studies.identify_search.fit` evaluates: ``objective(sets, cases, tag)`` -> one
    ``{"values", "objective"}`` per set (``cases`` and ``tag`` unused: every window counts)."""

    def __init__(self, robot: RobotParams, base: TankParams, nominal: Dict[str, float], records: Sequence[Record],
                 steps: int, stride: int, every: int, lead: int = 0) -> None:
        self.robot, self.base, self.nominal = robot, base, dict(nominal)
        self.steps, self.every, self.lead = steps, every, lead
        self.windows = [(record, window_starts(record, steps, stride, lead=lead)) for record in records]
        self.evaluations = 0

    @property
    def window_count(self) -> int:
        return int(sum(starts.size for _, starts in self.windows))

    def tank(self, values: Dict[str, float]) -> TankParams:
        return self.base.with_values(**dict(tank_overrides(dict(self.nominal, **values))))

    def errors(self, sets: Sequence[Dict[str, float]]) -> List[np.ndarray]:
        """Per record, the (S, W, M) geodesic errors (rad) of each set."""
        return self.errors_of([self.tank(values) for values in sets])

    def errors_of(self, tanks: Sequence[TankParams]) -> List[np.ndarray]:
        """Per record, the (S, W, M) geodesic errors (rad) of each whole tank plant."""
        self.evaluations += len(tanks)
        out = []
        for record, starts in self.windows:
            if starts.size:
                out.append(attitude_errors(replay(self.robot, tanks, record, starts, self.steps, self.every,
                                                  self.lead), record))
        return out

    @staticmethod
    def rms_deg(errors: Sequence[np.ndarray]) -> np.ndarray:
        """(S,) root mean square over every record, window and sample, in degrees."""
        squares = np.concatenate([e.reshape(e.shape[0], -1) ** 2 for e in errors], axis=1)
        return np.degrees(np.sqrt(squares.mean(axis=1)))

    def __call__(self, sets: Sequence[Dict[str, float]], cases: Any = None, tag: str = "") -> List[Dict[str, Any]]:
        if self.window_count == 0:
            raise StudyError("identify_bags: no window of %.2f s (after a lead-in of %.2f s) fits in the valid "
                             "samples of the records" % (self.steps * GRID_DT, self.lead * GRID_DT))
        objective = self.rms_deg(self.errors(sets))
        return [{"values": dict(values), "objective": float(value)} for values, value in zip(sets, objective)]

    def still_deg(self) -> float:
        """The objective of a model that predicts no motion (:func:`~quadruped_control.sim.replay.still_errors`)."""
        errors = [still_errors(record, starts, self.steps, self.every)[None]
                  for record, starts in self.windows if starts.size]
        return float(self.rms_deg(errors)[0])

    def per_window_deg(self, errors: Sequence[np.ndarray], row: int) -> List[List[float]]:
        """Per record, each window's root mean square error (deg) of set ``row`` of :meth:`errors`' result
        (a record without a window: an empty list)."""
        rows = iter(errors)
        return [[float(v) for v in np.degrees(np.sqrt(np.mean(next(rows)[row] ** 2, axis=-1)))] if starts.size else []
                for _, starts in self.windows]


class ServoObjective:
    """The servos' half (module docstring): the rate-limited lag of ``servo`` (the robot's servo, before
    tank.yaml's scales) driven by the recorded commands from the measured joints at each window start
    (:func:`~quadruped_control.sim.replay.replay_servos`), against the measured joints: the root mean square
    over the twelve joints, every window and sample, in degrees. Windows as :class:`ReplayObjective`'s,
    where every sample has a command."""

    def __init__(self, servo: ServoParams, records: Sequence[Record], steps: int, stride: int, every: int) -> None:
        self.servo, self.steps, self.every = servo, steps, every
        self.windows = [(record, window_starts(record, steps, stride, commanded=True)) for record in records]

    @property
    def window_count(self) -> int:
        return int(sum(starts.size for _, starts in self.windows))

    def _rms_deg(self, speeds: np.ndarray, lags: np.ndarray, bands: np.ndarray) -> np.ndarray:
        squares = [joint_errors(replay_servos(record, starts, self.steps, speeds, lags, self.every, bands), record,
                                starts, self.every).reshape(speeds.size, -1) ** 2
                   for record, starts in self.windows if starts.size]
        return np.degrees(np.sqrt(np.concatenate(squares, axis=1).mean(axis=1)))

    def __call__(self, speed_scales: Sequence[float], lag_scales: Sequence[float],
                 dead_bands: Sequence[float]) -> np.ndarray:
        """(S,) objective of each (servo_speed_scale, servo_lag_scale, servo_dead_band) set."""
        return self._rms_deg(self.servo.max_speed * np.asarray(speed_scales, dtype=float),
                             self.servo.time_constant * np.asarray(lag_scales, dtype=float),
                             np.asarray(dead_bands, dtype=float))

    def ideal_deg(self) -> float:
        """The paper's ideal servo: each joint at its command at once."""
        return float(self._rms_deg(np.array([math.inf]), np.array([0.0]), np.array([0.0]))[0])


#: The servo fit's first grid (:func:`fit_servos`), in the order of :data:`SERVO_FITTED`: servo_speed_scale
#: in steps of 0.05, servo_lag_scale in steps of 0.1 (3 ms), servo_dead_band in steps of 0.002 rad (0.11 deg)
#: over their bounds; the second grid has as many points per parameter as the first's speeds, one step
#: either side of the first's best.
SERVO_GRID = (11, 71, 11)


def fit_servos(objective: ServoObjective) -> Dict[str, Any]:
    """The :data:`SERVO_FITTED` values (bounds of identify.PARAMETERS) that minimise ``objective``: the grid
    :data:`SERVO_GRID` over the bounds, then a finer one around its best point (three parameters: the grid
    shows the whole landscape, and costs seconds; it is evaluated a dead band at a time, which bounds the
    replay's memory). Also each parameter's range on the first grid where its profile (the best over the
    others) lies within 1 % of the best (``within_1_percent``): a wide range says the runs do not pin that
    parameter down (a rate limit that never binds, a lag the strokes never reveal)."""
    bounds = [BOUNDS[name] for name in SERVO_FITTED]
    axes = [np.linspace(low, high, points) for (low, high), points in zip(bounds, SERVO_GRID)]
    best: Tuple[float, ...] = (math.inf, 0.0, 0.0, 0.0)
    near: Dict[str, List[float]] = {}
    for round_ in range(2):
        S, L = np.meshgrid(axes[0], axes[1], indexing="ij")
        table = np.array([objective(S.ravel(), L.ravel(), np.full(S.size, band)).reshape(S.shape)
                          for band in axes[2]])  # (bands, speeds, lags)
        b, i, j = np.unravel_index(int(np.argmin(table)), table.shape)
        if round_ == 0:  # how flat the landscape is: each parameter's profile (best over the others) on the grid
            limit = 1.01 * table[b, i, j]
            profiles = (table.min(axis=(0, 2)), table.min(axis=(0, 1)), table.min(axis=(1, 2)))
            for name, axis, profile in zip(SERVO_FITTED, axes, profiles):
                close = axis[profile <= limit]
                near[name] = [float(close.min()), float(close.max())]
        if table[b, i, j] < best[0]:
            best = (float(table[b, i, j]), float(axes[0][i]), float(axes[1][j]), float(axes[2][b]))
        steps = [axis[1] - axis[0] for axis in axes]
        axes = [np.linspace(max(low, centre - step), min(high, centre + step), SERVO_GRID[0])
                for (low, high), centre, step in zip(bounds, best[1:], steps)]
    fitted: Dict[str, Any] = dict(zip(SERVO_FITTED, best[1:]))
    fitted.update(objective=best[0], within_1_percent=near)
    return fitted


# --------------------------------------------------------------------------------------------------
# The study
# --------------------------------------------------------------------------------------------------

def _check_parameters(names: Sequence[str]) -> List[str]:
    unknown = [n for n in names if n not in BOUNDS]
    if unknown:
        raise StudyError("identify_bags: unknown parameter %s (one of identify.PARAMETERS)" % ", ".join(unknown))
    servo = [n for n in names if n in SERVO_PARAMETERS]
    if servo:
        raise StudyError("identify_bags: %s belong to the servo model, which the replay does not run: the "
                         "measured joint angles drive the plant" % ", ".join(servo))
    sensor = [n for n in names if n in SENSOR_PARAMETERS]
    if sensor:
        raise StudyError("identify_bags: %s belong to the IMU's heading, which the replay does not model: it "
                         "takes the recorded attitude as the true one" % ", ".join(sensor))
    if len(set(names)) != len(names):
        raise StudyError("identify_bags: a parameter is named twice")
    if len(names) < 2:  # pycma does not fit one dimension (pycma issue 86)
        raise StudyError("identify_bags: CMA-ES fits two or more parameters, got %d" % len(names))
    return list(names)


def expand_folders(runs: Sequence[str], hold_out: Sequence[str]) -> Tuple[List[str], List[str], List[str]]:
    """The training and held-out RUNs with each folder replaced by its usable armed runs (module docstring), and
    what the folders were missing."""
    training: List[str] = []
    held: List[str] = []
    missing: List[str] = []
    kinds = ("step_test", "table1")
    needs, wants = ("/imu/data", "/joint_states"), ("/servo_command",)
    for arg in runs:
        if not is_folder(arg):
            training.append(arg)
            continue
        found, lines = day_runs(arg, kinds, needs, wants)
        missing += lines
        if not found:
            raise StudyError("identify_bags: no usable step-test or Table-1 run in %s%s"
                             % (arg, "".join("\n  - " + line for line in lines)))
        last = max([run.repeat for run in found if run.kind == "table1"], default=0)
        out = [run for run in found if not hold_out and last > 1 and run.kind == "table1" and run.repeat == last]
        held += [run.source for run in out]
        training += [run.source for run in found if run not in out]
    for arg in hold_out:
        if is_folder(arg):
            found, lines = day_runs(arg, kinds, needs, wants)
            missing += lines
            held += [run.source for run in found]
        else:
            held.append(arg)
    return training, held, missing


def _records(args: argparse.Namespace, robot: RobotParams) -> Tuple[List[Record], List[Record], List[int]]:
    """The training and held-out records, and the corrupt joint samples skipped in each bag."""
    if args.simulated:
        if not args.rpy:
            raise StudyError("identify_bags: --simulated needs at least one --rpy")

        def runs(setpoints: Sequence[Sequence[float]], first_seed: int) -> List[Record]:
            return [smoothed(simulated_record(args.simulated, rpy, args.initial_rpy, args.duration, args.gains,
                                              args.attitude_noise_deg, args.joint_noise_deg, first_seed + i),
                             args.joint_filter_hz) for i, rpy in enumerate(setpoints)]

        return runs(args.rpy, args.seed), runs(args.hold_out_rpy or [], args.seed + len(args.rpy)), []
    if not args.runs:
        raise StudyError("identify_bags: name at least one recorded run (or --simulated)")
    training = [read_run(run, robot, args.max_gap) for run in args.runs]
    held_out = [read_run(run, robot, args.max_gap) for run in args.hold_out or []]
    return ([smoothed(r, args.joint_filter_hz) for r, _ in training],
            [smoothed(r, args.joint_filter_hz) for r, _ in held_out], [s for _, s in training + held_out])


#: The servo parameters the servos' half fits (:func:`fit_servos`); the load (servo_stall_torque_inverse) needs the
#: plant's joint loads and is not fitted.
SERVO_FITTED = ("servo_speed_scale", "servo_lag_scale", "servo_dead_band")


def _servo_study(servo: ServoParams, nominal: Dict[str, float], truth: Optional[Dict[str, float]],
                 training: Sequence[Record], held_out: Sequence[Record], steps: int, stride: int,
                 every: int) -> Optional[Dict[str, Any]]:
    """The servos' half of the report, None when no training run recorded its commands."""
    fitting = ServoObjective(servo, training, steps, stride, every)
    if fitting.window_count == 0:
        return None
    best = fit_servos(fitting)
    report: Dict[str, Any] = {"fitted": {n: best[n] for n in SERVO_FITTED},
                              "base": {n: nominal[n] for n in SERVO_FITTED},
                              "within_1_percent": best["within_1_percent"],
                              "servo": {"max_speed": servo.max_speed, "time_constant": servo.time_constant}}
    if truth is not None:
        report["truth"] = {n: truth[n] for n in SERVO_FITTED}
    for part, records in (("training", training), ("held_out", held_out)):
        side = fitting if part == "training" else ServoObjective(servo, records, steps, stride, every)
        summary: Dict[str, Any] = {"windows": side.window_count}
        if side.window_count:
            rows = [report["base"], report["fitted"]] + ([report["truth"]] if truth is not None else [])
            values = side(*([r[n] for r in rows] for n in SERVO_FITTED))
            summary.update(ideal=side.ideal_deg(), base=float(values[0]), fitted=float(values[1]))
            if truth is not None:
                summary["truth"] = float(values[2])
        report[part] = summary
    return report


def _plot(path: str, record: Record, objective: ReplayObjective, best: Dict[str, float], title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from quadruped_common.so3 import rotations_to_rpy

    # windows that do not overlap
    starts = window_starts(record, objective.steps, objective.steps, lead=objective.lead)
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    rpy = np.degrees(rotations_to_rpy(record.rotation))
    for axis, name in enumerate(("roll", "pitch", "yaw")):
        axes[axis].plot(record.t, rpy[:, axis], color="black", lw=1.0, label="recorded")
        axes[axis].set_ylabel(name + " [deg]")
    if starts.size:
        for label, values, style in (("fitted", best, "tab:blue"), ("base tank.yaml", {}, "tab:red")):
            result = replay(objective.robot, [objective.tank(values)], record, starts, objective.steps, objective.every,
                            objective.lead)
            for w, start in enumerate(starts):
                t = record.t[sample_index([start], result.rotation.shape[2], objective.every)[0]]
                replayed = np.degrees(rotations_to_rpy(result.rotation[0, w]))
                for axis in range(3):
                    axes[axis].plot(t, replayed[:, axis], color=style, lw=1.0, label=label if w == 0 else None)
    axes[0].legend(loc="best", fontsize=8)
    axes[0].set_title(title, fontsize=9)
    axes[2].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _text(report: Dict[str, Any]) -> str:
    lines = ["# The tank plant identified from recorded runs", "",
             "    " + " ".join(report["command"]), "",
             "Code %s (%s); %d parameter sets evaluated, %.0f s wall." % (
                 report["code"], describe_source(report.get("code_source", {})), report["evaluations"],
                 report["wall_time"]), ""]
    lines += ["| runs | windows | still [deg] | base tank.yaml [deg] | fitted [deg] |%s" %
              (" truth [deg] |" if "truth" in report else ""), "|---|---|---|---|---|%s" %
              ("---|" if "truth" in report else "")]
    for part in ("training", "held_out"):
        side = report[part]
        if not side["windows"]:
            continue
        row = "| %s (%d) | %d | %.2f | %.2f | %.2f |" % (part.replace("_", " "), len(side["runs"]), side["windows"],
                                                       side["still"], side["base"], side["fitted"])
        if "truth" in report:
            row += " %.2f |" % side["truth"]
        lines.append(row)
    start = ("after a lead-in of %g s with the attitude held to the record's" % report["lead_in"] if report["lead_in"]
             else "from the unmeasured states at rest")
    lines += ["", "Root mean square geodesic error between the replayed and the recorded attitude over windows "
              "of %g s, one every %g s, each %s." % (report["window"], report["stride"], start), ""]
    lines += ["| parameter | bounds | base | fitted |%s" % (" truth |" if "truth" in report else ""),
              "|---|---|---|---|%s" % ("---|" if "truth" in report else "")]
    for name in report["parameters"]:
        low, high = BOUNDS[name]
        row = "| %s | %.4g .. %.4g | %.4g | %.4g |" % (name, low, high, report["base"][name], report["fitted"][name])
        if "truth" in report:
            row += " %.4g |" % report["truth"]["values"][name]
        lines.append(row)
    servos = report.get("servos")
    lines.append("")
    if servos is None:
        lines.append("No training run recorded /servo_command: the servos are not fitted.")
    else:
        truth = "truth" in servos
        lines += ["The servos: the rate-limited lag driven by the recorded commands from the measured joints, root "
                  "mean square joint error [deg] (no-load speed %.2f rad/s and lag %.3f s before the scales):"
                  % (servos["servo"]["max_speed"], servos["servo"]["time_constant"]), "",
                  "| runs | windows | ideal servo | base | fitted |%s" % (" truth |" if truth else ""),
                  "|---|---|---|---|---|%s" % ("---|" if truth else "")]
        for part in ("training", "held_out"):
            side = servos[part]
            if side["windows"]:
                lines.append("| %s | %d | %.3f | %.3f | %.3f |%s" % (
                    part.replace("_", " "), side["windows"], side["ideal"], side["base"], side["fitted"],
                    " %.3f |" % side["truth"] if truth else ""))
        lines += ["", "| servo parameter | bounds | base | fitted | within 1 %% of the best |%s"
                  % (" truth |" if truth else ""), "|---|---|---|---|---|%s" % ("---|" if truth else "")]
        for name in SERVO_FITTED:
            low, high = BOUNDS[name]
            lines.append("| %s | %.4g .. %.4g | %.4g | %.4g | %.4g .. %.4g |%s" % (
                name, low, high, servos["base"][name], servos["fitted"][name], *servos["within_1_percent"][name],
                " %.4g |" % servos["truth"][name] if truth else ""))
    for part in ("training", "held_out"):
        for run in report[part]["runs"]:
            lines.append("")
            lines.append("- %s (%s): %.1f s, %d windows; per window, fitted [deg]: %s" % (
                run["source"], part.replace("_", " "), run["duration"], len(run["fitted_per_window"]),
                ", ".join("%.2f" % e for e in run["fitted_per_window"]) or "-"))
    return "\n".join(lines + missing_text(report.get("missing", []))) + "\n"


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="*", metavar="RUN", help="recorded runs to fit: a bag, a split "
                        "recording's parts joined by commas, or a tank day's folder")
    parser.add_argument("--hold-out", nargs="+", default=[], metavar="RUN", help="runs to predict, not fitted")
    parser.add_argument("--tank-yaml", default=None, help="base tank parameters (default: config/tank.yaml)")
    parser.add_argument("--robot-yaml", default=None, help="robot parameters (default: config/robot.yaml)")
    parser.add_argument("--parameters", nargs="+", default=list(PLANT_PARAMETERS), metavar="NAME",
                        help="parameters to fit (default: every plant parameter of identify.PARAMETERS)")
    parser.add_argument("--window", type=float, default=10.0, help="window length, s (default %(default)s)")
    parser.add_argument("--stride", type=float, default=5.0, help="one window every so many s (default %(default)s)")
    parser.add_argument("--lead-in", type=float, default=5.0, help="before each window, so many s with the "
                        "attitude held to the record's, 0: the unmeasured states start at rest (default %(default)s)")
    parser.add_argument("--every", type=int, default=10, help="compare every n-th step (default %(default)s)")
    parser.add_argument("--max-gap", type=float, default=0.1,
                        help="a longer gap (s) in a stream makes its samples invalid (default %(default)s)")
    parser.add_argument("--joint-filter-hz", type=float, default=10.0,
                        help="low-pass the joint angles without delay at this cutoff, 0: off (default %(default)s)")
    parser.add_argument("--evaluations", type=int, default=600, help="parameter sets (default %(default)s)")
    parser.add_argument("--popsize", type=int, default=16, help="CMA-ES population (default %(default)s)")
    parser.add_argument("--sigma", type=float, default=0.25, help="CMA-ES step, of each range (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="the fit's and the simulated noise's seed")
    parser.add_argument("--simulated", metavar="TRUTH_YAML", help="fit simulated runs on this tank.yaml instead")
    parser.add_argument("--rpy", nargs=3, type=float, action="append", metavar=("R", "P", "Y"),
                        help="--simulated: a run's setpoint, deg (repeat for more runs)")
    parser.add_argument("--hold-out-rpy", nargs=3, type=float, action="append", metavar=("R", "P", "Y"),
                        help="--simulated: a held-out run's setpoint, deg")
    parser.add_argument("--initial-rpy", nargs=3, type=float, default=[0.0, 0.0, 60.0], metavar=("R", "P", "Y"),
                        help="--simulated: initial attitude, deg (default %(default)s)")
    parser.add_argument("--duration", type=float, default=120.0, help="--simulated: run length, s")
    parser.add_argument("--gains", default="experiment", help="--simulated: gain set (default %(default)s)")
    parser.add_argument("--attitude-noise-deg", type=float, default=0.2, help="--simulated: IMU attitude noise")
    parser.add_argument("--joint-noise-deg", type=float, default=0.3, help="--simulated: joint feedback noise")
    parser.add_argument("--out", default="out/identify_bags", help="output folder (default %(default)s)")
    args = parser.parse_args(argv)
    warn_uncommitted()  # before any trial runs: a dirty tree's figures name no commit
    positive = {"--window": args.window, "--stride": args.stride, "--max-gap": args.max_gap,
                "--duration": args.duration}
    for flag, value in positive.items():
        if not (math.isfinite(value) and value > 0.0):
            parser.error("%s must be a positive number of seconds, got %r" % (flag, value))
    if not (math.isfinite(args.lead_in) and args.lead_in >= 0.0):
        parser.error("--lead-in must be a number of seconds >= 0, got %r" % (args.lead_in,))
    if args.every < 1 or args.evaluations < 1 or args.popsize < 2 or args.seed < 0:
        parser.error("--every and --evaluations must be >= 1, --popsize >= 2, --seed >= 0")
    if not (math.isfinite(args.sigma) and 0.0 < args.sigma <= 0.5):
        parser.error("--sigma must lie in (0, 0.5], a step of the scaled [0, 1] range; got %r" % args.sigma)
    for flag in ("attitude_noise_deg", "joint_noise_deg"):
        value = getattr(args, flag)
        if not (math.isfinite(value) and value >= 0.0):
            parser.error("--%s must be a finite std >= 0, got %r" % (flag.replace("_", "-"), value))
    steps, stride = int(round(args.window / GRID_DT)), max(1, int(round(args.stride / GRID_DT)))
    lead = int(round(args.lead_in / GRID_DT))
    if steps < args.every:
        parser.error("--window must hold at least --every steps of %g s" % GRID_DT)
    if args.simulated and (args.runs or args.hold_out):
        parser.error("give recorded runs or --simulated, not both")
    if not args.simulated and (args.rpy or args.hold_out_rpy):
        parser.error("--rpy and --hold-out-rpy belong to --simulated")
    try:
        names = _check_parameters(args.parameters)
        start_time = time.perf_counter()
        robot = load_robot_params(args.robot_yaml)
        base = load_tank_params(args.tank_yaml)
        nominal = nominal_values(base)
        args.runs, args.hold_out, missing = expand_folders(args.runs, args.hold_out or [])
        say_missing("identify_bags", missing)
        training, held_out, skipped = _records(args, robot)
        objective = ReplayObjective(robot, base, nominal, training, steps, stride, args.every, lead)
        # the base itself competes: a short search need not find a set better than its start (and its
        # evaluation refuses training runs without a window)
        evaluated = sorted(objective([{n: nominal[n] for n in names}])
                           + fit(objective, names, nominal, nominal, args.evaluations, args.popsize, args.seed, None,
                                 "fit", sigma=args.sigma), key=lambda r: r["objective"])
        best = evaluated[0]["values"]
        fitted = {n: float(best[n]) for n in names}
        check = ReplayObjective(robot, base, nominal, held_out, steps, stride, args.every, lead)
        truth_tank = load_tank_params(args.simulated) if args.simulated else None
        truth = nominal_values(truth_tank) if truth_tank is not None else None
        sides = {}
        for part, side, records in (("training", objective, training), ("held_out", check, held_out)):
            summary: Dict[str, Any] = {"windows": side.window_count, "runs": []}
            per_window: List[List[float]] = [[] for _ in records]
            if side.window_count:
                errors = side.errors([{}, fitted])  # the base and the fit in one batch
                base_deg, fitted_deg = side.rms_deg(errors)
                summary.update(still=side.still_deg(), base=float(base_deg), fitted=float(fitted_deg))
                per_window = side.per_window_deg(errors, 1)
                if truth_tank is not None:  # the whole truth, whatever the base holds outside the parameters
                    summary["truth"] = float(side.rms_deg(side.errors_of([truth_tank]))[0])
            for record, windows in zip(records, per_window):
                summary["runs"].append({"source": record.source, "duration": record.duration,
                                        "valid_fraction": float(np.mean(record.valid)),
                                        "fitted_per_window": windows})
            sides[part] = summary
        servos = _servo_study(load_servo_params(None, robot_yaml=args.robot_yaml), nominal, truth, training, held_out,
                              steps, stride, args.every)
    except (StudyError, ParameterError) as exc:
        print(str(exc), file=sys.stderr)
        return 1
    os.makedirs(args.out, exist_ok=True)
    report: Dict[str, Any] = {
        "study": "identify_bags", "command": command_line("quadruped_control.studies.identify_bags", argv),
        **code_record(),
        "tank_yaml": os.path.abspath(args.tank_yaml or config_path("tank.yaml")), "parameters": names,
        "window": args.window, "stride": args.stride, "lead_in": args.lead_in, "every": args.every, "seed": args.seed,
        "joint_filter_hz": args.joint_filter_hz,
        "evaluations": objective.evaluations, "popsize": args.popsize, "sigma": args.sigma,
        "skipped_joint_samples": skipped, "base": {n: nominal[n] for n in names}, "fitted": fitted,
        "fit_objective": evaluated[0]["objective"], "training": sides["training"], "held_out": sides["held_out"],
        "servos": servos, "wall_time": time.perf_counter() - start_time, "missing": missing}
    if truth is not None:
        report["truth"] = {"tank_yaml": os.path.abspath(args.simulated), "values": {n: truth[n] for n in names},
                           "attitude_noise_deg": args.attitude_noise_deg, "joint_noise_deg": args.joint_noise_deg}
    with open(os.path.join(args.out, "identify_bags.json"), "w") as stream:
        json.dump(report, stream, indent=1, allow_nan=False)
    with open(args.tank_yaml or config_path("tank.yaml")) as stream:
        template = stream.read()
    with open(os.path.join(args.out, "tank_fitted.yaml"), "w") as stream:
        servo_values = {n: servos["fitted"][n] for n in SERVO_FITTED} if servos else {}
        stream.write(update_tank_yaml(template, dict(fitted, **servo_values), "identify_bags (code %s), objective "
                                      "%.2f deg" % (report["code"], report["fit_objective"])))
    shown, side = (held_out[0], check) if held_out and check.window_count else (training[0], objective)
    _plot(os.path.join(args.out, "identify_bags.png"), shown, side, fitted,
          "%s: recorded, and replayed windows of %g s" % (shown.source, args.window))
    text = _text(report)
    with open(os.path.join(args.out, "identify_bags.md"), "w") as stream:
        stream.write(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
