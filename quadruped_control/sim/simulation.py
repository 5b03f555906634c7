"""Offline closed-loop simulation of the underwater quadruped (paper section "Simulation Validation").

Two layers:

- :class:`PlantSimulator`: the simulated robot alone. It takes the 12 commanded joint angles of one
  period, passes them through a servo model (:mod:`quadruped_control.sim.servo_model`; the paper's ideal
  servos by default), and advances the paper's floating-base model eq. (trans), (rot) with RK4 on SO(3)
  (:class:`~quadruped_control.sim.plants.paper.FloatingBaseModel`) over the period. Over a step the joints are
  taken to move linearly from their angles at its start to those at its end: the held input is their
  midpoint and the finite-difference velocity (:func:`~quadruped_control.sim.plants.paper.held_joint_input`),
  as the paper obtains q_dot "through finite differences". Used without a controller by the ROS
  ``sim_node`` behind the fake buses.
- :class:`ClosedLoopSimulation`: the plant plus the same
  :class:`~quadruped_control.control.controller.AttitudeController` object the ROS node runs, at the paper's
  dt = 0.01 s: at t_k = k dt the controller measures (R, omega) (optionally with IMU noise), commands
  joint targets, and the plant holds them over [t_k, t_k+1). :meth:`ClosedLoopSimulation.run`
  returns a :class:`SimulationResult` with every signal as arrays and the paper's metrics
  (:mod:`quadruped_control.analysis.metrics`).

Beyond the paper (all off by default, so the defaults are the paper's simulation): a rate-limited servo
model, IMU noise driven by ``seed``, and a centre-of-buoyancy offset giving a restoring torque.
Settings live in the ``simulation:`` section of ``config/simulation.yaml``.
"""
from __future__ import annotations

import csv
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.config import load_config
from quadruped_common.robot import LEGS
from quadruped_common.schema import Param, Schema
from quadruped_common.so3 import exp_so3, geodesic_angles, is_rotation, rotations_to_quaternions, rotations_to_rpy
from quadruped_control.analysis.metrics import compute_metrics, moving_average_centered
from quadruped_control.control.controller import AttitudeController, ControllerOutput
from quadruped_control.control.controller_config import ControllerConfig
from quadruped_control.model.kinematics import UnreachableError, joint_angles
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.magnetic_heading import reported_rotation
from quadruped_control.sim.safety_sensors import SAFETY_SENSOR_PARAMS, SafetySensorSettings, safety_sensor_settings
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState
from quadruped_control.sim.servo_model import (SERVO_MODELS, SERVO_SCHEMA, IdealServo, RateLimitedServo, ServoModel,
                                              ServoParams, make_servo_model, servo_params_from_dict)

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: progress(t_simulated, duration) callback of :meth:`ClosedLoopSimulation.run`.
ProgressCallback = Callable[[float, float], None]

__all__ = [
    "ClosedLoopSimulation",
    "PlantSimulator",
    "SIMULATION_SCHEMA",
    "SimulationError",
    "SimulationResult",
    "SimulationSettings",
    "imu_measurement",
    "load_simulation_settings",
    "nominal_joint_angles",
]


class SimulationError(RuntimeError):
    """The closed loop cannot continue (the plant diverged or was driven into an impossible pose)."""


# --------------------------------------------------------------------------------------------------
# Settings
# --------------------------------------------------------------------------------------------------

def _seeds_problem(seeds: list) -> Optional[str]:
    if not seeds or any(isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 32
                        for seed in seeds):
        return "must be a non-empty list of integers in [0, 2^32 - 1]"
    return None


