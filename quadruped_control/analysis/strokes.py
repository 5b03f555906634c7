"""The strokes a robot made, from its recorded joint angles: how long each power stroke lasted, how far
each paw went and how fast.

Why: the identification of the tank model (docs/identification.md, "What the model misses, and
why") finds that in simulation a power stroke lasts 0.07-0.16 s before its commanded path meets the
workspace boundary, the paws move a few centimetres, and the strokes deliver 2-6 % of the commanded
torque. Whether the real robot strokes the same way decides what the model lacks, and every bag holds
the answer: the controller's pair phases (``/controller_state``, paper section "Power and Recovery
Stroke Cycle") time each power stroke, and the measured servo angles (``/joint_states``, the ADS1115
feedback) give each paw's path in the body frame through the forward kinematics, eq. (ee_body).

For every power stroke of a pair, over its cycle (from the power phase's start to that pair's next
power start), and for each leg of the pair:

- ``power_duration``: the power phase's length (s), as the controller timed it;
- ``excursion``: the largest distance of the paw from where it was when the power phase began (m);
- ``peak_speed``: the paw's largest speed relative to the body (m/s), from successive joint samples.

A cycle still running at the end of the record is left out (its excursion is not known yet); joint
samples with an angle that is not finite or outside its servo's range (``joint_limits_deg`` of
robot.yaml), or that the kinematics cannot place, are corrupt feedback: skipped and counted. Figures are given as (p10, median, p90) over the strokes.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_control.model.kinematics import UnreachableError, foot_position
from quadruped_control.model.params import RobotParams

__all__ = ["StrokeStatistics", "foot_paths", "format_spread", "stroke_statistics"]

Spread = Tuple[float, float, float]


@dataclass(frozen=True)
class StrokeStatistics:
    """What :func:`stroke_statistics` found (module docstring): counts, and (p10, median, p90) spreads."""

    strokes: int               # complete power-stroke cycles, over both pairs
    leg_strokes: int           # (stroke, leg) pairs with joint samples in the cycle
    power_duration: Spread     # s
    excursion: Spread          # m
    peak_speed: Spread         # m/s
    skipped_samples: int       # joint samples not finite, outside the servo ranges or not placeable

    def as_dict(self) -> Dict[str, object]:
        return asdict(self)


def _spread(values: Sequence[float]) -> Spread:
    p10, p50, p90 = np.percentile(np.asarray(values, dtype=float), [10.0, 50.0, 90.0])
    return float(p10), float(p50), float(p90)


def _times(t: Sequence[float], name: str) -> np.ndarray:
    arr = np.asarray(t, dtype=float)
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise ValueError("%s must be a 1-D array of finite times" % name)
    if arr.size > 1 and np.any(np.diff(arr) <= 0.0):
        raise ValueError("%s must increase strictly (sort the samples and drop repeated stamps)" % name)
    return arr


def foot_paths(joints: np.ndarray, robot: RobotParams) -> Tuple[np.ndarray, np.ndarray]:
    """Paw positions r_e,i^B (samples x 4 x 3, m; eq. (ee_body)) of joint samples (samples x 12, the order
    of :data:`quadruped_common.robot.JOINT_NAMES`), and a mask of the samples every leg could be placed
    for (finite angles inside the servo ranges that the five-bar closes on)."""
    q = np.asarray(joints, dtype=float)
    if q.ndim != 2 or q.shape[1] != 12:
        raise ValueError("joint samples must have shape (samples, 12), got %s" % (q.shape,))
    paths = np.full((q.shape[0], 4, 3), np.nan)
    limits = np.tile(robot.joint_limits.as_array(), (4, 1))  # 12 x (low, high)
    with np.errstate(invalid="ignore"):
        good = np.all(np.isfinite(q) & (q >= limits[:, 0]) & (q <= limits[:, 1]), axis=1)
    for k in np.flatnonzero(good):
        try:
            for leg in range(4):
                paths[k, leg] = foot_position(q[k, 3 * leg:3 * leg + 3], leg + 1, robot)
        except UnreachableError:
            good[k] = False
    return paths, good


def stroke_statistics(phase_t: Sequence[float], in_power: Sequence[Sequence[bool]], joint_t: Sequence[float],
                      joints: np.ndarray, robot: RobotParams,
                      pairs: Sequence[Sequence[int]]) -> Optional[StrokeStatistics]:
    """Stroke figures (module docstring) of a record, or None when it holds no complete stroke cycle with
    joint samples.

    ``phase_t`` (M,), s, and ``in_power`` (M, pairs): the controller's steps and whether each pair was in
    its power phase; ``joint_t`` (K,), s, and ``joints`` (K, 12), rad: the measured joint angles; both
    time series increasing; ``pairs``: the legs (1..4) of each pair, in the controller's order.
    """
    t = _times(phase_t, "phase_t")
    power = np.asarray(in_power, dtype=bool)
    if power.ndim != 2 or power.shape != (t.size, len(pairs)):
        raise ValueError("in_power must have shape (%d, %d), got %s" % (t.size, len(pairs), power.shape))
    tj = _times(joint_t, "joint_t")
    paths, good = foot_paths(joints, robot)
    if paths.shape[0] != tj.size:
        raise ValueError("joint_t has %d samples, joints %d" % (tj.size, paths.shape[0]))
    durations: List[float] = []
    excursions: List[float] = []
    speeds: List[float] = []
    for p, legs in enumerate(pairs):
        column = power[:, p]
        starts = np.flatnonzero(column[1:] & ~column[:-1]) + 1
        if column.size and column[0]:
            starts = np.concatenate(([0], starts))
        for s, next_start in zip(starts, starts[1:]):  # complete cycles only
            ends = np.flatnonzero(~column[s:next_start])
            if ends.size == 0:
                continue  # the power phase never ended before the next start: a gap in the record
            durations.append(float(t[s + ends[0]] - t[s]))
            inside = (tj >= t[s]) & (tj < t[next_start]) & good
            if np.count_nonzero(inside) < 2:
                continue
            ts = tj[inside]
            for leg in legs:
                path = paths[inside, leg - 1]
                excursions.append(float(np.max(np.linalg.norm(path - path[0], axis=1))))
                steps = np.linalg.norm(np.diff(path, axis=0), axis=1) / np.diff(ts)
                speeds.append(float(np.max(steps)))
    if not durations or not excursions:
        return None
    return StrokeStatistics(strokes=len(durations), leg_strokes=len(excursions), power_duration=_spread(durations),
                            excursion=_spread(excursions), peak_speed=_spread(speeds),
                            skipped_samples=int(np.count_nonzero(~good)))


def format_spread(spread: Spread, scale: float = 1.0, digits: int = 2) -> str:
    """"median (p10-p90)" of a spread, each value times ``scale``."""
    p10, p50, p90 = (v * scale for v in spread)
    return "%.*f (%.*f-%.*f)" % (digits, p50, digits, p10, digits, p90) if math.isfinite(p50) else "-"
