"""Open-loop replay of a recorded run through the tank plant: the measured joint angles drive N plants.

Why: Table 1 of the paper (section "Experiments") gives fifteen rows of summary metrics, and fitting the
tank plant to them cannot tell its physics apart (docs/identification.md). A recorded run holds far more:
the attitude at the IMU's rate and every joint angle (the ADS1115 feedback). Driven by the measured
joints, the plant runs without the controller and the servo model, so what is left to explain the
recorded attitude is the plant alone: its hydrostatics, drag, added mass, rope and the candidate effects
of :mod:`quadruped_control.sim.plants.tank`.

:class:`Record` is a run on the plant's time grid (t_k = t_0 + k dt): attitude R_B^W, body rate, joint
angles and which samples are measured (a gap in either stream, or a corrupt joint sample, makes its
samples invalid). :func:`replay` runs the recorded joints through one
:class:`~quadruped_control.sim.plants.tank_batch.TankPlantBatch` trial per (parameter set, window), the
joints held over each step as the closed-loop engines hold them (midpoint and finite-difference rate,
:func:`~quadruped_control.sim.servo_model.servo_batch_step`), so a record of a simulated run replays to
the same bits from the same state.

:func:`replay_servos` is the servos' half: the closed loop's servo step
(:func:`~quadruped_control.sim.servo_model.servo_batch_step`) driven by the recorded commands from the
measured joints at each window start, for several (speed, time constant) pairs at once.

Multiple shooting: a window starts from the recorded attitude and body rate. What no sensor on the
robot measures (the body's position and velocity, the water in the paws' and the body's wakes, the
floating block) either starts at rest (``lead`` = 0): the body on a vertical rope under its anchor
(:meth:`~quadruped_control.sim.plants.tank.TankModel.attach`), still wakes, the block at rest; or comes
from a lead-in: the plant runs ``lead`` steps before the window with the recorded joints, and after each
step its attitude and body rate are set to the record's. The unmeasured states then follow the measured
motion as they did on the robot (an observer with full gain on what is measured, none on the rest), and
the window starts from them. Why: a free body swims while it turns, and the paws' drag depends on that
velocity; started at rest, the paper's free body misses its own run by about 2.5 deg within 3 s, by
0.5 deg after a lead-in of 3 s and by 0.13 deg after 5 s (tests/control/sim/test_replay.py). On a rope
the body hardly translates, and the lead-in matters less.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from quadruped_common.so3 import geodesic_angles
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.tank_params import TankParams
from quadruped_control.sim.plants.tank_batch import TankPlantBatch
from quadruped_control.sim.servo_model import servo_batch_step

__all__ = ["Record", "ReplayResult", "attitude_errors", "joint_errors", "replay", "replay_servos", "sample_index",
           "still_errors", "window_starts"]


@dataclass(frozen=True)
class Record:
    """A run on a uniform time grid: ``t`` (K,) s with step ``dt``; ``rotation`` (K, 3, 3) the attitude
    R_B^W; ``omega`` (K, 3) the body rate in body axes, rad/s; ``joints`` (K, 4, 3) the joint angles
    (theta1, theta2, theta3 of legs 1..4), rad; ``valid`` (K,) whether the sample was measured (the
    invalid samples' values are not used). ``source`` says where it came from."""

    t: np.ndarray
    rotation: np.ndarray
    omega: np.ndarray
    joints: np.ndarray
    valid: np.ndarray
    dt: float
    source: str = ""
    #: (K, 4, 3) the joint targets commanded at each sample and held to the next, rad (the controller's
    #: /servo_command); NaN where none was recorded; None: the record has no commands.
    commands: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        k = self.t.shape[0] if self.t.ndim == 1 else -1
        shapes = {"rotation": (k, 3, 3), "omega": (k, 3), "joints": (k, 4, 3), "valid": (k,), "commands": (k, 4, 3)}
        for name, shape in shapes.items():
            if getattr(self, name) is not None and getattr(self, name).shape != shape:
                raise ValueError("record %s must have shape %s, got %s" % (name, shape, getattr(self, name).shape))
        if k < 2:
            raise ValueError("a record needs at least two samples, got %d" % max(k, 0))
        if not (math.isfinite(self.dt) and self.dt > 0.0):
            raise ValueError("record dt must be a positive time step, got %r" % (self.dt,))
        if not np.allclose(np.diff(self.t), self.dt, rtol=0.0, atol=1e-9 * max(1.0, abs(float(self.t[-1])))):
            raise ValueError("record times must be a uniform grid with step dt = %g s" % self.dt)
        good = self.valid.astype(bool)
        for name in ("rotation", "omega", "joints"):
            if not np.all(np.isfinite(getattr(self, name)[good])):
                raise ValueError("record %s is not finite at a sample marked valid" % name)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])