#: ``config/simulation.yaml``: the ``simulation:`` section (the simulator) and the study sections ``paper_sim``
#: and ``robustness`` (read by the simulate CLI's studies), all optional but ``simulation.servo.time_constant``.
SIMULATION_SCHEMA = Schema("simulation.yaml", (
    Param("simulation.dt", "s", "RK4 step and control period", 0.0, 1.0, low_open=True, default=0.01, source="paper"),
    Param("simulation.servo_model", "", "servo model unless a caller asks for another: ideal (the paper's, commanded "
          "angles reached at once) or rate-limited (simulation.servo)", kind="string", choices=SERVO_MODELS,
          default="ideal", source="choice"),
    *SERVO_SCHEMA.params,
    Param("simulation.sensor_noise.attitude_deg", "deg", "IMU noise: std of a random rotation-vector perturbation "
          "(0: the paper's noiseless simulation)", 0.0, 90.0, default=0.0, source="choice"),
    Param("simulation.sensor_noise.gyro", "rad/s", "IMU noise: std per gyro axis", 0.0, 10.0, default=0.0,
          source="choice"),
    Param("paper_sim.setpoints_deg", "deg", "setpoints of the paper-sim study, each applied to roll, pitch and yaw "
          "at once (one trial each)", -360.0, 360.0, kind="vector", default=[15.0, 45.0, 75.0], source="paper"),
    Param("paper_sim.initial_rpy_deg", "deg", "initial roll, pitch, yaw of its trials (not in the paper: level, at "
          "rest)", -360.0, 360.0, kind="vector", length=3, default=[0.0, 0.0, 0.0], source="estimate"),
    Param("paper_sim.duration", "s", "length of its trials (not in the paper: long enough to check the 30 s settling "
          "criterion)", 0.0, 1e5, low_open=True, default=120.0, source="estimate"),
    Param("paper_sim.gains", "", "gain set of controller.yaml its trials run", kind="string", default="simulation",
          source="paper"),
    Param("robustness.initial_perturbation_deg", "deg", "robustness study: uniform +- perturbation of each initial "
          "Euler angle", 0.0, 90.0, default=0.5, source="choice"),
    Param("robustness.seeds", "", "robustness study: one perturbed trial per seed (integers in [0, 2^32 - 1]) and "
          "setpoint", kind="list", default=[1, 2, 3], source="choice", check=_seeds_problem),
    *SAFETY_SENSOR_PARAMS,
))


@dataclass(frozen=True)
class SimulationSettings:
    """The ``simulation:`` section of ``config/simulation.yaml``.

    ``dt``: step (s); ``servo_model``: default servo model name; ``servo``: rate-limited servo
    parameters; ``attitude_noise``: std of the IMU attitude error (rad, rotation vector);
    ``gyro_noise``: std per gyro axis (rad/s); ``sensors``: the simulated robot's depth sensor and LiPo packs
    (the ``simulated_robot`` section, :mod:`quadruped_control.sim.safety_sensors`).
    """

    dt: float = SIMULATION_SCHEMA["simulation.dt"].default
    servo_model: str = SIMULATION_SCHEMA["simulation.servo_model"].default
    servo: ServoParams = field(default_factory=lambda: ServoParams(95.0 * math.pi / 30.0, 0.03))
    attitude_noise: float = math.radians(SIMULATION_SCHEMA["simulation.sensor_noise.attitude_deg"].default)
    gyro_noise: float = SIMULATION_SCHEMA["simulation.sensor_noise.gyro"].default
    sensors: SafetySensorSettings = field(default_factory=SafetySensorSettings)


def simulation_settings_from_dict(tree: Mapping[str, Any]) -> SimulationSettings:
    """Read a parsed simulation.yaml tree through :data:`SIMULATION_SCHEMA`: the ``simulation:`` section (typed
    result) and the study sections ``paper_sim`` and ``robustness`` (read by the simulate CLI)."""
    v = SIMULATION_SCHEMA.read(tree)
    return SimulationSettings(
        dt=v["simulation.dt"],
        servo_model=v["simulation.servo_model"],
        servo=servo_params_from_dict(tree),
        attitude_noise=math.radians(v["simulation.sensor_noise.attitude_deg"]),
        gyro_noise=v["simulation.sensor_noise.gyro"],
        sensors=safety_sensor_settings(v),
    )


def load_simulation_settings(path: Optional[str] = None) -> SimulationSettings:
    """Load and validate the ``simulation:`` section (default file: the package's config/simulation.yaml)."""
    return load_config(path, "simulation.yaml", simulation_settings_from_dict)


def load_simulation_tree(path: Optional[str] = None) -> Dict[str, Any]:
    """The whole simulation.yaml (study sections included), validated by :func:`simulation_settings_from_dict`."""
    def build(tree: Dict[str, Any]) -> Dict[str, Any]:
        simulation_settings_from_dict(tree)
        return tree
    return load_config(path, "simulation.yaml", build)


def nominal_joint_angles(robot: RobotParams) -> np.ndarray:
    """Joint angles (4, 3) that put every foot at its nominal position (the stroke cycle's start)."""
    return np.array([joint_angles(robot.nominal_foot_body(leg), leg, robot) for leg in LEGS])


