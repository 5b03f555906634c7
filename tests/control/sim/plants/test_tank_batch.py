"""TankPlantBatch on its own: what it adds to the per-trial TankModel it runs (its set-up, its state across
attaches, the step it is asked for). The closed-loop agreement of the two engines is in tests/control/sim/
test_batch.py."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_common.config import ParameterError
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.rigid_body import RigidBodyState
from quadruped_control.sim.plants.tank import TankModel, TurnUnresolved
from quadruped_control.sim.plants.tank_params import TankParams
from quadruped_control.sim.plants.tank_batch import TankPlantBatch
from quadruped_control.sim.simulation import nominal_joint_angles

ROBOT = load_robot_params()
DT = 0.01
#: A rope that only twists (no hydrostatics, no drag): the body turns on the rope's torsion alone.
TWISTING = TankParams(hydrostatics=False, torso_added_mass=False, paw_added_mass=False, drag=False,
                      rope_torsion_stiffness=0.05)


def _states(n: int, omega_z: float = 0.0):
    p, v, w = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    w[:, 2] = omega_z
    return p, v, np.repeat(np.eye(3)[None], n, axis=0), w


def _legs(n: int):
    return np.repeat(nominal_joint_angles(ROBOT)[None], n, axis=0), np.zeros((n, 4, 3))


def test_attach_makes_every_trial_a_new_one_a_failed_trial_included() -> None:
    """A trial that failed is frozen until the batch is attached again: then it runs like the others."""
    batch = TankPlantBatch(ROBOT, [TWISTING, TWISTING])
    p, v, R, w = _states(2, 0.5)
    batch.attach(p, R)
    batch.failed[1] = True
    q, q_dot = _legs(2)
    batch.step(p, v, R, w, q, q_dot, DT)
    assert not np.array_equal(R[0], np.eye(3)) and np.array_equal(R[1], np.eye(3))  # trial 1 frozen
    p, v, R, w = _states(2, 0.5)
    batch.attach(p, R)
    assert not batch.failed.any()
    batch.step(p, v, R, w, q, q_dot, DT)
    np.testing.assert_array_equal(R[1], R[0])


def test_a_step_longer_than_a_trial_can_resolve_is_refused_by_name() -> None:
    """The control period (10 ms) is checked when the batch is built; a longer step is checked when asked
    for, and a trial whose damping RK4 cannot take at that step is named."""
    inertia_z = float(TankModel(ROBOT, TWISTING).body_mass_matrix[5, 5])
    damped = TWISTING.with_values(appendage_damping_linear=(0.0, 0.0, 0.5 * 2.5 * inertia_z / DT))
    batch = TankPlantBatch(ROBOT, [TWISTING, damped])
    p, v, R, w = _states(2, 0.1)
    batch.attach(p, R)
    q, q_dot = _legs(2)
    batch.step(p, v, R, w, q, q_dot, DT)
    with pytest.raises(ParameterError,
                       match=r"0.03 s step cannot resolve: appendage_damping.appendage_damping_linear\[2\]"):
        batch.step(p, v, R, w, q, q_dot, 3.0 * DT)


def test_the_batch_counts_the_ropes_turns_as_the_per_trial_plant_does_to_the_bit() -> None:
    """A body wound by its own yaw rate to 1.4 pi (252 deg) on a twisting rope, the tether winding round the
    tie too: the batch's states, step by step, are the per-trial plant's, past half a turn and back."""
    tank = TWISTING.with_values(hook_friction_arm=0.002, hook_friction_wrap=0.3, net_weight=1.0, hydrostatics=True)
    model = TankModel(ROBOT, tank)
    rate = 1.4 * math.pi * math.sqrt(0.05 / float(model.body_mass_matrix[5, 5]))
    batch = TankPlantBatch(ROBOT, [tank])
    p, v, R, w = _states(1, rate)
    batch.attach(p, R)
    state = RigidBodyState(omega=np.array([0.0, 0.0, rate]))
    model.attach(state)
    q, q_dot = _legs(1)
    largest = 0.0
    for _ in range(400):
        batch.step(p, v, R, w, q, q_dot, DT)
        state = model.step(state, q[0], q_dot[0], DT)
        largest = max(largest, model.twist)
        for mine, theirs in ((p[0], state.position), (v[0], state.velocity), (R[0], state.rotation),
                             (w[0], state.omega)):
            np.testing.assert_array_equal(mine, theirs)
        assert batch.constants["torsion"][0, 2] == model.twist
    assert largest > math.pi  # the rope was wound past half a turn
    assert not batch.failed.any()


def test_the_batch_carries_the_tethers_relaxed_tilt_as_the_per_trial_plant_does_to_the_bit() -> None:
    """A body released at a 25 deg roll and 10 deg pitch on the tank plant with a bent tether that relaxes in
    2 s, beside one without it: each trial's states, step by step, are its per-trial plant's, and so is the
    relaxed tilt the batch carries; attach relaxes it at the new attitude."""
    base = TankParams()
    tanks = [base.with_values(tether_stiffness=0.01, tether_relaxing_stiffness=0.08, tether_relaxation_time=2.0), base]
    batch = TankPlantBatch(ROBOT, tanks)
    models = [TankModel(ROBOT, tank) for tank in tanks]
    p, v, R, w = _states(2)
    start = rpy_to_rot(math.radians(25.0), math.radians(10.0), 0.0)
    batch.attach(p, R)
    for model in models:
        model.attach(RigidBodyState())
    R[:] = start
    states = [RigidBodyState(rotation=start) for _ in models]
    q, q_dot = _legs(2)
    for _ in range(300):
        batch.step(p, v, R, w, q, q_dot, DT)
        states = [model.step(state, q[i], q_dot[i], DT) for i, (model, state) in enumerate(zip(models, states))]
        for i, state in enumerate(states):
            for mine, theirs in ((p[i], state.position), (v[i], state.velocity), (R[i], state.rotation),
                                 (w[i], state.omega)):
                np.testing.assert_array_equal(mine, theirs)
        assert tuple(batch.constants["tether"][0, 3:]) == models[0].tether_relaxed
    assert np.linalg.norm(batch.constants["tether"][0, 3:]) > 1e-3  # relaxed towards the tilts it swung through
    assert tuple(batch.constants["tether"][1, 3:]) == (0.0, 0.0, 0.0) and not models[1].bends_tether
    assert not np.array_equal(R[0], R[1])  # the tether moved the body
    batch.attach(p, R)
    models[0].attach(RigidBodyState(position=p[0], rotation=R[0]))
    assert tuple(batch.constants["tether"][0, 3:]) == models[0].tether_relaxed != (0.0, 0.0, 0.0)
    assert not batch.failed.any()


#: A tie the 10 ms step resolves with the tether wound half a turn (presliding K dt^2 / I 0.41 there), not
#: with it wound a whole turn (exp(mu_w phi) 4.8 times stiffer: 1.95).
WOUND = TankParams(hook_friction_arm=0.05, hook_friction_angle=0.001, hook_friction_wrap=0.5)


def test_a_tether_wound_past_the_turn_its_tie_was_checked_for_is_refused_by_name() -> None:
    """The capstan law stiffens the tie as exp(mu_w |phi|) and the whole twist counts every turn: the check
    at construction covers half a turn; TankModel.check_turn covers a further turn when the plant reaches
    it, a quarter turn ahead. Turned by the states handed to it (0.3 rad a step), the per-trial plant and
    the batch refuse the set at the same step, naming the tie: the per-trial plant raises (a ParameterError
    that the closed loop reports as a failed step), the batch marks the trial failed with the same reason and
    steps the others on."""
    model = TankModel(ROBOT, WOUND)
    assert model.checked_turn == pytest.approx(math.pi)
    model.check_turn(0.9 * math.pi)  # covered: nothing to check
    with pytest.raises(ParameterError, match="presliding stiffness"):
        TankModel(ROBOT, WOUND).check_turn(2.0 * math.pi)
    q, q_dot = _legs(1)
    model = TankModel(ROBOT, WOUND)
    model.attach(RigidBodyState())
    with pytest.raises(TurnUnresolved, match="presliding stiffness") as raised:
        for k in range(1, 40):
            model.step(RigidBodyState(rotation=rpy_to_rot(0.0, 0.0, 0.3 * k)), q[0], q_dot[0], DT)
    assert isinstance(raised.value, ParameterError) and isinstance(raised.value, RuntimeError)
    refused = k
    batch = TankPlantBatch(ROBOT, [WOUND, TankParams()])
    q, q_dot = _legs(2)
    for k in range(1, 40):
        p, v, R, w = _states(2)
        R[:] = rpy_to_rot(0.0, 0.0, 0.3 * k)
        batch.step(p, v, R, w, q, q_dot, DT)
        if batch.failed[0]:
            break
    assert k == refused and 0.3 * refused > math.pi
    assert batch.failure_reasons == {0: str(raised.value)} and not batch.failed[1]
    batch.attach(p, R)
    assert not batch.failed.any() and batch.failure_reasons == {}


def test_the_batch_pushes_its_trials_with_their_own_tanks_disturbance_to_the_bit_and_again_after_attach() -> None:
    """Two tanks that are not still (their own seeds and correlation times) beside a still one, 25 s of legs
    held on the tank plant: the batch's states are each per-trial plant's, step by step, across the blocks
    the draws come in (1,024 steps each); the disturbance it holds is each plant's; attach starts each
    trial's disturbance again, so a second run repeats the first."""
    base = TankParams()
    tanks = [base.with_values(disturbance_torque_std=0.01, disturbance_correlation_time=3.0, disturbance_seed=7),
             base, base.with_values(disturbance_torque_std=0.004, disturbance_correlation_time=0.5,
                                    disturbance_seed=8)]
    batch = TankPlantBatch(ROBOT, tanks)
    q, q_dot = _legs(3)
    runs = []
    for _ in range(2):
        models = [TankModel(ROBOT, tank) for tank in tanks]
        p, v, R, w = _states(3)
        batch.attach(p, R)
        for model in models:
            model.attach(RigidBodyState())
        states = [RigidBodyState() for _ in models]
        for step in range(2500):
            batch.step(p, v, R, w, q, q_dot, DT)
            states = [model.step(state, q[i], q_dot[i], DT) for i, (model, state) in enumerate(zip(models, states))]
            if step % 97 == 0 or step in (1022, 1023, 1024, 2047, 2048):
                for i, state in enumerate(states):
                    for mine, theirs in ((p[i], state.position), (v[i], state.velocity), (R[i], state.rotation),
                                         (w[i], state.omega)):
                        np.testing.assert_array_equal(mine, theirs)
                    np.testing.assert_array_equal(batch.disturbance[i], models[i].disturbance)
        runs.append(R.copy())
    np.testing.assert_array_equal(runs[1], runs[0])
    assert np.array_equal(runs[0][1], np.eye(3))  # the still tank's body stays at rest upright
    angles = [math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(runs[0][i]) - 1.0) / 2.0)))) for i in range(3)]
    assert angles[0] > 1.0 and angles[2] > 0.1  # the disturbed bodies were pushed off their rest
    assert not batch.failed.any()
