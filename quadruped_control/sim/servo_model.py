"""Servo models for the simulator: how the 12 joint angles follow their commands.

The paper's model (section "Body Dynamics") treats the commanded joint angles as reached instantly:
"the commanded joint angles q_j,i are the inputs to this model and their velocities are obtained
through finite differences". That is :class:`IdealServo`, the default of the paper study.

The paper also notes (section "Experimental Setup") that "the servos have finite bandwidth and do not
reach the commanded velocities instantaneously". :class:`RateLimitedServo` models this with a
first-order position loop whose speed is limited by the servo's no-load speed (95 rpm, section
"Robot Design"):

    dq/dt = clip((q_cmd - q) / T, -w_max, w_max)

integrated exactly over each step for a command held over the step. Its parameters live in the
``simulation.servo`` section of ``config/simulation.yaml`` and are estimates (see there). On the tank
plant it can also carry a dead band (:func:`dead_band_command`, off by default): the error a hobby
servo's position loop ignores.

Joint arrays are (12,) in the :data:`~quadruped_common.robot.JOINT_NAMES` order or (4, 3)
(legs 1..4 x (theta1, theta2, theta3)); models return the shape they are given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np

from quadruped_common.config import ParameterError, load_config, lookup
from quadruped_common.jit import jitable, kernel
from quadruped_common.schema import Param, Schema
from quadruped_control.model.servo import rate_limited_lag_step
from quadruped_control.sim.plants.rigid_body import check_dt

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: Names accepted by :func:`make_servo_model` (CLI ``--servo-model``).
SERVO_MODELS = ("ideal", "rate-limited")

__all__ = [
    "IdealServo",
    "RateLimitedServo",
    "SERVO_MODELS",
    "SERVO_SCHEMA",
    "ServoModel",
    "ServoParams",
    "dead_band_command",
    "load_servo_params",
    "loaded_speed",
    "rate_limited_lag_step",
    "servo_batch_step",
    "tank_servo_params",
    "make_servo_model",
]


def _joints(value: ArrayLike, name: str) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape not in ((12,), (4, 3)):
        raise ValueError("%s must have shape (12,) or (4, 3), got %s" % (name, arr.shape))
    if not np.all(np.isfinite(arr)):
        raise ValueError("%s has non-finite elements: %s" % (name, arr.reshape(-1).tolist()))
    return arr


@dataclass(frozen=True)
class ServoParams:
    """Parameters of :class:`RateLimitedServo`: ``max_speed`` w_max (rad/s), ``time_constant`` T (s),
    ``stall_torque`` tau_stall (N m) of the loaded-servo speed :func:`loaded_speed` (0: the speed does not
    depend on the load) and ``dead_band`` d (rad), the half-width of the error the position loop ignores
    (:func:`dead_band_command`; 0: none)."""

    max_speed: float
    time_constant: float
    stall_torque: float = 0.0
    dead_band: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_speed) and self.max_speed > 0.0):
            raise ParameterError("servo max_speed must be a positive finite rad/s, got %r" % (self.max_speed,))
        if not (math.isfinite(self.time_constant) and self.time_constant >= 0.0):
            raise ParameterError("servo time_constant must be a finite number >= 0 s, got %r"
                                 % (self.time_constant,))
        if not (math.isfinite(self.stall_torque) and self.stall_torque >= 0.0):
            raise ParameterError("servo stall_torque must be a finite number >= 0 N m (0: off), got %r"
                                 % (self.stall_torque,))
        if not (math.isfinite(self.dead_band) and self.dead_band >= 0.0):
            raise ParameterError("servo dead_band must be a finite half-width >= 0 rad (0: off), got %r"
                                 % (self.dead_band,))


class ServoModel:
    """Base class: ``reset(q)`` puts the servos at ``q``; ``update(q_cmd, dt)`` returns the angles after
    ``dt`` s with ``q_cmd`` held. ``position`` is the current angle array (a copy)."""

    name = "base"

    def __init__(self) -> None:
        self._q: Optional[np.ndarray] = None

    @property
    def position(self) -> np.ndarray:
        if self._q is None:
            raise RuntimeError("servo model not initialised: call reset(q) first")
        return self._q.copy()

    def reset(self, q: ArrayLike) -> None:
        """Place the servos at ``q`` (at rest)."""
        self._q = _joints(q, "servo position")

    def update(self, q_cmd: ArrayLike, dt: float) -> np.ndarray:
        """Advance ``dt`` seconds towards the held command ``q_cmd``; returns the new angles."""
        command = _joints(q_cmd, "servo command")
        dt = check_dt(dt)
        if self._q is None:
            self._q = command.copy()
            return command
        if command.shape != self._q.shape:
            command = command.reshape(self._q.shape)
        self._q = self._advance(self._q, command, dt)
        return self._q.copy()

    def update_trusted(self, command: np.ndarray, dt: float) -> np.ndarray:
        """:meth:`update` for a caller that already checked ``command`` (finite float array of the
        shape given to :meth:`reset`) and ``dt`` (positive): no checks, the returned array is the
        model's own (do not modify it)."""
        if self._q is None:
            self._q = command.copy()
        else:
            self._q = self._advance(self._q, command, dt)
        return self._q

    def _advance(self, q: np.ndarray, command: np.ndarray, dt: float) -> np.ndarray:
        raise NotImplementedError