def _rotation(R: ArrayLike, name: str) -> np.ndarray:
    M = np.array(R, dtype=float)
    if M.shape != (3, 3) or not is_rotation(M, 1e-6):
        raise ValueError("%s must be a 3x3 rotation matrix (finite, R^T R = I, det +1), got %r" % (name, R))
    return M


# --------------------------------------------------------------------------------------------------
# Plant
# --------------------------------------------------------------------------------------------------

class PlantSimulator:
    """The simulated robot: servo model + joint command hold + floating-base model, no controller.

    ``robot``: model parameters; ``servo_model``: a :class:`~quadruped_control.sim.servo_model.ServoModel`
    (default the paper's :class:`~quadruped_control.sim.servo_model.IdealServo`); ``initial_rotation``:
    R_B^W at rest (default level); ``restoring_offset``: optional centre of buoyancy relative to the
    centre of mass in the body frame (m), see :class:`~quadruped_control.sim.plants.paper.FloatingBaseModel`;
    ``initial_joints``: (4, 3) or (12,) servo angles at start (default: feet at the nominal position);
    ``dt``: default step (s); ``model``: the plant's equations of motion (default the paper's
    :class:`~quadruped_control.sim.plants.paper.FloatingBaseModel`; :mod:`quadruped_control.sim.plants`).

    :meth:`step` takes the 12 commanded joint angles (JOINT_NAMES order, or (4, 3)). Commands outside a
    servo's range are clamped to it (a servo cannot turn further; ``clamped_joints`` counts them).
    A malformed or non-finite command raises ValueError and leaves the plant unchanged; a command whose
    joint motion the five-bar cannot follow, or a diverging integration, raises :class:`SimulationError`
    and also leaves it unchanged.
    """

    def __init__(self, robot: RobotParams, servo_model: Optional[ServoModel] = None,
                 initial_rotation: Optional[ArrayLike] = None, restoring_offset: Optional[ArrayLike] = None,
                 initial_joints: Optional[ArrayLike] = None, dt: float = 0.01,
                 model: Optional[FloatingBaseModel] = None) -> None:
        self.robot = robot
        if model is not None and restoring_offset is not None:
            raise ValueError("give either a plant model or a restoring_offset, not both")
        self.model = model if model is not None else FloatingBaseModel(robot, restoring_offset=restoring_offset)
        self.servo = servo_model if servo_model is not None else IdealServo()
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError("dt must be a positive finite number of seconds, got %r" % (dt,))
        self.dt = dt
        limits = robot.joint_limits.as_array()
        self._low = np.tile(limits[:, 0], (4, 1))
        self._high = np.tile(limits[:, 1], (4, 1))
        self._bounds: Tuple[float, ...] = tuple(limits.reshape(6).tolist())  # (low1, high1, .., low3, high3)
        self.clamped_joints = 0
        self.time = 0.0
        self.reset(initial_rotation, initial_joints)

    # ---- state -------------------------------------------------------------------------------

    def reset(self, rotation: Optional[ArrayLike] = None, joints: Optional[ArrayLike] = None,
              state: Optional[RigidBodyState] = None) -> None:
        """Start again at rest (or at ``state``), with the servos at ``joints`` (default nominal pose)."""
        if state is not None:
            if rotation is not None:
                raise ValueError("give either rotation or state, not both")
            self._state = state.validate()
        else:
            R = np.eye(3) if rotation is None else _rotation(rotation, "initial rotation")
            self._state = RigidBodyState(rotation=R)
        self.model.attach(self._state)
        q = nominal_joint_angles(self.robot) if joints is None else self._command(joints)
        # The initial pose must be one the legs can take.
        self.model.leg_input(q, np.zeros((4, 3)))
        self.servo.reset(q)
        self._q = self.servo.position
        self._q_rows: List[List[float]] = self._q.tolist()  # self._q as floats
        self._q_dot_start = self._q
        self._h = self.dt
        self._command_q = q.copy()
        self.time = 0.0
        self.clamped_joints = 0

    def place_body(self, rotation: ArrayLike) -> None:
        """Hold the body at rest at ``rotation`` where it is (the joints keep moving): a robot on a stand, held
        level or tilted by the operator (the pre-dive check's guided poses)."""
        R = _rotation(rotation, "stand rotation")
        self._state = RigidBodyState(position=self._state.position.copy(), rotation=R)
        self.model.attach(self._state)

    @property
    def state(self) -> RigidBodyState:
        """Current floating-base state (a copy)."""
        return self._state.copy()

    @property
    def joint_positions(self) -> np.ndarray:
        """Current servo angles (4, 3), rad (a copy)."""
        return np.array(self._q)

    @property
    def joint_velocities(self) -> np.ndarray:
        """Average servo velocities over the last step (4, 3), rad/s (zero before the first step)."""
        return (self._q - self._q_dot_start) / self._h

    @property
    def last_command(self) -> np.ndarray:
        """The last accepted (clamped) command (4, 3), rad."""
        return self._command_q.copy()

    def _command(self, q_cmd: ArrayLike) -> np.ndarray:
        q = np.array(q_cmd, dtype=float)
        if q.shape == (12,):
            q = q.reshape(4, 3)
        if q.shape != (4, 3):
            raise ValueError("joint command must have shape (12,) or (4, 3), got %s" % (q.shape,))
        if not np.all(np.isfinite(q)):
            raise ValueError("joint command has non-finite elements: %s" % (q.reshape(-1).tolist(),))
        return q

    # ---- stepping ----------------------------------------------------------------------------

    def step(self, q_cmd: ArrayLike, dt: Optional[float] = None) -> RigidBodyState:
        """Hold the command ``q_cmd`` for ``dt`` s (default the plant's dt); returns the new state (a copy)."""
        h = self.dt if dt is None else float(dt)
        if not (math.isfinite(h) and h > 0.0):
            raise ValueError("dt must be a positive finite number of seconds, got %r" % (dt,))
        return self._advance(self._command(q_cmd), h).copy()

    def _outside_count(self, rows: Sequence[Sequence[float]]) -> int:
        """Number of joint commands in ``rows`` (4 x 3 floats) outside their servo range; NaN counts."""
        l1, h1, l2, h2, l3, h3 = self._bounds
        count = 0
        for t1, t2, t3 in rows:
            if not (l1 <= t1 <= h1 and l2 <= t2 <= h2 and l3 <= t3 <= h3):
                count += (not l1 <= t1 <= h1) + (not l2 <= t2 <= h2) + (not l3 <= t3 <= h3)
        return count

    def _advance(self, command: np.ndarray, h: float, rows: Optional[List[List[float]]] = None,
                 count: Optional[int] = None) -> RigidBodyState:
        """:meth:`step` for a checked (4, 3) finite command and a positive ``h``; returns the plant's
        own state object (states are never mutated in place, so it stays valid). ``rows``:
        ``command.tolist()`` and ``count``: its :meth:`_outside_count`, if the caller has them.

        The held input (midpoint and finite difference of the servo angles) is formed on floats, with
        the same arithmetic as the array expressions 0.5 * (q_start + q_end) and (q_end - q_start) / h.
        """
        if rows is None:
            rows = command.tolist()
        if count is None:
            count = self._outside_count(rows)
        clamped = np.clip(command, self._low, self._high) if count else command
        q_start = self._q
        servo_before = q_start  # the servo's position array is replaced, never mutated
        q_end = self.servo.update_trusted(clamped, h)
        # An ideal servo reaches the (unclamped) command exactly: its floats are already at hand.
        end_rows = rows if (count == 0 and type(self.servo) is IdealServo) else q_end.tolist()
        mid = []
        rate = []
        for (a1, a2, a3), (b1, b2, b3) in zip(self._q_rows, end_rows):
            mid.append((0.5 * (a1 + b1), 0.5 * (a2 + b2), 0.5 * (a3 + b3)))
            rate.append(((b1 - a1) / h, (b2 - a2) / h, (b3 - a3) / h))
        try:
            new_state = self.model.step_trusted(self._state, mid, rate, h)
        except (UnreachableError, ArithmeticError, RuntimeError) as exc:
            self.servo.reset(servo_before)
            raise SimulationError("plant step at t = %.3f s failed: %s" % (self.time, exc)) from None
        self.clamped_joints += count
        loads = getattr(self.model, "joint_loads", None)
        if loads is not None and isinstance(self.servo, RateLimitedServo):
            self.servo.loads = loads  # what the servos work against in their next step (loaded servos)
        self._state = new_state
        self._q = q_end
        self._q_rows = end_rows
        self._q_dot_start = q_start
        self._h = h
        self._command_q = clamped
        self.time += h
        return new_state


