"""Setpoints held in turn (quadruped_control.control.setpoint_sequence): the maneuver node's parameters."""
from __future__ import annotations

import math

import pytest

from quadruped_common.config import ParameterError
from quadruped_control.control import setpoint_sequence as seq


def test_a_sequence_parses_from_its_parameter_form() -> None:
    parsed = seq.parse_sequence([[45, 0, 0, 120], [33.5, 0, -10, 90.0]])
    assert parsed == (seq.SetpointHold((45.0, 0.0, 0.0), 120.0), seq.SetpointHold((33.5, 0.0, -10.0), 90.0))
    assert seq.total_seconds(parsed) == 210.0


@pytest.mark.parametrize("value, message", [
    ([], "non-empty list"), ("45,0,0,120", "non-empty list"), (None, "non-empty list"),
    ([[45, 0, 0]], "row 0 must be"), ([[45, 0, 0, 120], [1, 2, 3, "x"]], "row 1 must be"),
    ([[45, 0, 0, True]], "row 0 must be"), ([[math.nan, 0, 0, 10]], "row 0: angles"),
    ([[0, 181, 0, 10]], "row 0: angles"), ([[0, 0, 0, 0]], "row 0: the hold"),
    ([[0, 0, 0, math.inf]], "row 0: the hold"), ([[0, 0, 0, -5]], "row 0: the hold")])
def test_a_bad_sequence_is_refused_naming_the_row(value, message) -> None:
    with pytest.raises(ParameterError, match=message):
        seq.parse_sequence(value)


def test_the_node_commands_a_protocol_a_sequence_or_its_one_maneuver() -> None:
    assert seq.command_sequence("step_test", [], (45.0, 0.0, 0.0), 120.0) == seq.STEP_TEST
    assert seq.command_sequence("", [[10, 0, 0, 5]], (45.0, 0.0, 0.0), 120.0) == (
        seq.SetpointHold((10.0, 0.0, 0.0), 5.0),)
    assert seq.command_sequence("", [], (45.0, 0.0, 0.0), 120.0) == (seq.SetpointHold((45.0, 0.0, 0.0), 120.0),)
    with pytest.raises(ParameterError, match="not one of step_test"):
        seq.command_sequence("steps", [], (45.0, 0.0, 0.0), 120.0)
    with pytest.raises(ParameterError, match="not both"):
        seq.command_sequence("step_test", [[10, 0, 0, 5]], (45.0, 0.0, 0.0), 120.0)
    with pytest.raises(ParameterError, match="the hold"):
        seq.command_sequence("", [], (45.0, 0.0, 0.0), 0.0)


def test_the_step_test_steps_one_tilt_axis_at_a_time_towards_upright_and_away_for_eighteen_minutes() -> None:
    previous = (0.0, 0.0, 0.0)
    steps = set()
    for hold in seq.STEP_TEST:
        changed = [axis for axis in range(3) if hold.rpy_deg[axis] != previous[axis]]
        assert len(changed) == 1 and changed[0] in (0, 1) and hold.seconds >= 90.0
        steps.add((changed[0], previous[changed[0]], hold.rpy_deg[changed[0]]))
        previous = hold.rpy_deg
    for axis in (0, 1):
        assert {(axis, 45.0, 33.0), (axis, 33.0, 45.0), (axis, 45.0, 57.0), (axis, 57.0, 45.0)} <= steps
    assert seq.total_seconds(seq.STEP_TEST) == 18 * 60.0
    assert seq.PROTOCOLS["step_test"] is seq.STEP_TEST