class IdealServo(ServoModel):
    """The paper's servo: the commanded angle is reached at the end of the step (section "Body Dynamics")."""

    name = "ideal"

    def _advance(self, q: np.ndarray, command: np.ndarray, dt: float) -> np.ndarray:
        return command.copy()


class RateLimitedServo(ServoModel):
    """First-order lag with a speed limit, dq/dt = clip((q_cmd - q) / T, -w_max, w_max), exact per step,
    on the error beyond the ``dead_band`` (:func:`dead_band_command`; :class:`ServoParams`).

    With the command held over the step and error e = q_cmd - q, the joint moves at w_max while
    |e| > w_max T, then decays as exp(-t / T). T = 0 is a pure rate limiter. With a ``stall_torque``
    (:class:`ServoParams`) and the plant's joint ``loads`` (set by the simulator after each plant step,
    :attr:`~quadruped_control.sim.plants.tank.TankModel.joint_loads`) the speed limit of each joint is
    its loaded speed, :func:`loaded_speed`.
    """

    name = "rate-limited"

    def __init__(self, params: ServoParams) -> None:
        super().__init__()
        self.params = params
        #: the external torque on each joint (4 x 3 floats, N m) at the last plant step, or None
        self.loads: Optional[Sequence[Sequence[float]]] = None

    def reset(self, q: ArrayLike) -> None:
        super().reset(q)
        self.loads = None

    def _advance(self, q: np.ndarray, command: np.ndarray, dt: float) -> np.ndarray:
        w_max, tau, stall = self.params.max_speed, self.params.time_constant, self.params.stall_torque
        band, positions = self.params.dead_band, q.ravel().tolist()
        targets = [dead_band_command(x, c, band) for x, c in zip(positions, command.ravel().tolist())]
        if stall <= 0.0 or self.loads is None:
            return np.array([rate_limited_lag_step(x, c, w_max, tau, dt)
                             for x, c in zip(positions, targets)]).reshape(q.shape)
        loads = [value for row in self.loads for value in row]
        return np.array([rate_limited_lag_step(x, c, loaded_speed(w_max, c - x, load, stall), tau, dt)
                         for x, c, load in zip(positions, targets, loads)]).reshape(q.shape)


@jitable
def dead_band_command(q: float, command: float, dead_band: float) -> float:
    """The command a servo with a dead band of half-width ``dead_band`` d (rad) acts on, from the joint at
    ``q``: the servo's position loop drives only the error beyond the band,
    dq/dt = clip(dz(q_cmd - q) / T, -w_max, w_max) with dz(e) = sign(e) max(|e| - d, 0).

    Physics: a hobby servo's amplifier ignores a pulse-width error below its dead band (1-10 us of pulse,
    0.1-0.9 deg at the IB53BHU's ~11 us/deg) so that it does not hunt, and its gear train adds backlash
    of the same order; the joint stops up to d short of each command and a reversal first crosses 2 d of
    command before the joint moves back (the play of a backlash), so a stroke loses a share of its
    amplitude that grows as the stroke shrinks. (The model's strokes sweep about 20 deg of joint angle at
    every error, so the share stays small; docs/tank_model.md, "Candidate effects (project, off by default)".)

    Exact for a held command: while |e| > d the lag drives q towards q_cmd - sign(e) d, which it never
    passes, so over a step dz(e) = (q_cmd - sign(e) d) - q and :func:`rate_limited_lag_step` towards that
    command is the exact solution; inside the band the joint stays (returns ``q``). d = 0 returns
    ``command`` unchanged, a NaN command NaN."""
    if dead_band <= 0.0:
        return command
    error = command - q
    if error > dead_band:
        return command - dead_band
    if error < -dead_band:
        return command + dead_band
    if error != error:
        return error
    return q


@jitable
def loaded_speed(max_speed: float, error: float, load: float, stall_torque: float) -> float:
    """The speed limit of a servo that moves a joint towards ``error`` = q_cmd - q against the external
    torque ``load`` (N m, positive along the joint angle): the DC motor's torque-speed line,
    w = w_max (1 - tau_opp / tau_stall), with tau_opp the part of the load that opposes the motion (a load
    that helps does not speed the servo beyond its no-load speed: its gearbox and position loop hold it).
    ``stall_torque`` <= 0: no load dependence (w_max). At or beyond the stall torque the joint stops
    (a floor of 1e-6 w_max keeps the lag's arithmetic finite)."""
    if stall_torque <= 0.0:
        return max_speed
    opposing = -load if error > 0.0 else (load if error < 0.0 else 0.0)
    if opposing <= 0.0:
        return max_speed
    fraction = 1.0 - opposing / stall_torque
    return max_speed * (fraction if fraction > 1e-6 else 1e-6)


