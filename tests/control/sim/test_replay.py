"""The open-loop replay: a simulated run's joints replayed from its start give its attitude to the bit; each
(parameter set, window) trial is its own; a lead-in held to the record brings the unmeasured states (a free
body's drift) into a later window; the baseline of no motion; records and windows checked."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_common.so3 import rot_z, rpy_to_rot
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.batch import BatchSimulation, BatchTrial
from quadruped_control.sim.plants import load_tank_params
from quadruped_control.sim.replay import (Record, attitude_errors, joint_errors, replay, replay_servos, still_errors,
                                          window_starts)
from quadruped_control.studies import identify_bags as ib
from quadruped_control.studies.trial import TrialSpec, trial_setup

TANK = "config/tank_identified.yaml"


@pytest.fixture(scope="module")
def simulated():
    """(robot, tank, record, full states) of a 6 s roll manoeuvre on the sixth identified set, experiment
    gains and rate-limited servos: the closed loop the replay must reproduce."""
    spec = TrialSpec(label="replay", setpoint_rpy_deg=(45.0, 0.0, 0.0), initial_rpy_deg=(0.0, 0.0, 60.0),
                     duration=6.0, gains="experiment", servo_model="rate-limited", plant="tank", tank_yaml=TANK)
    setup = trial_setup(spec)
    trial = BatchTrial(config=setup.config, setpoint=rpy_to_rot(math.radians(45.0), 0.0, 0.0),
                       initial=rpy_to_rot(0.0, 0.0, math.radians(60.0)), servo_model="rate-limited",
                       servo_params=setup.servo_params, tank=setup.model.tank)
    result = BatchSimulation(setup.robot, [trial]).run(6.0, record_states=601)
    states = result.states
    commands = np.full_like(states["joints"][0], math.nan)
    commands[:-1] = states["targets"][0]  # the controller's targets, none after the last step
    record = Record(t=result.t, rotation=states["rotation"][0], omega=states["omega"][0], joints=states["joints"][0],
                    valid=np.ones(result.t.size, dtype=bool), dt=0.01, commands=commands)
    return setup.robot, setup.model.tank, record, setup.servo_params


def test_a_simulated_run_replays_to_the_bit_from_its_start(simulated) -> None:
    """The replay holds the joints as the closed loop did (midpoint, finite-difference rate), and the run
    starts at rest on a vertical rope as a window does: the same plant gives the same attitude."""
    robot, tank, record, _ = simulated
    result = replay(robot, [tank], record, [0], 600, every=1)
    assert not result.failed.any()
    np.testing.assert_array_equal(result.rotation[0, 0], record.rotation[1:601])
    assert attitude_errors(result, record).max() == 0.0


def test_every_parameter_set_and_window_is_its_own_trial(simulated) -> None:
    robot, tank, record, _ = simulated
    other = tank.with_values(appendage_damping_linear=(0.0, 0.0, 0.0))
    starts = window_starts(record, 200, 150)
    assert list(starts) == [0, 150, 300]
    both = replay(robot, [tank, other], record, starts, 200, every=20)
    assert both.rotation.shape == (2, 3, 10, 3, 3)
    for s, params in enumerate((tank, other)):
        for w, start in enumerate(starts):
            alone = replay(robot, [params], record, [start], 200, every=20)
            np.testing.assert_array_equal(both.rotation[s, w], alone.rotation[0, 0])
    errors = attitude_errors(both, record)
    assert errors[0, 0].max() == 0.0  # the truth from the run's own start
    # a later window starts with the unmeasured states at rest (still wakes, a vertical rope): a small
    # error for the truth, and far less than for the plant without its damping
    assert 0.0 < errors[0, 1:].max() < math.radians(1.0)
    assert errors[1].mean() > 5.0 * errors[0].mean()


def test_a_lead_in_from_the_runs_start_is_the_run_itself(simulated) -> None:
    """Held to a record of the same plant, the lead-in's attitude and body rate are the plant's own: the
    window after it is the run, to the bit."""
    robot, tank, record, _ = simulated
    result = replay(robot, [tank], record, [250], 300, every=1, lead=250)
    np.testing.assert_array_equal(result.rotation[0, 0], record.rotation[251:551])


def test_a_lead_in_brings_a_free_bodys_drift_into_the_window(tmp_path) -> None:
    """The paper's free body (no rope, no hydrostatics, no added mass) swims while it turns. A window that
    starts it at rest misses that drift, and the paws' drag then turns it wrongly: about 2.5 deg within 3 s
    for the truth itself. A lead-in of 3 s held to the record gives the body its drift back."""
    with open("config/tank.yaml") as stream:
        text = stream.read()
    for effect in ("suspension", "hydrostatics", "torso_added_mass", "paw_added_mass"):
        assert "  %s: true" % effect in text
        text = text.replace("  %s: true" % effect, "  %s: false" % effect)
    free = str(tmp_path / "free.yaml")
    with open(free, "w") as stream:
        stream.write(text)
    record = ib.simulated_record(free, (45.0, 0.0, 0.0), (0.0, 0.0, 60.0), 12.0)
    robot, tank = load_robot_params(None), load_tank_params(free)
    starts = window_starts(record, 300, 300, lead=500)
    assert list(starts) == [500, 800]
    at_rest = attitude_errors(replay(robot, [tank], record, starts, 300, 10), record)
    led_in = attitude_errors(replay(robot, [tank], record, starts, 300, 10, lead=300), record)
    assert at_rest.max(axis=2).min() > math.radians(1.5)
    assert np.all(led_in.max(axis=2) < 0.25 * at_rest.max(axis=2))


def test_the_servos_replay_to_the_bit_from_the_measured_joints(simulated) -> None:
    """The servo step of the closed loop, driven by the recorded targets from the recorded joints: the same
    joints, at every window (the servos have no state beyond their angles); slower servos miss them."""
    _, _, record, servo = simulated
    starts = window_starts(record, 100, 100, commanded=True)
    assert list(starts) == [0, 100, 200, 300, 400]  # 500 would need the last sample's command
    replayed = replay_servos(record, starts, 100, [servo.max_speed, servo.max_speed],
                             [servo.time_constant, 2.0 * servo.time_constant], every=10)
    assert replayed.shape == (2, 5, 10, 4, 3)
    index = starts[:, None] + 10 * np.arange(1, 11)[None, :]
    np.testing.assert_array_equal(replayed[0], record.joints[index])
    errors = joint_errors(replayed, record, starts, 10)
    assert errors[0].max() == 0.0 and errors[1].mean() > math.radians(0.1)


def test_the_servos_replay_with_a_dead_band_per_set(simulated) -> None:
    """A dead band of 0 is the replay without one, to the bit; 0.01 rad on a run without one misses the
    joints; a dead band per set or none."""
    _, _, record, servo = simulated
    starts = window_starts(record, 100, 100, commanded=True)
    speeds, lags = [servo.max_speed] * 2, [servo.time_constant] * 2
    banded = replay_servos(record, starts, 100, speeds, lags, every=10, dead_bands=[0.0, 0.01])
    np.testing.assert_array_equal(banded[0], replay_servos(record, starts, 100, speeds[:1], lags[:1], every=10)[0])
    assert joint_errors(banded, record, starts, 10)[1].mean() > math.radians(0.1)
    with pytest.raises(ValueError, match="dead band"):
        replay_servos(record, starts, 100, speeds, lags, dead_bands=[0.0])


def test_a_record_without_commands_has_no_servo_windows(simulated) -> None:
    _, _, record, servo = simulated
    bare = Record(t=record.t, rotation=record.rotation, omega=record.omega, joints=record.joints, valid=record.valid,
                  dt=record.dt)
    assert window_starts(bare, 100, 100, commanded=True).size == 0
    with pytest.raises(ValueError, match="no commands"):
        replay_servos(bare, [0], 100, [servo.max_speed], [servo.time_constant])


def test_the_still_baseline_is_the_turn_since_the_window_start() -> None:
    t = np.arange(301) * 0.01
    rotation = np.array([rot_z(0.2 * tk) for tk in t])  # 0.2 rad/s about z
    record = Record(t=t, rotation=rotation, omega=np.tile([0.0, 0.0, 0.2], (301, 1)),
                    joints=np.zeros((301, 4, 3)), valid=np.ones(301, dtype=bool), dt=0.01)
    errors = still_errors(record, [0, 100], 200, every=50)
    np.testing.assert_allclose(errors, [[0.1, 0.2, 0.3, 0.4]] * 2, atol=1e-12)


def test_a_failed_trial_counts_the_largest_error() -> None:
    """Joints that jump by 1e6 rad every step drive the plant's state to non-finite values: the trial fails,
    is frozen and scores pi."""
    robot = load_robot_params(None)
    joints = np.zeros((21, 4, 3))
    joints[1::2] = 1e6
    record = Record(t=np.arange(21) * 0.01, rotation=np.tile(np.eye(3), (21, 1, 1)), omega=np.zeros((21, 3)),
                    joints=joints, valid=np.ones(21, dtype=bool), dt=0.01)
    result = replay(robot, [load_tank_params(TANK)], record, [0], 20, every=10)
    assert result.failed.all()
    np.testing.assert_array_equal(attitude_errors(result, record), math.pi)


def test_windows_leave_out_invalid_samples() -> None:
    valid = np.ones(100, dtype=bool)
    valid[45] = False
    record = Record(t=np.arange(100) * 0.01, rotation=np.tile(np.eye(3), (100, 1, 1)), omega=np.zeros((100, 3)),
                    joints=np.zeros((100, 4, 3)), valid=valid, dt=0.01)
    assert list(window_starts(record, 20, 10)) == [0, 10, 20, 50, 60, 70]  # 30 and 40 would cross 45
    assert list(window_starts(record, 99, 1)) == []
    # a lead-in of 10 samples must be valid too, and the first window starts after it
    assert list(window_starts(record, 20, 10, lead=10)) == [10, 20, 60, 70]  # 30..50 would reach 45
    with pytest.raises(ValueError, match="lead"):
        window_starts(record, 20, 10, lead=-1)
    with pytest.raises(ValueError, match="stride"):
        window_starts(record, 0, 10)


def test_a_record_is_checked() -> None:
    t = np.arange(5) * 0.01
    good = dict(t=t, rotation=np.tile(np.eye(3), (5, 1, 1)), omega=np.zeros((5, 3)), joints=np.zeros((5, 4, 3)),
                valid=np.ones(5, dtype=bool), dt=0.01)
    Record(**good)
    with pytest.raises(ValueError, match="joints must have shape"):
        Record(**dict(good, joints=np.zeros((5, 12))))
    with pytest.raises(ValueError, match="uniform grid"):
        Record(**dict(good, t=np.array([0.0, 0.01, 0.02, 0.04, 0.05])))
    with pytest.raises(ValueError, match="positive time step"):
        Record(**dict(good, dt=float("nan")))
    nan = np.zeros((5, 3))
    nan[2, 0] = math.nan
    with pytest.raises(ValueError, match="not finite at a sample marked valid"):
        Record(**dict(good, omega=nan))
    invalid = np.ones(5, dtype=bool)
    invalid[2] = False
    Record(**dict(good, omega=nan, valid=invalid))  # an invalid sample's value is not used
    with pytest.raises(ValueError, match="past the record"):
        replay(load_robot_params(None), [load_tank_params(TANK)], Record(**good), [2], 3, every=1)
    with pytest.raises(ValueError, match="lead-in runs past the record"):
        replay(load_robot_params(None), [load_tank_params(TANK)], Record(**good), [1], 3, every=1, lead=2)
