"""A setpoint step test read as Table 1 is read (pure numpy): how long the body takes to settle after the
setpoint of one tilt axis steps from a held attitude, towards upright or away from it.

The test (docs/identification.md, "The step test as a study"): the robot
holds a tilt (roll or pitch 45 deg), then the setpoint steps by about 12 deg towards upright (a return, as
after an overshoot) or away from it. A plant with a net static torque pushing away from upright returns
much more slowly than it moves away; one whose trim and rope balance takes the same time both ways.

A step is any change of the recorded setpoint (:func:`find_steps`); its response (:func:`step_response`)
runs from the change to the next one, the record's end, or the instant the controller stopped acting
(:func:`response_ends`: a robot disarmed or holding its safe pose is not following the step, and a step taken
less than :data:`HOLD_CHECK` s after such a stop is not read at all). On that stretch, the stepped axis's angle is
smoothed as the paper's metrics smooth it (a 3 s centred moving average, truncated at the stretch's ends:
:func:`~quadruped_control.analysis.metrics.moving_average_centered`), and the error to the new setpoint
gives:

- ``settle_6``: the paper's settling time t_s (section "Experiments": within +-6 deg for 30 s,
  :func:`~quadruped_control.analysis.metrics.settling_time`), from the step;
- ``settle_2``: the same within +-2 deg;
- ``overshoot_deg``: how far the smoothed angle went past the new setpoint in the step's direction
  (0 if it never did);
- ``held_error_deg``: before the step, the mean error to the old setpoint over the last
  :data:`HOLD_CHECK` s (how well the held tilt was held: the test assumes it was).

Two responses agree (:func:`agrees`) when both settle within a factor :data:`AGREEMENT_FACTOR` of each other,
or neither settles: the identification's "within 2x" (docs/identification.md, "Objective, with its weights").
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_control.analysis.metrics import (AXES, SETTLING_BAND_DEG, SETTLING_HOLD, moving_average_centered,
                                                settling_time)

__all__ = ["AGREEMENT_FACTOR", "FINE_BAND_DEG", "HOLD_CHECK", "MIN_STEP_DEG", "Step", "StepResponse", "TIME_FLOOR",
           "agrees", "find_steps", "judged", "response_ends", "step_response"]

#: The narrower band (deg) the test also times: the fitted members differ most in how they creep into it.
FINE_BAND_DEG = 2.0
#: Seconds before a step over which the held error is averaged.
HOLD_CHECK = 10.0
#: A setpoint change smaller than this (deg, on every axis) is not a step (float noise of a republished one).
MIN_STEP_DEG = 0.5
#: Two settling times agree within this factor.
AGREEMENT_FACTOR = 2.0
#: Settling times below this (s) count as this when compared: a step inside the band settles "at once", whatever
#: the smoothing's first samples say (the identification's objective has the same floor).
TIME_FLOOR = 0.5


@dataclass(frozen=True)
class Step:
    """A setpoint change at ``time`` (s) from ``before`` to ``after`` (roll, pitch, yaw, rad)."""

    time: float
    before: Tuple[float, float, float]
    after: Tuple[float, float, float]

    @property
    def axis(self) -> int:
        """The axis that changed most (0 roll, 1 pitch, 2 yaw)."""
        return int(np.argmax(np.abs(np.subtract(self.after, self.before))))

    @property
    def single_axis(self) -> bool:
        """Whether only :attr:`axis` changed (by more than :data:`MIN_STEP_DEG`): the test's kind of step."""
        change = np.abs(np.subtract(self.after, self.before))
        return int(np.count_nonzero(change > math.radians(MIN_STEP_DEG))) == 1

    @property
    def towards_upright(self) -> bool:
        """Whether the stepped axis's new setpoint is nearer level than the old one."""
        return abs(self.after[self.axis]) < abs(self.before[self.axis])


@dataclass(frozen=True)
class StepResponse:
    """How one step was followed (module docstring); times in s from the step, angles in deg."""

    axis: str
    before_deg: float
    after_deg: float
    towards_upright: bool
    settle_6: Optional[float]
    settle_2: Optional[float]
    overshoot_deg: float
    held_error_deg: Optional[float]
    duration: float

    def as_dict(self) -> Dict[str, Any]:
        return asdict(self)