# --------------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------------

@dataclass
class SimulationResult:
    """Recorded closed-loop trial; row k is the instant t_k at which the controller measured and acted.

    ``rotation`` (N, 3, 3) true R_B^W; ``quaternion`` (N, 4) (x, y, z, w) of it; ``reported_rotation``
    (N, 3, 3) the attitude the IMU reported, noise apart, when the plant's IMU turns the heading (a residual
    field, :mod:`~quadruped_control.sim.magnetic_heading`; None: the true one); ``rpy`` (N, 3) rad and
    ``geodesic`` (N,) the geodesic error (rad) of the reported attitude, from which the metrics are taken as
    Table 1's were from the robot's IMU (the true attitude unless the heading is turned);
    ``omega`` (N, 3) rad/s (true, body); ``tau_cmd``, ``tau_sat`` (N, 3) N m; ``saturated`` (N,) bool;
    ``pair_phase`` (N, P) str; ``holding`` (N,) bool;
    ``joint_targets`` (N, 12) commanded, ``joint_positions`` (N, 12) servo angles, rad;
    ``setpoint`` R_d; ``info``: the trial's settings (JSON-ready).
    """

    t: np.ndarray
    rotation: np.ndarray
    omega: np.ndarray
    tau_cmd: np.ndarray
    tau_sat: np.ndarray
    saturated: np.ndarray
    pair_phase: np.ndarray
    holding: np.ndarray
    joint_targets: np.ndarray
    joint_positions: np.ndarray
    setpoint: np.ndarray
    info: Dict[str, Any]
    wall_time: float = 0.0
    #: (N, 3) centre-of-mass position in the world frame, m (zeros if not recorded).
    position: Optional[np.ndarray] = None
    reported_rotation: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        if self.position is None:
            self.position = np.zeros((self.t.size, 3))
        self.quaternion = rotations_to_quaternions(self.rotation)
        seen = self.rotation if self.reported_rotation is None else self.reported_rotation
        self.rpy = rotations_to_rpy(seen)
        self.setpoint_rpy = rotations_to_rpy(self.setpoint[None, :, :])[0]
        self.geodesic = geodesic_angles(self.setpoint, seen)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second of the run."""
        return (self.duration + self.info.get("dt", 0.01)) / self.wall_time if self.wall_time > 0 else math.inf

    def geodesic_smoothed(self) -> np.ndarray:
        """Geodesic error after the centred 3 s moving average (rad)."""
        return moving_average_centered(self.geodesic, self.t)

    def metrics(self) -> Dict[str, Any]:
        """The paper's metrics of this trial (:func:`quadruped_control.analysis.metrics.compute_metrics`)."""
        return compute_metrics(self.t, self.rpy, self.setpoint_rpy, self.geodesic)

    #: Column names of :meth:`write_csv` (angles in degrees, everything else SI).
    CSV_COLUMNS: Tuple[str, ...] = (
        "t", "qx", "qy", "qz", "qw", "roll_deg", "pitch_deg", "yaw_deg",
        "roll_setpoint_deg", "pitch_setpoint_deg", "yaw_setpoint_deg", "omega_x", "omega_y", "omega_z",
        "tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "tau_sat_x", "tau_sat_y", "tau_sat_z", "saturated",
        "geodesic_deg", "geodesic_smoothed_deg", "com_x", "com_y", "com_z")

    def write_csv(self, path: str) -> None:
        """Time series as CSV: :attr:`CSV_COLUMNS`, then ``phase_pair<i>`` per leg pair and ``holding``."""
        pairs = self.pair_phase.shape[1] if self.pair_phase.ndim == 2 else 0
        header = list(self.CSV_COLUMNS) + ["phase_pair%d" % (i + 1) for i in range(pairs)] + ["holding"]
        numeric = np.column_stack((
            self.t, self.quaternion, np.degrees(self.rpy), np.tile(np.degrees(self.setpoint_rpy), (self.t.size, 1)),
            self.omega, self.tau_cmd, self.tau_sat, self.saturated.astype(float), np.degrees(self.geodesic),
            np.degrees(self.geodesic_smoothed()), self.position))
        with open(path, "w", newline="") as stream:
            writer = csv.writer(stream)
            writer.writerow(header)
            for k in range(self.t.size):
                row = ["%.2f" % numeric[k, 0]] + ["%.9g" % v for v in numeric[k, 1:20]] \
                    + ["%d" % int(numeric[k, 20])] + ["%.6g" % v for v in numeric[k, 21:]]
                row += [str(p) for p in self.pair_phase[k]] + ["%d" % int(self.holding[k])]
                writer.writerow(row)


