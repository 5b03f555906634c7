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
``simulation.servo`` section of ``config/simulation.yaml`` and are estimates (see there).

Joint arrays are (12,) in the :data:`~quadruped_common.robot.JOINT_NAMES` order or (4, 3)
(legs 1..4 x (theta1, theta2, theta3)); models return the shape they are given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np

from quadruped_common.config import ParameterError, check_keys, load_config, lookup, number

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: Names accepted by :func:`make_servo_model` (CLI ``--servo-model``).
SERVO_MODELS = ("ideal", "rate-limited")

__all__ = [
    "IdealServo",
    "RateLimitedServo",
    "SERVO_MODELS",
    "ServoModel",
    "ServoParams",
    "load_servo_params",
    "make_servo_model",
]


def _joints(value: ArrayLike, name: str) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape not in ((12,), (4, 3)):
        raise ValueError("%s must have shape (12,) or (4, 3), got %s" % (name, arr.shape))
    if not np.all(np.isfinite(arr)):
        raise ValueError("%s has non-finite elements: %s" % (name, arr.reshape(-1).tolist()))
    return arr


def _positive_dt(dt: float) -> float:
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError("dt must be a positive finite number of seconds, got %r" % (dt,))
    return dt


@dataclass(frozen=True)
class ServoParams:
    """Parameters of :class:`RateLimitedServo`: ``max_speed`` w_max (rad/s), ``time_constant`` T (s)."""

    max_speed: float
    time_constant: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_speed) and self.max_speed > 0.0):
            raise ParameterError("servo max_speed must be a positive finite rad/s, got %r" % (self.max_speed,))
        if not (math.isfinite(self.time_constant) and self.time_constant >= 0.0):
            raise ParameterError("servo time_constant must be a finite number >= 0 s, got %r"
                                 % (self.time_constant,))


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
        dt = _positive_dt(dt)
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
    """First-order lag with a speed limit, dq/dt = clip((q_cmd - q) / T, -w_max, w_max), exact per step.

    With the command held over the step and error e = q_cmd - q, the joint moves at w_max while
    |e| > w_max T, then decays as exp(-t / T). T = 0 is a pure rate limiter.
    """

    name = "rate-limited"

    def __init__(self, params: ServoParams) -> None:
        super().__init__()
        self.params = params

    def _advance(self, q: np.ndarray, command: np.ndarray, dt: float) -> np.ndarray:
        """The exact step on plain floats (12 joints: faster than a dozen small numpy operations); the
        same element-wise formulas as :meth:`_advance_array` (math.exp may differ from np.exp by an ulp)."""
        w_max, tau = self.params.max_speed, self.params.time_constant
        exp = math.exp
        out = []
        if tau <= 1e-9 * dt:  # no lag to speak of (and no overflow in dt / tau): pure rate limiter
            step = w_max * dt
            for x, c in zip(q.ravel().tolist(), command.ravel().tolist()):
                e = c - x
                if e > 0.0:
                    out.append(x + (e if e < step else step))
                elif e < 0.0:
                    out.append(x - (-e if -e < step else step))
                else:  # zero, or NaN (kept, as np.sign gives NaN)
                    out.append(x + e * 0.0 if e != e else x)
            return np.array(out).reshape(q.shape)
        knee = w_max * tau                                # |e| below which the lag is linear
        for x, c in zip(q.ravel().tolist(), command.ravel().tolist()):
            e = c - x
            magnitude = e if e >= 0.0 else -e
            t_saturated = (magnitude - knee) / w_max
            if not t_saturated > 0.0:
                t_saturated = 0.0
            if t_saturated >= dt:
                new_magnitude = magnitude - w_max * dt
            else:
                remaining = dt - t_saturated
                new_magnitude = (magnitude if magnitude < knee else knee) * exp(-(remaining if remaining > 0.0 else 0.0)
                                                                                / tau)
            if e > 0.0:
                out.append(c - new_magnitude)
            elif e < 0.0:
                out.append(c + new_magnitude)
            else:  # zero error: stays; NaN propagates as in the array formulas
                out.append(c - e * new_magnitude if e != e else c)
        return np.array(out).reshape(q.shape)

    def _advance_array(self, q: np.ndarray, command: np.ndarray, dt: float) -> np.ndarray:
        """Reference of :meth:`_advance` with numpy array operations (used by the tests)."""
        w_max, tau = self.params.max_speed, self.params.time_constant
        error = command - q
        magnitude = np.abs(error)
        sign = np.sign(error)
        if tau <= 1e-9 * dt:  # no lag to speak of (and no overflow in dt / tau): pure rate limiter
            return q + sign * np.minimum(magnitude, w_max * dt)
        knee = w_max * tau                                # |e| below which the lag is linear
        t_saturated = np.maximum(0.0, (magnitude - knee) / w_max)
        remaining = np.maximum(0.0, dt - t_saturated)
        linear_error = np.minimum(magnitude, knee) * np.exp(-remaining / tau)
        saturated_only = t_saturated >= dt
        new_magnitude = np.where(saturated_only, magnitude - w_max * dt, linear_error)
        return command - sign * new_magnitude


def servo_params_from_dict(tree: Mapping[str, Any], robot_yaml: Optional[str] = None) -> ServoParams:
    """:class:`ServoParams` from a parsed simulation.yaml tree (its ``simulation.servo`` section: load
    scale and lag) and the no-load speed ``servo.no_load_speed_rpm`` of ``config/robot.yaml`` (or
    ``robot_yaml``), the one place the servo speed is kept."""
    from quadruped_control.model.params import load_robot_params

    key = "simulation.servo"
    servo = check_keys(lookup(tree, key), key, ("speed_scale", "time_constant"), ("time_constant",))
    scale = number(servo.get("speed_scale", 1.0), key + ".speed_scale", 0.0, 1.0, low_open=True)
    tau = number(servo["time_constant"], key + ".time_constant", 0.0, 10.0)
    return ServoParams(max_speed=load_robot_params(robot_yaml).servo_no_load_speed * scale, time_constant=tau)


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
