"""The yaw references in closed loop: the robot's supervisor and controller stepped in lock-step with the paper's
plant (rate-limited servos, as on the simulated robot), a 45 degree roll step from a heading of 70 degrees."""
import math

import numpy as np
import pytest

from quadruped_common.so3 import rot_to_quat, rot_to_rpy, rpy_to_rot
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.control.supervisor import ControlSupervisor
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.servo_model import make_servo_model
from quadruped_control.sim.simulation import PlantSimulator

ROBOT = load_robot_params()
HEADING = math.radians(70.0)
ROLL = math.radians(45.0)


def roll_step(mode, seconds=30.0):
    """Level at heading 70 deg, armed after 1 s with the setpoint roll 45, pitch 0, yaw 0 in ``mode`` (None: the
    configuration's default); per 10 ms step the IMU sample of the plant's state, one supervisor tick, and the
    plant held at its joint targets. Returns the times, the attitudes (roll, pitch, yaw) and the tick outputs."""
    controller = AttitudeController(ROBOT, load_controller_config(gain_set="simulation"))
    supervisor = ControlSupervisor(controller, lambda q: 1500.0 + 600.0 * np.asarray(q))
    supervisor.set_setpoint(rpy_to_rot(ROLL, 0.0, 0.0), mode)
    plant = PlantSimulator(ROBOT, make_servo_model("rate-limited"), initial_rotation=rpy_to_rot(0.0, 0.0, HEADING))
    targets = plant.last_command
    times, rpy, outputs = [], [], []
    for k in range(int(round(seconds / 0.01))):
        t = 0.01 * k
        state = plant.state
        supervisor.set_imu(rot_to_quat(state.rotation), state.omega, t)
        if k == 100:
            assert supervisor.arm(True).startswith("armed")
        out = supervisor.tick(t, t)
        targets = targets if out.joint_targets is None else out.joint_targets
        plant.step(targets)
        times.append(t)
        rpy.append(rot_to_rpy(state.rotation))
        outputs.append(out)
    return np.array(times), np.array(rpy), outputs


def test_relative_roll_step_keeps_the_heading_it_had_at_arming():
    t, rpy, outputs = roll_step(None)  # relative: config/controller.yaml's default
    armed = t >= 1.0
    heading_error = np.degrees(np.abs(rpy[armed, 2] - HEADING))
    assert heading_error.max() < 5.0, "the heading left the one at arming by %.1f deg" % heading_error.max()
    late = t >= t[-1] - 5.0
    assert np.degrees(np.abs(rpy[late, 0].mean() - ROLL)) < 5.0  # the roll step was made
    np.testing.assert_allclose(outputs[-1].output.state.R_d, rpy_to_rot(ROLL, 0.0, HEADING), atol=1e-6)


def test_absolute_roll_step_turns_to_face_east_and_tilt_asks_no_yaw_torque():
    t, rpy, _ = roll_step("absolute", seconds=20.0)
    assert abs(math.degrees(rpy[-1, 2])) < 10.0  # yaw 0 in world ENU: the robot turned by some 70 degrees
    t, rpy, outputs = roll_step("tilt", seconds=20.0)
    armed = [out for out in outputs if out.armed]
    assert armed and all(abs(np.dot(out.output.state.tau_sat, rpy_to_rot(*angles)[2])) < 1e-12
                         for out, angles in zip(outputs, rpy) if out.armed)
    assert max(np.linalg.norm(out.output.state.tau_sat) for out in armed) > 1.0
    assert np.degrees(np.abs(rpy[t >= 15.0, 0].mean() - ROLL)) < 6.0


@pytest.mark.parametrize("mode", ["absolute", "relative"])
def test_heading_at_arming_is_the_imus(mode):
    _, rpy, outputs = roll_step(mode, seconds=1.5)
    yaw = math.degrees(rot_to_rpy(outputs[-1].output.state.R_d)[2])
    assert yaw == pytest.approx(0.0 if mode == "absolute" else 70.0, abs=1e-6)
