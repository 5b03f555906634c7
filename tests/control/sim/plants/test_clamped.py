"""The tank plant with its body clamped (quadruped_control.sim.plants.clamped) and its held wrench."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_common.so3 import rpy_to_rot
from quadruped_control.control.allocation import estimate_body_torque
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.clamped import ClampedTank
from quadruped_control.sim.plants.rigid_body import RigidBodyState
from quadruped_control.sim.plants.tank import TankModel
from quadruped_control.sim.plants.tank_params import TankParams
from quadruped_control.sim.simulation import ClosedLoopSimulation, nominal_joint_angles


def test_the_held_wrench_of_moving_legs_is_the_papers_leg_torque() -> None:
    """With the body at rest and no wake, what the moving legs add to the held torque is the paws' drag,
    eq. (torque_leg) summed over the legs: the same physics as the controller's telemetry estimate."""
    robot = load_robot_params()
    model = TankModel(robot, TankParams())
    state = RigidBodyState(rotation=rpy_to_rot(0.2, -0.1, 0.3))
    model.attach(state)
    q = nominal_joint_angles(robot)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q_dot = rng.uniform(-4.0, 4.0, size=(4, 3))
        moving = model.held_wrench(state, q, q_dot)[3:6] - model.held_wrench(state, q, np.zeros((4, 3)))[3:6]
        np.testing.assert_allclose(moving, estimate_body_torque(q, q_dot, state.rotation, np.zeros(3), robot),
                                   rtol=1e-9, atol=1e-12)


def test_the_restoring_torque_is_the_held_wrench_with_the_legs_still() -> None:
    robot = load_robot_params()
    model = TankModel(robot, TankParams(center_of_buoyancy=(0.0, 0.0, 0.002)))
    R = rpy_to_rot(0.5, 0.0, 0.0)
    q = nominal_joint_angles(robot)
    restoring = model.restoring_torque(R, q)
    assert restoring[0] < 0.0  # back towards level
    np.testing.assert_array_equal(restoring, model.held_wrench(RigidBodyState(rotation=R), q, np.zeros((4, 3)))[3:6])


def test_the_clamp_holds_the_body_while_the_legs_stroke() -> None:
    robot = load_robot_params()
    clamp = ClampedTank(TankModel(robot, TankParams(paw_wake_fraction=0.5)))
    start = rpy_to_rot(0.0, 0.1, 0.0)
    sim = ClosedLoopSimulation(robot, load_controller_config(None, "experiment"), "rate-limited", initial_R=start,
                               setpoint_R=rpy_to_rot(math.radians(20.0), 0.1, 0.0), model=clamp)
    nominal = nominal_joint_angles(robot)
    moved = 0.0
    for _ in range(300):
        state, _ = sim.step()
        np.testing.assert_array_equal(state.rotation, start)
        assert not state.omega.any() and not state.velocity.any()
        moved = max(moved, float(np.abs(sim.plant.joint_positions - nominal).max()))
    assert moved > 0.1  # rad: the legs stroked
    assert len(clamp.torques) == 300 and all(math.isfinite(x) for row in clamp.torques for x in row)
    assert clamp.model.wake.any()  # the paws' wake built up against the clamped body
    # the strokes push towards the setpoint (+roll) on average once they run
    assert np.mean([row[0] for row in clamp.torques[100:]]) > 0.0


def test_a_clamp_must_be_attached_before_it_steps() -> None:
    robot = load_robot_params()
    clamp = ClampedTank(TankModel(robot, TankParams()))
    q = nominal_joint_angles(robot)
    with pytest.raises(RuntimeError, match="attach"):
        clamp.step_trusted(RigidBodyState(), q.tolist(), np.zeros((4, 3)).tolist(), 0.01)
    moving = RigidBodyState(velocity=np.array([0.1, 0.0, 0.0]), omega=np.array([0.0, 0.2, 0.0]))
    clamp.attach(moving)
    held = clamp.step_trusted(moving, q.tolist(), np.zeros((4, 3)).tolist(), 0.01)
    assert not held.velocity.any() and not held.omega.any()  # clamped at rest, whatever the state given