def window_starts(record: Record, steps: int, stride: int, commanded: bool = False, lead: int = 0) -> np.ndarray:
    """The first sample of each window of ``steps`` steps (``steps`` + 1 samples, all valid), one every
    ``stride`` samples from the record's start plus ``lead`` (a window over an invalid sample is left out);
    ``commanded``: every sample of the window has a command too (:func:`replay_servos`); ``lead``: the
    window's lead-in of :func:`replay` (``lead`` samples before the start) must be valid too."""
    if steps < 1 or stride < 1 or lead < 0:
        raise ValueError("window steps and stride must be >= 1 and lead >= 0, got %d, %d and %d"
                         % (steps, stride, lead))
    valid = record.valid.astype(bool)
    if commanded:
        if record.commands is None:
            return np.zeros(0, dtype=int)
        valid = valid & np.all(np.isfinite(record.commands.reshape(valid.size, 12)), axis=1)
    # bad[k] = number of invalid samples before k: samples first..last are clean when the count does not grow
    bad = np.concatenate(([0], np.cumsum(~valid)))
    last = valid.size - steps - 1
    starts = np.arange(lead, last + 1, stride) if last >= lead else np.zeros(0, dtype=int)
    return starts[bad[starts + steps + 1] == bad[starts - lead]].astype(int)


@dataclass
class ReplayResult:
    """What :func:`replay` returns: the replayed attitude every ``every`` steps of each window,
    ``rotation`` (S, W, M, 3, 3) for S parameter sets, W windows and M = steps // every samples (the
    first after ``every`` steps); ``failed`` (S, W) whose plant step failed (its rotations from then on
    are those of the failure, not to be used)."""

    rotation: np.ndarray
    failed: np.ndarray
    starts: np.ndarray
    every: int


