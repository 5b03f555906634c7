"""Stroke schemes: how the controller's torque becomes foot motion (:class:`StrokeScheme`).

- ``paper``: the paper's power/recovery cycle, unchanged (:class:`~quadruped_control.control.strokes.paper.StrokeCycle`),
  which runs :mod:`~quadruped_control.control.strokes.cycle`, the cycle the batched simulator runs too;
- ``coordinated``: phase-coordinated pairs, recovery to where the next stroke has range, durations from
  path length and servo speed (:class:`~quadruped_control.control.strokes.coordinated.CoordinatedStrokes`).

:func:`make_stroke_scheme` builds one by name; ``stroke.scheme`` in config/controller.yaml chooses it.
"""
from __future__ import annotations

from typing import Optional, Sequence

from quadruped_common.config import ParameterError
from quadruped_control.control.strokes.base import PHASE_HOLD, PHASE_POWER, PHASE_RECOVERY, StrokeScheme
from quadruped_control.control.strokes.coordinated import COORDINATED_PARAMS, CoordinatedParams, CoordinatedStrokes
from quadruped_control.control.strokes.paper import StrokeCycle
from quadruped_control.model.params import RobotParams

__all__ = ["COORDINATED_PARAMS", "PHASE_HOLD", "PHASE_POWER", "PHASE_RECOVERY", "SCHEMES", "CoordinatedParams",
           "CoordinatedStrokes", "StrokeCycle", "StrokeScheme", "make_stroke_scheme"]

#: Names of the stroke schemes, the first is the default.
SCHEMES = ("paper", "coordinated")


def make_stroke_scheme(name: str, robot: RobotParams, pairs: Sequence[Sequence[int]], t_rec: float,
                       t_pow_max: float, coordinated: Optional[CoordinatedParams] = None) -> StrokeScheme:
    """The stroke scheme ``name`` ('paper' or 'coordinated'); ParameterError for another name."""
    if name == "paper":
        return StrokeCycle(robot, pairs, t_rec, t_pow_max)
    if name == "coordinated":
        return CoordinatedStrokes(robot, pairs, t_rec, t_pow_max, coordinated)
    raise ParameterError("unknown stroke scheme %r (choose from %s)" % (name, ", ".join(SCHEMES)))
