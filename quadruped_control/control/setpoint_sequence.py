"""Attitude setpoints held in turn: a test protocol the robot runs by itself, as the maneuver node publishes it
and the offline studies simulate it (pure Python).

A sequence is a tuple of :class:`SetpointHold`: a setpoint (roll, pitch, yaw in degrees, REP 103 Z-Y-X) held for
so many seconds, from the first to the last. :data:`PROTOCOLS` names the ones the project uses:

- ``step_test`` (:data:`STEP_TEST`): the setpoint step test of docs/identification.md ("The step test as a
  study"): roll 45 deg held 120 s, then 33, 45, 57 and 45 deg for 90 s each (12 deg towards upright and away
  from it, as after an overshoot), level for 120 s, and the same in pitch; 18 minutes in all.
  ``python -m quadruped_control.studies.step_test RUN.bag`` reads its bag.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Sequence, Tuple

from quadruped_common.config import ParameterError

__all__ = ["MAX_ANGLE_DEG", "PROTOCOLS", "STEP_TEST", "SetpointHold", "command_sequence", "parse_sequence",
           "total_seconds"]

#: No setpoint angle beyond this (deg): an angle past +-180 is a typo, not an attitude.
MAX_ANGLE_DEG = 180.0


@dataclass(frozen=True)
class SetpointHold:
    """A setpoint (roll, pitch, yaw, deg) held for ``seconds``."""

    rpy_deg: Tuple[float, float, float]
    seconds: float


def _holds(rows: Sequence[Tuple[float, float, float, float]]) -> Tuple[SetpointHold, ...]:
    return tuple(SetpointHold((float(r), float(p), float(y)), float(s)) for r, p, y, s in rows)


#: The setpoint step test (module docstring).
STEP_TEST: Tuple[SetpointHold, ...] = _holds((
    (45.0, 0.0, 0.0, 120.0), (33.0, 0.0, 0.0, 90.0), (45.0, 0.0, 0.0, 90.0), (57.0, 0.0, 0.0, 90.0),
    (45.0, 0.0, 0.0, 90.0), (0.0, 0.0, 0.0, 120.0),
    (0.0, 45.0, 0.0, 120.0), (0.0, 33.0, 0.0, 90.0), (0.0, 45.0, 0.0, 90.0), (0.0, 57.0, 0.0, 90.0),
    (0.0, 45.0, 0.0, 90.0)))

#: The named sequences (the maneuver node's ``~protocol``).
PROTOCOLS: Dict[str, Tuple[SetpointHold, ...]] = {"step_test": STEP_TEST}


def parse_sequence(value: Any) -> Tuple[SetpointHold, ...]:
    """A sequence from its parameter form, a list of ``[roll, pitch, yaw, seconds]`` (deg, s); ParameterError
    naming the row for an empty list, a row that is not four numbers, an angle not finite or beyond
    :data:`MAX_ANGLE_DEG`, or a time not finite and positive."""
    if not isinstance(value, (list, tuple)) or not value:
        raise ParameterError("sequence must be a non-empty list of [roll, pitch, yaw, seconds], got %r" % (value,))
    rows = []
    for k, row in enumerate(value):
        if (not isinstance(row, (list, tuple)) or len(row) != 4
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in row)):
            raise ParameterError("sequence row %d must be [roll, pitch, yaw, seconds] (numbers), got %r" % (k, row))
        roll, pitch, yaw, seconds = (float(v) for v in row)
        if not all(math.isfinite(a) and abs(a) <= MAX_ANGLE_DEG for a in (roll, pitch, yaw)):
            raise ParameterError("sequence row %d: angles must be finite degrees within +-%g, got %r"
                                 % (k, MAX_ANGLE_DEG, row))
        if not (math.isfinite(seconds) and seconds > 0.0):
            raise ParameterError("sequence row %d: the hold must be a positive number of seconds, got %r" % (k, row))
        rows.append((roll, pitch, yaw, seconds))
    return _holds(rows)


def command_sequence(protocol: str, sequence: Any, maneuver: Sequence[float],
                     duration: float) -> Tuple[SetpointHold, ...]:
    """What the maneuver node commands from its parameters: the named ``protocol`` (:data:`PROTOCOLS`), else the
    ``sequence`` (:func:`parse_sequence`), else the one ``maneuver`` setpoint (roll, pitch, yaw, deg) held
    ``duration`` s; ParameterError for an unknown protocol, both given, or a bad sequence, maneuver or
    duration."""
    if protocol and sequence:
        raise ParameterError("give ~protocol or ~sequence, not both")
    if protocol:
        if protocol not in PROTOCOLS:
            raise ParameterError("~protocol %r is not one of %s" % (protocol, ", ".join(sorted(PROTOCOLS))))
        return PROTOCOLS[protocol]
    if sequence:
        return parse_sequence(sequence)
    return parse_sequence([[float(v) for v in maneuver] + [float(duration)]])


def total_seconds(sequence: Sequence[SetpointHold]) -> float:
    """How long the whole sequence takes, s."""
    return float(sum(hold.seconds for hold in sequence))