def replay(robot: RobotParams, tanks: Sequence[TankParams], record: Record, starts: Sequence[int], steps: int,
           every: int = 10, lead: int = 0) -> ReplayResult:
    """Replay ``record``'s joints from each window start (:func:`window_starts`) for ``steps`` steps on the
    tank plant of each of ``tanks`` (module docstring): one batch of len(tanks) x len(starts) trials.

    ``lead`` > 0 runs a lead-in of ``lead`` steps before each start, with the attitude and body rate held to
    the record's after every step (module docstring): the states no sensor measures (the body's drift on
    its rope, the wakes, the block) follow the measured motion, and the window starts from them instead of
    from rest. ``lead`` = 0: they start at rest."""
    starts = np.asarray(starts, dtype=int)
    n_sets, n_windows = len(tanks), starts.size
    if n_sets < 1 or n_windows < 1:
        raise ValueError("replay needs at least one parameter set and one window")
    if every < 1 or steps < every or lead < 0:
        raise ValueError("replay needs steps >= every >= 1 and lead >= 0, got %d, %d and %d" % (steps, every, lead))
    if starts.min() - lead < 0 or starts.max() + steps >= record.t.size:
        raise ValueError("a window or its lead-in runs past the record (%d samples)" % record.t.size)
    first = starts - lead
    plant = TankPlantBatch(robot, [tank for tank in tanks for _ in range(n_windows)])
    n = plant.n
    windows = np.tile(np.arange(n_windows), n_sets)
    p, v = np.zeros((n, 3)), np.zeros((n, 3))
    R = np.ascontiguousarray(record.rotation[first[windows]], dtype=float)
    w = np.ascontiguousarray(record.omega[first[windows]], dtype=float)
    plant.attach(p, R)
    joints = record.joints
    samples = steps // every
    out = np.empty((n, samples, 3, 3))
    dt = record.dt
    mid, rate = np.empty((n, 4, 3)), np.empty((n, 4, 3))
    held_mid, held_rate = mid.reshape(n_sets, n_windows, 4, 3), rate.reshape(n_sets, n_windows, 4, 3)  # views
    forced_R, forced_w = R.reshape(n_sets, n_windows, 3, 3), w.reshape(n_sets, n_windows, 3)  # views
    for k in range(lead + steps):
        q0, q1 = joints[first + k], joints[first + k + 1]
        # the closed-loop engines' joint hold (servo_batch_step): midpoint and finite-difference rate
        held_mid[:] = 0.5 * (q0 + q1)
        held_rate[:] = (q1 - q0) / dt
        p, v, R, w = plant.step(p, v, R, w, mid, rate, dt)
        if k < lead:  # the lead-in: the measured states held to the record (the step advanced them in place)
            forced_R[:] = record.rotation[first + k + 1]
            forced_w[:] = record.omega[first + k + 1]
        elif (k + 1 - lead) % every == 0:
            out[:, (k + 1 - lead) // every - 1] = R
    return ReplayResult(rotation=out.reshape(n_sets, n_windows, samples, 3, 3),
                        failed=plant.failed.reshape(n_sets, n_windows).copy(), starts=starts, every=every)


def _angles(recorded: np.ndarray, replayed: np.ndarray) -> np.ndarray:
    """Geodesic angle (rad) between rotations (..., 3, 3) that broadcast (:func:`geodesic_angles`)."""
    recorded, replayed = np.broadcast_arrays(recorded, replayed)
    shape = recorded.shape[:-2]
    return geodesic_angles(recorded.reshape(-1, 3, 3), replayed.reshape(-1, 3, 3)).reshape(shape)


def sample_index(starts: Sequence[int], samples: int, every: int) -> np.ndarray:
    """(W, M) the record's sample of each of :func:`replay`'s (and :func:`replay_servos`') samples: the
    first ``every`` steps after each window start, then every ``every`` steps."""
    return np.asarray(starts, dtype=int)[:, None] + every * np.arange(1, samples + 1)[None, :]


def _recorded_samples(record: Record, starts: np.ndarray, samples: int, every: int) -> np.ndarray:
    return record.rotation[sample_index(starts, samples, every)]  # (W, M, 3, 3)


def attitude_errors(result: ReplayResult, record: Record) -> np.ndarray:
    """(S, W, M) geodesic angle (rad) between the replayed and the recorded attitude at each sample of
    :func:`replay`'s result; pi (the largest) for a failed trial's samples."""
    samples = result.rotation.shape[2]
    errors = _angles(_recorded_samples(record, result.starts, samples, result.every)[None], result.rotation)
    errors[result.failed] = math.pi
    return errors


def still_errors(record: Record, starts: Sequence[int], steps: int, every: int = 10) -> np.ndarray:
    """(W, M) geodesic angle (rad) of a model that predicts no motion at all (the attitude held at each
    window's start) at :func:`replay`'s samples: the baseline a plant must beat to predict anything."""
    starts = np.asarray(starts, dtype=int)
    recorded = _recorded_samples(record, starts, steps // every, every)
    return _angles(record.rotation[starts][:, None], recorded)


def replay_servos(record: Record, starts: Sequence[int], steps: int, max_speeds: Sequence[float],
                  time_constants: Sequence[float], every: int = 10,
                  dead_bands: Optional[Sequence[float]] = None) -> np.ndarray:
    """The servos' half of a record: from the measured joints at each window start, the rate-limited lag
    (:func:`~quadruped_control.sim.servo_model.servo_batch_step`, the closed loop's servo step) driven by the
    recorded commands, each held over its step, for each (max speed, time constant, dead band) set (rad/s,
    s, rad; ``dead_bands`` None: none). Returns the joint angles every ``every`` steps, (S, W, M, 4, 3), as
    :func:`replay`'s samples."""
    starts = np.asarray(starts, dtype=int)
    speeds, lags = np.asarray(max_speeds, dtype=float), np.asarray(time_constants, dtype=float)
    bands = np.zeros(speeds.size) if dead_bands is None else np.asarray(dead_bands, dtype=float)
    n_sets, n_windows = speeds.size, starts.size
    if record.commands is None:
        raise ValueError("the record has no commands")
    if n_sets < 1 or n_windows < 1 or lags.size != n_sets or bands.size != n_sets:
        raise ValueError("replay_servos needs a time constant (and a dead band) per speed, one or more, and a "
                         "window")
    if every < 1 or steps < every or starts.min() < 0 or starts.max() + steps >= record.t.size:
        raise ValueError("replay_servos needs steps >= every >= 1 within the record")
    n = n_sets * n_windows
    q = np.ascontiguousarray(np.tile(record.joints[starts], (n_sets, 1, 1)))
    out, mid, rate = np.empty_like(q), np.empty_like(q), np.empty_like(q)
    command = np.empty_like(q)
    held = command.reshape(n_sets, n_windows, 4, 3)  # a view
    speed, lag, dead_band = np.repeat(speeds, n_windows), np.repeat(lags, n_windows), np.repeat(bands, n_windows)
    ideal, loads, stall = np.zeros(n, dtype=bool), np.zeros((n, 4, 3)), np.zeros(n)
    samples = np.empty((n, steps // every, 4, 3))
    for k in range(steps):
        held[:] = record.commands[starts + k]
        servo_batch_step(q, command, ideal, speed, lag, stall, dead_band, loads, record.dt, out, mid, rate)
        q, out = out, q
        if (k + 1) % every == 0:
            samples[:, (k + 1) // every - 1] = q
    return samples.reshape(n_sets, n_windows, steps // every, 4, 3)


def joint_errors(replayed: np.ndarray, record: Record, starts: Sequence[int], every: int) -> np.ndarray:
    """(S, W, M) root mean square over the twelve joints (rad) of :func:`replay_servos`' angles against the
    record's measured joints at the same samples."""
    difference = replayed - record.joints[sample_index(starts, replayed.shape[2], every)][None]
    return np.sqrt(np.mean(difference.reshape(difference.shape[:3] + (12,)) ** 2, axis=-1))