def find_steps(t: Sequence[float], setpoint_rpy: Sequence[Sequence[float]]) -> List[Step]:
    """The setpoint changes of a record whose setpoint (roll, pitch, yaw, rad) at time ``t`` (sorted) is
    ``setpoint_rpy``: each sample whose setpoint differs from the previous one's by more than
    :data:`MIN_STEP_DEG` on some axis (angles compared the short way round)."""
    times = np.asarray(t, dtype=float)
    setpoints = np.asarray(setpoint_rpy, dtype=float).reshape(times.size, 3)
    change = np.abs(np.angle(np.exp(1j * np.diff(setpoints, axis=0))))
    steps = []
    for k in np.flatnonzero(np.any(change > math.radians(MIN_STEP_DEG), axis=1)):
        steps.append(Step(float(times[k + 1]), tuple(float(v) for v in setpoints[k]),  # type: ignore[arg-type]
                          tuple(float(v) for v in setpoints[k + 1])))
    return steps


def response_ends(steps: Sequence[Step], stops: Sequence[float], end: float) -> List[Optional[float]]:
    """Where each step's response ends when the controller stopped acting (disarmed, or holding its safe pose) at
    the times ``stops``: at the next step, the first stop after the step, or ``end``, whichever is first; None for
    a step with a stop in the :data:`HOLD_CHECK` s before it (or at it), whose tilt was not held by the controller
    and whose response is not the test's."""
    stop_times = np.sort(np.asarray(stops, dtype=float))
    ends: List[Optional[float]] = []
    for k, step in enumerate(steps):
        first_before = int(np.searchsorted(stop_times, step.time - HOLD_CHECK, side="left"))
        if first_before < stop_times.size and stop_times[first_before] <= step.time:
            ends.append(None)
            continue
        after = int(np.searchsorted(stop_times, step.time, side="right"))
        candidates = [end] + ([steps[k + 1].time] if k + 1 < len(steps) else [])
        candidates += [float(stop_times[after])] if after < stop_times.size else []
        ends.append(min(candidates))
    return ends


def step_response(t: Sequence[float], rpy: Sequence[Sequence[float]], step: Step,
                  end: Optional[float] = None) -> StepResponse:
    """The response to ``step`` of a record of attitudes ``rpy`` (rad, REP 103) at times ``t`` (sorted),
    from the step to ``end`` (default the record's end); ValueError if fewer than two samples lie there."""
    times = np.asarray(t, dtype=float)
    angles = np.asarray(rpy, dtype=float).reshape(times.size, 3)[:, step.axis]
    end = times[-1] if end is None else end
    after = (times >= step.time) & (times <= end)
    if np.count_nonzero(after) < 2:
        raise ValueError("step at %.2f s: fewer than two attitude samples follow it" % step.time)
    target = step.after[step.axis]
    error = np.angle(np.exp(1j * (angles[after] - target)))
    stretch = times[after] - step.time
    smooth = moving_average_centered(error, stretch)
    band, fine = math.radians(SETTLING_BAND_DEG), math.radians(FINE_BAND_DEG)
    direction = math.copysign(1.0, target - step.before[step.axis])
    before = (times < step.time) & (times >= step.time - HOLD_CHECK)
    held = None
    if np.any(before):
        held = math.degrees(float(np.mean(np.angle(np.exp(1j * (angles[before] - step.before[step.axis]))))))
    return StepResponse(
        axis=AXES[step.axis], before_deg=math.degrees(step.before[step.axis]), after_deg=math.degrees(target),
        towards_upright=step.towards_upright, settle_6=settling_time(stretch, smooth, band),
        settle_2=settling_time(stretch, smooth, fine),
        overshoot_deg=max(0.0, math.degrees(float(np.max(direction * smooth)))), held_error_deg=held,
        duration=float(stretch[-1]))


def judged(response: StepResponse) -> bool:
    """Whether a response runs long enough to be judged: at least the settling hold (30 s), without which nothing
    settles by the paper's definition and two responses would "agree" by neither settling (a response a stop of
    the controller cut short)."""
    return response.duration >= SETTLING_HOLD


def agrees(model: Optional[float], robot: Optional[float], factor: float = AGREEMENT_FACTOR) -> bool:
    """Whether a model's settling time agrees with the robot's: both settle within ``factor`` of each other,
    or neither settles."""
    if model is None or robot is None:
        return model is None and robot is None
    ratio = max(model, TIME_FLOOR) / max(robot, TIME_FLOOR)
    return 1.0 / factor <= ratio <= factor