@kernel
def servo_batch_step(q, command, ideal, max_speed, time_constant, stall_torque, dead_band, loads, dt, out, mid, rate):
    """Every trial's servos after ``dt`` s with ``command`` held, into ``out`` (N, 4, 3): the command itself
    for an ``ideal`` trial, else :func:`rate_limited_lag_step` per joint with the trial's ``max_speed``
    and ``time_constant`` (N,) towards the :func:`dead_band_command` of its ``dead_band`` (N,), the speed
    the :func:`loaded_speed` against the joint ``loads`` (N, 4, 3) where the trial's ``stall_torque`` (N,)
    is positive: the per-trial functions in a compiled loop (:mod:`quadruped_common.jit`).
    Also the joints as the plant holds them over the step
    (:class:`~quadruped_control.sim.simulation.PlantSimulator`), into ``mid`` (q + out) / 2 and ``rate``
    (out - q) / dt, in the same loop (``out``, ``mid``, ``rate`` must not alias ``q``)."""
    for i in range(q.shape[0]):
        for leg in range(q.shape[1]):
            for joint in range(q.shape[2]):
                start = q[i, leg, joint]
                if ideal[i]:
                    end = command[i, leg, joint]
                else:
                    target = dead_band_command(start, command[i, leg, joint], dead_band[i])
                    speed = loaded_speed(max_speed[i], target - start, loads[i, leg, joint], stall_torque[i])
                    end = rate_limited_lag_step(start, target, speed, time_constant[i], dt)
                out[i, leg, joint] = end
                mid[i, leg, joint] = 0.5 * (start + end)
                rate[i, leg, joint] = (end - start) / dt


def tank_servo_params(params: ServoParams, tank: Any) -> ServoParams:
    """The servos on the tank plant: ``params`` with the tank's ``servo_speed_scale`` and
    ``servo_lag_scale`` applied, its loaded-servo ``servo_stall_torque`` and its ``servo_dead_band``
    (:class:`~quadruped_control.sim.plants.tank.TankParams`, the ``servos`` section of tank.yaml). The one
    place both the offline trials and the simulated robot (sim_node) take them from."""
    return replace(params, max_speed=params.max_speed * tank.servo_speed_scale,
                   time_constant=params.time_constant * tank.servo_lag_scale, stall_torque=tank.servo_stall_torque,
                   dead_band=tank.servo_dead_band)


#: The ``simulation.servo`` keys of ``config/simulation.yaml`` (the rate-limited servo; part of
#: :data:`~quadruped_control.sim.simulation.SIMULATION_SCHEMA`).
SERVO_SCHEMA = Schema("simulation.yaml", (
    Param("simulation.servo.speed_scale", "", "fraction of robot.yaml's servo no-load speed reachable under load in "
          "water", 0.0, 1.0, low_open=True, default=1.0, source="estimate"),
    Param("simulation.servo.time_constant", "s", "time constant T of the position loop's first-order lag, dq/dt = "
          "clip((q_cmd - q) / T, -w_max, w_max)", 0.0, 10.0, source="estimate"),
))


def servo_params_from_dict(tree: Mapping[str, Any], robot_yaml: Optional[str] = None) -> ServoParams:
    """:class:`ServoParams` from a parsed simulation.yaml tree (its ``simulation.servo`` section: load
    scale and lag) and the no-load speed ``servo.no_load_speed_rpm`` of ``config/robot.yaml`` (or
    ``robot_yaml``), the one place the servo speed is kept."""
    from quadruped_control.model.params import load_robot_params

    v = SERVO_SCHEMA.read({"simulation": {"servo": lookup(tree, "simulation.servo")}})
    scale = v["simulation.servo.speed_scale"]
    return ServoParams(max_speed=load_robot_params(robot_yaml).servo_no_load_speed * scale,
                       time_constant=v["simulation.servo.time_constant"])


def load_servo_params(path: Optional[str] = None, tree: Optional[Mapping[str, Any]] = None,
                      robot_yaml: Optional[str] = None) -> ServoParams:
    """:class:`ServoParams` from ``config/simulation.yaml`` (or ``tree``) and the servo speed of
    ``config/robot.yaml`` (or ``robot_yaml``)."""
    if tree is not None:
        return servo_params_from_dict(tree, robot_yaml)
    return load_config(path, "simulation.yaml", lambda data: servo_params_from_dict(data, robot_yaml))


def make_servo_model(name: str, params: Optional[ServoParams] = None) -> ServoModel:
    """Servo model by name: ``"ideal"`` or ``"rate-limited"`` (``params`` default from the config)."""
    if name == "ideal":
        return IdealServo()
    if name in ("rate-limited", "rate_limited"):
        return RateLimitedServo(params if params is not None else load_servo_params())
    raise ValueError("unknown servo model %r (choose from %s)" % (name, ", ".join(SERVO_MODELS)))