# --------------------------------------------------------------------------------------------------
# Closed loop
# --------------------------------------------------------------------------------------------------

def imu_measurement(rng: np.random.Generator, R: np.ndarray, omega: np.ndarray, attitude_noise: float,
                    gyro_noise: float) -> Tuple[np.ndarray, np.ndarray]:
    """What the simulated IMU reports for the true (R, omega): R exp(n_R^) with n_R ~ N(0, attitude_noise^2 I)
    (a rotation-vector error, rad) and omega + n_w with n_w ~ N(0, gyro_noise^2 I) (rad/s); the draws in
    that order from ``rng``, none for a zero std (so noise-free runs draw nothing)."""
    if attitude_noise > 0.0:
        R = R @ exp_so3(rng.normal(0.0, attitude_noise, 3))
    if gyro_noise > 0.0:
        omega = omega + rng.normal(0.0, gyro_noise, 3)
    return R, omega


class _Sample(NamedTuple):
    """A sample :meth:`ClosedLoopSimulation.run` recorded last: at step ``k``, the plant's ``state``, the measured
    ``R`` and ``omega``, and the controller's ``output`` (None once the setpoint or the controller changed)."""

    k: int
    state: RigidBodyState
    R: np.ndarray
    omega: np.ndarray
    output: Optional[ControllerOutput]


