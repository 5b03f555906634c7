"""Batched closed-loop simulation: N trials of controller + servos + plant stepped together.

:class:`BatchSimulation` is :class:`~quadruped_control.sim.simulation.ClosedLoopSimulation` for N trials
at once, on arrays with a leading trial axis: the controller of
:class:`~quadruped_control.sim.batch_controller.BatchController`, each trial's servo model (the paper's ideal
servo or the rate-limited lag, :func:`~quadruped_control.sim.servo_model.servo_batch_step`,
with its own speed and time constant), the joint hold of
:class:`~quadruped_control.sim.simulation.PlantSimulator` (midpoint and finite-difference rate) and the
plant (:class:`~quadruped_control.sim.plants.paper_batch.PaperPlantBatch` or
:class:`~quadruped_control.sim.plants.tank_batch.TankPlantBatch`, each trial with its own tank parameters). The step order, the time
grid t_k = k dt and the recorded samples are those of the per-trial engine, and the tests compare the
two trial by trial (every state equal, bit for bit, and the same metrics).

Each trial has its own gains, torque limit, stroke timing, setpoint, initial attitude, servo model,
centre-of-buoyancy offset or tank parameters, IMU noise (its own seeded generator, drawn as the per-trial
engine draws, :func:`~quadruped_control.sim.simulation.imu_measurement`) and stroke scheme; the robot and
the controller's period are shared (:class:`BatchTrial`). When every trial runs the paper's stroke scheme
with the controller on, the controller is the compiled loop of
:class:`~quadruped_control.sim.batch_controller.BatchController`; otherwise (the coordinated scheme, the
controller off) it is the robot's own controller objects,
:class:`~quadruped_control.sim.batch_controller.ControllerObjects`, and only the plant, servos and recording
are batched. ``run(..., stroke_metrics=True)`` accumulates the stroke-scheme figures as it goes
(:class:`~quadruped_control.sim.stroke_metrics.StrokeTorqueMetrics`).

Memory: the recorded attitude (roll, pitch, yaw and the geodesic error, float64) costs 32 bytes per
trial and step, 0.86 GB for 1,500 trials of 180 s; the full states are kept only for the first
``record_states`` steps (the agreement tests).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from quadruped_common.jit import kernel
from quadruped_common.so3 import geodesic_f, rotations_to_rpy, rpy_f
from quadruped_control.analysis.metrics import compute_metrics
from quadruped_control.control.controller_config import ControllerConfig
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.batch_controller import BatchController, ControllerObjects
from quadruped_control.sim.magnetic_heading import reported_rotation
from quadruped_control.sim.plants.paper_batch import PaperPlantBatch
from quadruped_control.sim.plants.tank_params import TankParams
from quadruped_control.sim.plants.tank_batch import TankPlantBatch
from quadruped_control.sim.servo_model import ServoParams, servo_batch_step
from quadruped_control.sim.simulation import imu_measurement
from quadruped_control.sim.stroke_metrics import StrokeTorqueMetrics

__all__ = ["BatchResult", "BatchSimulation", "BatchTrial"]


@dataclass(frozen=True)
class BatchTrial:
    """One trial of a batch: controller configuration, setpoint and initial attitude (rotation
    matrices), servo model ('ideal' or 'rate-limited' with ``servo_params``), optional centre-of-buoyancy
    offset (m, body frame) of the paper plant, or the tank plant's parameters. The trials of a batch
    all run the paper plant or all the tank plant."""

    config: ControllerConfig
    setpoint: np.ndarray
    initial: np.ndarray = field(default_factory=lambda: np.eye(3))
    servo_model: str = "ideal"
    servo_params: Optional[ServoParams] = None
    restoring_offset: Optional[Sequence[float]] = None
    #: the tank plant's parameters (:class:`~quadruped_control.sim.plants.tank_params.TankParams`); None: the paper plant
    tank: Optional[TankParams] = None
    #: IMU noise std: attitude (rad, rotation vector) and gyro (rad/s), drawn from default_rng(seed)
    attitude_noise: float = 0.0
    gyro_noise: float = 0.0
    seed: int = 0
    #: False: the controller stays in its hold state (passive dynamics)
    controller_enabled: bool = True


@dataclass
class BatchResult:
    """Recorded batch: ``t`` (T,), ``rpy`` (N, T, 3) rad and ``geodesic`` (N, T) rad of the attitude the IMU
    reports (the true one unless a tank trial's IMU turns the heading), ``setpoint_rpy``
    (N, 3) rad; ``failed`` (N,) trials whose plant step failed (kinematics or a non-finite state) and
    ``refused`` (N,) trials whose measurement the robot's controller would have refused (it would hold),
    both untrustworthy from then on; ``failure_reasons``: why a failed trial failed, where the plant says
    (row -> reason: ``TankPlantBatch.failure_reasons``); ``states``: the first steps' (p, v, R, omega,
    joint positions, and the joint targets the controller computed at the sample, held to the next: one
    fewer at the run's end) per trial when recorded; ``ik_fallbacks`` (N,); ``stroke_metrics``: per trial,
    when asked for (:class:`~quadruped_control.sim.stroke_metrics.StrokeTorqueMetrics`)."""

    t: np.ndarray
    rpy: np.ndarray
    geodesic: np.ndarray
    setpoint_rpy: np.ndarray
    failed: np.ndarray
    refused: np.ndarray
    ik_fallbacks: np.ndarray
    wall_time: float
    states: Optional[Dict[str, np.ndarray]] = None
    stroke_metrics: Optional[List[Dict[str, float]]] = None
    failure_reasons: Dict[int, str] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.rpy.shape[0])

    def trusted(self, i: int) -> bool:
        return not (self.failed[i] or self.refused[i])

    def metrics(self, i: int) -> Dict[str, Any]:
        """The paper's metrics of trial ``i`` (:func:`~quadruped_control.analysis.metrics.compute_metrics`)."""
        return compute_metrics(self.t, self.rpy[i], self.setpoint_rpy[i], self.geodesic[i])

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds of all trials per wall-clock second."""
        duration = float(self.t[-1] - self.t[0]) + (self.t[1] - self.t[0] if self.t.size > 1 else 0.0)
        return self.n * duration / self.wall_time if self.wall_time > 0 else math.inf


@kernel
def record_attitude(R, setpoints, k, rpy, geodesic):
    """Sample ``k`` of every trial: roll, pitch, yaw (:func:`~quadruped_common.so3.rpy_f`) of R (N, 3, 3)
    into ``rpy`` (N, T, 3) and the geodesic angle to its setpoint (N, 9) rows
    (:func:`~quadruped_common.so3.geodesic_f`) into ``geodesic`` (N, T)."""
    for i in range(R.shape[0]):
        rpy[i, k, 0], rpy[i, k, 1], rpy[i, k, 2] = rpy_f(R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 2, 0],
                                                        R[i, 2, 1], R[i, 2, 2])
        Ri = (R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2], R[i, 2, 0], R[i, 2, 1],
              R[i, 2, 2])
        geodesic[i, k] = geodesic_f(setpoints[i], Ri)


class BatchSimulation:
    """N closed-loop trials on the paper or the tank plant (module docstring)."""

    def __init__(self, robot: RobotParams, trials: Sequence[BatchTrial]) -> None:
        if not trials:
            raise ValueError("a batch needs at least one trial")
        n = len(trials)
        self.n = n
        self.robot = robot
        self.trials = list(trials)
        setpoints = np.array([np.asarray(t.setpoint, dtype=float) for t in trials])
        configs = [t.config for t in trials]
        if all(t.config.stroke_scheme == "paper" and t.controller_enabled for t in trials):
            self.controller: Any = BatchController(robot, configs, setpoints)
        else:
            self.controller = ControllerObjects(robot, configs, setpoints, [t.controller_enabled for t in trials])
        for trial in trials:
            for name in ("attitude_noise", "gyro_noise"):
                value = getattr(trial, name)
                if not (math.isfinite(value) and value >= 0.0):
                    raise ValueError("%s must be a finite non-negative std, got %r" % (name, value))
        self.noisy = [i for i, t in enumerate(trials) if t.attitude_noise > 0.0 or t.gyro_noise > 0.0]
        # the trials whose IMU turns the heading (a residual field at the IMU), and their fields
        self.heading_turned = [i for i, t in enumerate(trials) if t.tank is not None and t.tank.heading_disturbed]
        self._field_residual = np.array([trials[i].tank.imu_field_residual for i in self.heading_turned],
                                        dtype=float).reshape(-1, 3)
        self.rngs = {i: np.random.default_rng(int(trials[i].seed)) for i in self.noisy}
        self.dt = self.controller.dt
        tank = [trial.tank is not None for trial in trials]
        if any(tank) and not all(tank):
            raise ValueError("the trials of a batch must all run the paper plant or all the tank plant")
        if all(tank):
            if any(trial.restoring_offset is not None for trial in trials):
                raise ValueError("restoring_offset belongs to the paper plant (the tank has its centre of buoyancy)")
            self.plant: Any = TankPlantBatch(robot, [trial.tank for trial in trials])
        else:
            restoring = np.zeros((n, 3, 3))
            for i, trial in enumerate(trials):
                if trial.restoring_offset is not None:
                    restoring[i] = PaperPlantBatch.restoring_matrix(robot, trial.restoring_offset)
            self.plant = PaperPlantBatch(robot, n, restoring)
        for trial in trials:
            if trial.servo_model not in ("ideal", "rate-limited"):
                raise ValueError("unknown servo model %r" % (trial.servo_model,))
            if trial.servo_model == "rate-limited" and trial.servo_params is None:
                raise ValueError("a rate-limited servo needs servo_params")
        self.ideal = np.array([t.servo_model == "ideal" for t in trials])
        self.max_speed = np.array([t.servo_params.max_speed if t.servo_params else math.inf
                                   for t in trials])
        self.time_constant = np.array([t.servo_params.time_constant if t.servo_params else 0.0
                                       for t in trials])
        self.stall_torque = np.array([t.servo_params.stall_torque if t.servo_params else 0.0 for t in trials])
        self.dead_band = np.array([t.servo_params.dead_band if t.servo_params else 0.0 for t in trials])
        # the joint loads of loaded servos (the tank plant's, else none)
        self._loads = self.plant.loads if isinstance(self.plant, TankPlantBatch) else np.zeros((n, 4, 3))
        self.position = np.zeros((n, 3))
        self.velocity = np.zeros((n, 3))
        self.rotation = np.array([np.asarray(t.initial, dtype=float) for t in trials])
        self.omega = np.zeros((n, 3))
        self.q = self.controller.joints.copy()  # servos at the nominal pose
        self._q_buffers = (self.q, np.empty_like(self.q))
        self._mid, self._rate = np.empty_like(self.q), np.empty_like(self.q)
        self.k = 0
        if isinstance(self.plant, TankPlantBatch):
            self.plant.attach(self.position, self.rotation)

    def _reported(self) -> np.ndarray:
        """The attitude each trial's IMU reports, noise apart: the true one, or with the heading turned
        where the trial's tank has a residual field at the IMU
        (:func:`~quadruped_control.sim.magnetic_heading.reported_rotation`)."""
        if not self.heading_turned:
            return self.rotation
        R = self.rotation.copy()
        R[self.heading_turned] = reported_rotation(self.rotation[self.heading_turned], self._field_residual)
        return R

    def _measure(self, seen: Optional[np.ndarray] = None):
        """What each trial's IMU reports: the reported attitude (``seen``, :meth:`_reported` unless given) and
        the true rate, with noise where the trial has some."""
        if seen is None:
            seen = self._reported()
        if not self.noisy:
            return seen, self.omega
        R, omega = seen.copy(), self.omega.copy()
        for i in self.noisy:
            trial = self.trials[i]
            R[i], omega[i] = imu_measurement(self.rngs[i], seen[i], self.omega[i], trial.attitude_noise,
                                             trial.gyro_noise)
        return R, omega

    def _control(self, seen: Optional[np.ndarray] = None) -> np.ndarray:
        """The controllers' step at t_k on the measurement (of the reported attitude ``seen`` when given);
        the joint targets (N, 4, 3)."""
        return self.controller.step(self.k * self.dt, *self._measure(seen))

    def step(self) -> None:
        """One control period of every trial: measure at t_k, control, hold the joint targets to t_k+1."""
        self._advance(self._control())

    def _advance(self, targets: np.ndarray) -> None:
        """Servos and plant from t_k to t_k+1 with the joint targets of t_k."""
        h = self.dt
        # The servos' state (never the controller's target array, which the next step updates in place)
        # alternates between two buffers: the step reads one and writes the other.
        q_end = self._q_buffers[0] if self.q is self._q_buffers[1] else self._q_buffers[1]
        servo_batch_step(self.q, targets, self.ideal, self.max_speed, self.time_constant, self.stall_torque,
                         self.dead_band, self._loads, h, q_end, self._mid, self._rate)
        self.position, self.velocity, self.rotation, self.omega = self.plant.step(
            self.position, self.velocity, self.rotation, self.omega, self._mid, self._rate, h)
        self.q = q_end
        self.k += 1

    def run(self, duration: float, record_states: int = 0, stroke_metrics: bool = False) -> BatchResult:
        """Simulate ``duration`` s: round(duration / dt) + 1 samples per trial, as the per-trial engine
        records them; ``record_states``: keep the full states of the first that many samples;
        ``stroke_metrics``: accumulate the stroke-scheme figures (the controller then also runs at the last
        sample, as the per-trial engine does, for its stroke phase)."""
        duration = float(duration)
        if not (math.isfinite(duration) and duration > 0.0):
            raise ValueError("duration must be a positive finite number of seconds, got %r" % (duration,))
        steps = int(round(duration / self.dt))
        samples = steps + 1
        n = self.n
        rpy = np.empty((n, samples, 3))
        geodesic = np.empty((n, samples))
        times = np.empty(samples)
        kept = min(int(record_states), samples)
        states: Dict[str, List[np.ndarray]] = {"position": [], "velocity": [], "rotation": [], "omega": [],
                                               "joints": [], "targets": []}
        setpoints = self.controller.R_d
        metrics = StrokeTorqueMetrics(self.robot, n) if stroke_metrics else None
        start = time.perf_counter()
        # A diverging trial turns its own rows non-finite (flagged in ``failed``, then frozen): no warnings.
        with np.errstate(all="ignore"):
            self._record_loop(samples, steps, kept, times, rpy, geodesic, states, setpoints, metrics)
        wall = time.perf_counter() - start
        recorded = {key: np.stack(values, axis=1) for key, values in states.items() if values} if kept else None
        return BatchResult(t=times, rpy=rpy, geodesic=geodesic, setpoint_rpy=rotations_to_rpy(setpoints),
                           failed=self.plant.failed.copy(), refused=self.controller.refused.copy(),
                           ik_fallbacks=self.controller.ik_fallbacks.copy(), wall_time=wall, states=recorded,
                           stroke_metrics=metrics.results() if metrics is not None else None,
                           failure_reasons=dict(getattr(self.plant, "failure_reasons", {})))

    def _record_loop(self, samples: int, steps: int, kept: int, times: np.ndarray, rpy: np.ndarray,
                     geodesic: np.ndarray, states: Dict[str, List[np.ndarray]], setpoints: np.ndarray,
                     metrics: Optional[StrokeTorqueMetrics]) -> None:
        setpoint_rows = np.ascontiguousarray(setpoints.reshape(-1, 9))
        for i in range(samples):
            times[i] = self.k * self.dt
            seen = self._reported()  # once per sample: the record and the controller's measurement
            record_attitude(seen, setpoint_rows, i, rpy, geodesic)  # as the IMU reports it
            if i < kept:
                for key, value in (("position", self.position), ("velocity", self.velocity),
                                   ("rotation", self.rotation), ("omega", self.omega), ("joints", self.q)):
                    states[key].append(value.copy())
            if i >= steps and metrics is None:
                continue  # the last sample: only the stroke metrics need the controller's answer to it
            targets = self._control(seen)
            if i < kept and i < steps:
                states["targets"].append(targets.copy())
            if metrics is not None:
                # The state of sample i and the controller's answer to it (metrics.add copies; the plant
                # steps its arrays in place).
                metrics.add(times[i], self.q.reshape(self.n, 12), self.rotation, self.omega,
                            self.controller.tau_sat, np.any(self.controller.power, axis=1))
            if i < steps:
                self._advance(targets)
