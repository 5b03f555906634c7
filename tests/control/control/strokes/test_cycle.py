"""Tests of quadruped_control.control.strokes.cycle, the stroke cycle both the robot's StrokeCycle and the
batched controller run (their agreement: tests/control/sim/test_batch.py)."""
import numpy as np

from quadruped_control.control.strokes.cycle import (LegSolution, PairSolutions, new_cycle_state, path_nearly_full,
                                                     power_step, power_targets, record_point, recovery_step,
                                                     recovery_targets, start_power, start_recovery,
                                                     wait_at_start)

NOMINAL = np.array([[0.1, 0.1, -0.1], [0.1, -0.1, -0.1], [-0.1, 0.1, -0.1], [-0.1, -0.1, -0.1]])
JOINTS = np.array([[1.0, 2.0, 0.0]] * 4)
LEGS = np.array([[0, 2], [1, 3]], dtype=np.int64)


def _solved(targets):
    """An IK that reaches every target, with joints (x, y, z) (a stand-in: the cycle only stores them)."""
    return PairSolutions(*(LegSolution(True, t.x, t.y, t.z) for t in (targets.first, targets.second)))


def test_start_up_first_pair_waits_half_a_recovery_second_starts_power_at_once():
    state = new_cycle_state(2, 8, NOMINAL, JOINTS)
    for i in range(2):
        wait_at_start(state, i, 0, LEGS, 0.75)
        wait_at_start(state, i, 1, LEGS, 0.0)
    targets = recovery_targets(state, 0, 1, LEGS, 0.01)
    assert not targets.first.moves and not targets.second.moves
    assert recovery_step(state, 0, 1, LEGS, targets, _solved(targets))  # over: start the power phase
    targets = recovery_targets(state, 0, 0, LEGS, 0.01)
    assert not recovery_step(state, 0, 0, LEGS, targets, _solved(targets))
    np.testing.assert_array_equal(state.positions[0], NOMINAL)


def test_power_integrates_the_latched_command_records_and_ends_at_the_boundary():
    state = new_cycle_state(1, 8, NOMINAL, JOINTS)
    start_power(state, 0, 1, LEGS, 0.5, (0.0, 0.0, -1.0), (float("nan"), 0.0, 0.0))
    np.testing.assert_array_equal(state.velocities[0, 3], 0.0)  # non-finite: no stroke
    targets = power_targets(state, 0, 1, LEGS, 0.01)
    assert targets.first.moves and not targets.second.moves
    assert targets.first.z == NOMINAL[1, 2] + 0.01 * -1.0  # eq. (foot_integration)
    power_step(state, 0, 1, LEGS, 0.01, 1.5, targets, _solved(targets))
    assert state.power[0, 1] and state.path_count[0, 1] == 2 and state.path_count[0, 3] == 1
    np.testing.assert_array_equal(state.positions[0, 1], (targets.first.x, targets.first.y, targets.first.z))
    targets = power_targets(state, 0, 1, LEGS, 0.01)
    unreachable = PairSolutions(LegSolution(False, 0.0, 0.0, 0.0), LegSolution(False, 0.0, 0.0, 0.0))
    kept = state.positions[0, 1].copy()
    power_step(state, 0, 1, LEGS, 0.01, 1.5, targets, unreachable)
    assert not state.power[0, 1] and state.t_move[0, 1] == 1.5  # workspace boundary: recovery
    np.testing.assert_array_equal(state.positions[0, 1], kept)
    np.testing.assert_array_equal(state.velocities[0], 0.0)


def test_recovery_falls_back_to_the_nearest_recorded_point_and_counts_it():
    state = new_cycle_state(1, 8, NOMINAL, JOINTS)
    start_power(state, 0, 0, LEGS, 0.5, (0.0, 0.0, -1.0), (0.0, 0.0, -1.0))
    for _ in range(3):
        targets = power_targets(state, 0, 0, LEGS, 0.01)
        power_step(state, 0, 0, LEGS, 0.01, 1.0, targets, _solved(targets))
    targets = power_targets(state, 0, 0, LEGS, 0.0)  # no motion: no IK asked, no boundary
    assert not targets.first.moves and not targets.second.moves
    power_step(state, 0, 0, LEGS, 1e-12, 1.0, targets,
               PairSolutions(LegSolution(False, 0.0, 0.0, 0.0), LegSolution(False, 0.0, 0.0, 0.0)))
    assert state.power[0, 0]
    start_recovery(state, 0, 0, LEGS, 1.0)
    targets = recovery_targets(state, 0, 0, LEGS, 0.3)
    assert targets.first.moves
    recovery_step(state, 0, 0, LEGS, targets, PairSolutions(LegSolution(False, 0.0, 0.0, 0.0),
                                                            _solved(targets).second))
    assert state.ik_fallbacks[0] == 1
    assert tuple(state.positions[0, 0]) in {tuple(p) for p in state.path_points[0, 0, :4]}
    np.testing.assert_array_equal(state.positions[0, 2], (targets.second.x, targets.second.y, targets.second.z))


def test_a_full_record_is_reported():
    state = new_cycle_state(1, 2, NOMINAL, JOINTS)
    record_point(state, 0, 0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert state.path_count[0, 0] == 2 and not state.overflowed[0] and path_nearly_full(state, 0, 0, LEGS)
    record_point(state, 0, 0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # the same point: not stored
    assert not state.overflowed[0]
    record_point(state, 0, 0, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert state.overflowed[0] and state.path_count[0, 0] == 2