class ClosedLoopSimulation:
    """Controller + plant at the controller's period (the paper's RK4 with dt = 0.01 s).

    ``robot``: model parameters (controller and plant share them: the paper's simulation has no model
    mismatch); ``controller_config``: gains etc.; ``servo_model``: a ServoModel or a name ('ideal',
    'rate-limited'), default ideal; ``initial_R``, ``setpoint_R``: rotations; ``restoring_offset``:
    optional centre of buoyancy offset (m, body frame); ``seed``: seeds the IMU noise;
    ``attitude_noise`` (rad), ``gyro_noise`` (rad/s): IMU noise std (default 0, the paper);
    ``model``: the plant's equations of motion (default the paper's, :mod:`quadruped_control.sim.plants`);
    ``controller_enabled`` False keeps the controller in its hold state, so the legs stay at the
    nominal pose (passive dynamics: ballast checks, physics tests). Mid-run, :meth:`set_controller` turns it
    on or off as the robot's controller acts or holds its safe pose, and :meth:`disarm` stops it as disarming
    the robot does.
    """

    def __init__(self, robot: RobotParams, controller_config: ControllerConfig,
                 servo_model: Union[ServoModel, str, None] = None, initial_R: Optional[ArrayLike] = None,
                 setpoint_R: Optional[ArrayLike] = None, restoring_offset: Optional[ArrayLike] = None,
                 seed: int = 0, attitude_noise: float = 0.0, gyro_noise: float = 0.0,
                 model: Optional[FloatingBaseModel] = None, controller_enabled: bool = True) -> None:
        if isinstance(servo_model, str):
            servo_model = make_servo_model(servo_model)
        for name, value in (("attitude_noise", attitude_noise), ("gyro_noise", gyro_noise)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError("%s must be a finite non-negative std, got %r" % (name, value))
        self.robot = robot
        self.config = controller_config
        self.dt = float(controller_config.dt)
        self.initial_R = np.eye(3) if initial_R is None else _rotation(initial_R, "initial_R")
        self.setpoint_R = np.eye(3) if setpoint_R is None else _rotation(setpoint_R, "setpoint_R")
        self.restoring_offset = None if restoring_offset is None else np.array(restoring_offset, dtype=float)
        self.seed = int(seed)
        self.attitude_noise = float(attitude_noise)
        self.gyro_noise = float(gyro_noise)
        self.controller = AttitudeController(robot, controller_config)
        self.controller.set_setpoint(self.setpoint_R)
        self.controller_enabled = bool(controller_enabled)
        self.disarmed = False
        self.plant = PlantSimulator(robot, servo_model, initial_rotation=self.initial_R,
                                    restoring_offset=self.restoring_offset, dt=self.dt, model=model)
        self._rng = np.random.default_rng(self.seed)
        self.k = 0
        self.holds = 0
        # The last sample :meth:`run` recorded. The next step at the same k uses it, so a run continued by another
        # draws no second measurement and steps the controller once per period, as one longer run would.
        self._last_sample: Optional[_Sample] = None

    @property
    def time(self) -> float:
        """Time of the next control step, s (k dt, not accumulated: no drift)."""
        return self.k * self.dt

    def set_setpoint(self, setpoint_R: ArrayLike) -> None:
        """A new setpoint R_d from the next step on (ValueError unless a rotation), as the ROS node takes one
        mid-run; the controller keeps its integral (the paper does not reset it). Between two runs, the step at the
        first run's last sample is controlled again with the new setpoint, on the same measurement: at h = 0 the
        controller's integral and stroke clock stay where they were, and only its output changes."""
        self.setpoint_R = _rotation(setpoint_R, "setpoint_R")
        self.controller.set_setpoint(self.setpoint_R)
        self._control_last_sample_again()

    def set_controller(self, enabled: bool, reset: bool = False) -> None:
        """The controller on (stroking) or off (its hold state: no new strokes, the legs back at the nominal pose)
        from the next step on, as the robot's controller acts, or holds its safe pose, mid-run; ``reset`` also
        clears its integral and stroke state, as arming the robot does. Between two runs, the step at the first
        run's last sample is controlled again in the new state, on the same measurement (:meth:`set_setpoint`).
        Ends a :meth:`disarm`: on, with ``reset``, is arming the robot again."""
        self.controller_enabled = bool(enabled)
        self.disarmed = False
        if reset:
            self.controller.reset()
        self._control_last_sample_again()

    def disarm(self) -> None:
        """The controller off as disarming the robot turns it off, from the next step on: the supervisor
        publishes no servo commands, and the PCA9685 keeps its last pulses (the pwm_node watchdog's failsafe
        ``hold``, config/hardware.yaml's default for every channel), so the legs stay where the last command
        put them, mid-stroke if it came mid-stroke. Holding (:meth:`set_controller` off) retraces them to the
        nominal pose instead, as the armed robot's safe pose does. A channel configured ``neutral`` or ``off``
        is not modelled. Arm again with ``set_controller(True, reset=True)``."""
        self.controller_enabled = False
        self.disarmed = True
        self._control_last_sample_again()

    def _control_last_sample_again(self) -> None:
        """After a change of setpoint or controller between two runs: the next step controls the last run's last
        sample again, on its measurement."""
        if self._last_sample is not None:
            self._last_sample = self._last_sample._replace(output=None)

    def _reported(self, rotation: np.ndarray) -> np.ndarray:
        """The attitude the IMU reports, noise apart: the true one, or with the heading a residual field at
        the IMU turns (the plant's ``imu_field_residual``, :mod:`~quadruped_control.sim.magnetic_heading`)."""
        residual = self.plant.model.imu_field_residual
        return rotation if residual is None else reported_rotation(rotation, residual)

    def _measure(self, state: RigidBodyState) -> Tuple[np.ndarray, np.ndarray]:
        return imu_measurement(self._rng, self._reported(state.rotation), state.omega, self.attitude_noise,
                               self.gyro_noise)

    def _control(self, t: float, R: np.ndarray, omega: np.ndarray) -> ControllerOutput:
        """The controller's output at ``t`` for a measurement: its hold state if it is off or rejects the
        measurement (counted in :attr:`holds`), as the ROS node does."""
        if self.disarmed:
            # the controller runs its hold as the supervisor's does; the servos keep the last command instead
            return replace(self.controller.hold(t, "disarmed"), joint_targets=self.plant.last_command)
        if not self.controller_enabled:
            return self.controller.hold(t, "controller off")
        try:
            return self.controller.step(t, R, omega)
        except ValueError as exc:
            self.holds += 1
            return self.controller.hold(t, "bad measurement: %s" % exc)

    def step(self) -> Tuple[RigidBodyState, ControllerOutput]:
        """One control period: measure at t_k, control, hold the joint targets until t_k+1.

        Returns (state at t_k, controller output at t_k). A measurement the controller rejects puts it
        in its hold (safe) state for the step, as the ROS node does.
        """
        t = self.time
        state = self.plant._state  # noqa: SLF001 (read-only use; the plant never mutates states)
        last, self._last_sample = self._last_sample, None
        if last is not None and last.k == self.k and last.state is state:
            R, omega = last.R, last.omega
            output = self._control(t, R, omega) if last.output is None else last.output
        else:
            R, omega = self._measure(state)
            output = self._control(t, R, omega)
        targets = output.joint_targets
        plant = self.plant
        # The controller guarantees (4, 3) finite targets; a target inside its servo range is finite.
        rows = targets.tolist() if targets.shape == (4, 3) else None
        count = plant._outside_count(rows) if rows is not None else 0  # noqa: SLF001
        if rows is None or (count and not np.isfinite(targets).all()):
            raise SimulationError("controller returned invalid joint targets at t = %.3f s: %r" % (t, targets))
        plant._advance(targets, self.dt, rows, count)  # noqa: SLF001 (checked above)
        self.k += 1
        return state, output

    def run(self, duration: float, progress: Optional[ProgressCallback] = None,
            progress_interval: float = 2.0) -> SimulationResult:
        """Simulate ``duration`` s from the current state; records round(duration / dt) + 1 samples
        (t = 0 .. duration inclusive: the last sample is measured, the plant is not stepped past it).

        ``progress(t, duration)`` is called at most every ``progress_interval`` s of wall time and at
        the end. Raises :class:`SimulationError` if the plant diverges.
        """
        duration = float(duration)
        if not (math.isfinite(duration) and duration > 0.0):
            raise ValueError("duration must be a positive finite number of seconds, got %r" % (duration,))
        steps = int(round(duration / self.dt))
        n = steps + 1
        times: List[float] = []
        states: List[RigidBodyState] = []
        records: List[Any] = []
        targets: List[np.ndarray] = []
        positions: List[np.ndarray] = []
        start = time.perf_counter()
        last_report = start
        step = self.step
        for i in range(n):
            positions.append(self.plant._q)  # noqa: SLF001 (arrays are replaced, never mutated)
            times.append(self.time)
            if i < steps:
                state, output = step()
            else:  # last sample: measure and record, do not advance (the next step, if any, starts from it)
                state = self.plant._state  # noqa: SLF001
                R, w = self._measure(state)
                output = self._control(self.time, R, w)
                self._last_sample = _Sample(self.k, state, R, w, output)
            states.append(state)
            records.append(output.state)
            targets.append(output.joint_targets)
            if progress is not None and (i & 63) == 0:
                now = time.perf_counter()
                if now - last_report >= progress_interval:
                    last_report = now
                    progress(times[-1], duration)
        wall = time.perf_counter() - start
        if progress is not None:
            progress(times[-1], duration)
        t_rec = np.array(times)
        rotation = np.array([s.rotation for s in states])
        reported = self._reported(rotation)
        omega = np.array([s.omega for s in states])
        position = np.array([s.position for s in states])
        tau_cmd = np.array([r.tau_cmd for r in records], dtype=float).reshape(n, 3)
        tau_sat = np.array([r.tau_sat for r in records], dtype=float).reshape(n, 3)
        saturated = np.array([bool(r.saturated) for r in records])
        holding = np.array([bool(r.holding) for r in records])
        phases = [tuple(r.pair_phase) for r in records]
        target_array = np.array(targets, dtype=float).reshape(n, 12)
        position_array = np.array(positions, dtype=float).reshape(n, 12)
        info = {
            "dt": self.dt,
            "duration": duration,
            "gains": {"k_p": self.config.gains.k_p, "k_i": self.config.gains.k_i, "k_d": self.config.gains.k_d,
                      "k_aw": self.config.gains.k_aw},
            "t_rec": self.config.t_rec,
            "t_pow_max": self.config.t_pow_max,
            "tau_max": self.config.tau_max,
            "pairs": [list(p) for p in self.config.pairs],
            "normalize_force_direction": bool(self.config.normalize_force_direction),
            "servo_model": self.plant.servo.name,
            "restoring_offset": None if self.restoring_offset is None else self.restoring_offset.tolist(),
            "seed": self.seed,
            "attitude_noise_deg": math.degrees(self.attitude_noise),
            "gyro_noise": self.gyro_noise,
            "clamped_joint_commands": self.plant.clamped_joints,
            "controller_holds": self.holds,
            "plant": getattr(self.plant.model, "name", "paper"),
            "controller": "disarmed" if self.disarmed else "on" if self.controller_enabled else "off",
        }
        return SimulationResult(t=t_rec, rotation=rotation, omega=omega, position=position, tau_cmd=tau_cmd, tau_sat=tau_sat,
                                saturated=saturated, pair_phase=np.array(phases, dtype=str), holding=holding,
                                joint_targets=target_array, joint_positions=position_array,
                                setpoint=self.setpoint_R.copy(),
                                info=info, wall_time=wall, reported_rotation=None if reported is rotation else reported)
