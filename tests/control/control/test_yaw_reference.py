"""The yaw reference of setpoints (relative, absolute, tilt): the pure functions, the controller's tilt-only law
and the supervisor's heading at arming (quadruped_control.control.yaw_reference)."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.so3 import attitude_error, exp_so3, geodesic_angle, quat_to_rot, rot_to_quat, rot_z, rpy_to_rot
from quadruped_common.vec3 import mat3
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import ParameterError, load_controller_config
from quadruped_control.control.supervisor import ControlSupervisor
from quadruped_control.control.yaw_reference import (YAW_REFERENCES, YawReference, heading, mode_of_frame,
                                                     tilt_setpoint, world_setpoint)
from quadruped_control.model.params import load_robot_params

ROBOT = load_robot_params()
CONFIG = load_controller_config(gain_set="simulation")
rotations = st.tuples(*[st.floats(-3.1, 3.1)] * 3).map(lambda w: exp_so3(np.array(w)))


def tilt(R_s, R):
    return np.array(tilt_setpoint(mat3(R_s.ravel()), mat3(R.ravel()))).reshape(3, 3)


@settings(max_examples=200)
@given(rotations, rotations)
def test_tilt_setpoint_keeps_the_tilt_and_leaves_no_error_about_the_vertical(R_s, R):
    R_d = tilt(R_s, R)
    assert np.allclose(R_d @ R_d.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R_d[2], R_s[2], atol=1e-15)  # the tilt: the world vertical in the desired body
    np.testing.assert_allclose(R_d, rot_z(heading(R_d @ R_s.T)) @ R_s, atol=1e-12)  # a turn about the vertical
    e_R = attitude_error(R_d, R)  # eq. (error), body frame
    assert abs(np.dot(R @ e_R, (0.0, 0.0, 1.0))) < 1e-9
    closest = min(geodesic_angle(rot_z(a) @ R_s, R) for a in np.linspace(-math.pi, math.pi, 721))
    assert geodesic_angle(R_d, R) <= closest + 1e-9


def test_tilt_setpoint_of_a_level_request_is_level_at_the_measured_heading():
    R = rpy_to_rot(0.3, 0.0, 1.2)
    np.testing.assert_allclose(tilt(np.eye(3), R), rot_z(1.2), atol=1e-12)
    np.testing.assert_allclose(tilt(rpy_to_rot(0.5, 0.0, -2.0), R), rpy_to_rot(0.5, 0.0, 1.2), atol=1e-12)


def test_world_setpoint_of_each_mode():
    R_s = rpy_to_rot(0.5, 0.1, 0.2)
    psi_0 = math.radians(70.0)
    absolute = world_setpoint(R_s, "absolute", psi_0)
    assert absolute.R_d is R_s and not absolute.yaw_free
    relative = world_setpoint(R_s, "relative", psi_0)
    np.testing.assert_allclose(relative.R_d, rpy_to_rot(0.5, 0.1, 0.2 + psi_0), atol=1e-12)
    assert not relative.yaw_free
    assert world_setpoint(R_s, "relative", None).R_d is R_s  # not armed yet: read as absolute
    assert world_setpoint(R_s, "tilt", psi_0) == (R_s, True)


def test_modes_defaults_and_frames():
    assert YAW_REFERENCES[0] == "relative" == CONFIG.yaw_reference  # the robot's default (config/controller.yaml)
    assert load_controller_config().replace(yaw_reference="tilt").yaw_reference == "tilt"
    with pytest.raises(ParameterError):
        CONFIG.replace(yaw_reference="north")
    reference = YawReference("tilt")
    assert (reference.default, reference.mode, reference.psi_0) == ("tilt", "absolute", None)
    assert reference.resolve(None) == "tilt" and reference.resolve("absolute") == "absolute"
    with pytest.raises(ValueError):
        reference.resolve("magnetic")
    assert [mode_of_frame(f) for f in ("", " ", "relative", "/absolute", "tilt")] == \
        [None, None, "relative", "absolute", "tilt"]
    with pytest.raises(ValueError, match="relative, absolute, tilt"):
        mode_of_frame("odom")
    assert heading(rpy_to_rot(0.2, -0.3, 1.1)) == pytest.approx(1.1)


# ---------------------------------------------------------------- the controller's tilt-only law

def test_tilt_only_law_demands_no_torque_about_the_vertical():
    """Spinning about the vertical while tilted and far from the setpoint: the D term, the gyroscopic feedforward
    and a yaw error would all ask for yaw torque; yaw_free asks for none, also when it saturates."""
    controller = AttitudeController(ROBOT, CONFIG.replace(tau_max=0.3))
    controller.set_setpoint(rpy_to_rot(0.8, -0.3, 2.5), yaw_free=True)
    assert controller.yaw_free
    omega = np.array([0.1, -0.2, 0.6])
    saturated = False
    for k in range(300):
        R = rot_z(0.006 * k) @ rpy_to_rot(0.2, 0.1, -0.4)
        out = controller.step(0.01 * k, R, omega)
        vertical = R[2]  # the world vertical in the body frame
        state = out.state
        for torque in (state.tau_cmd, state.tau_sat, state.integral, state.tau_feedforward, state.e_R):
            assert abs(np.dot(torque, vertical)) < 1e-12
        np.testing.assert_allclose(state.R_d, tilt(rpy_to_rot(0.8, -0.3, 2.5), R), atol=1e-15)
        np.testing.assert_array_equal(controller.setpoint, state.R_d)
        saturated |= state.saturated
    assert saturated and np.linalg.norm(state.tau_sat) > 0.1  # it does act on the tilt
    controller.set_setpoint(np.eye(3))  # and back to the full law: a yaw torque again
    out = controller.step(3.0, rot_z(1.0), np.zeros(3))
    assert abs(np.dot(out.state.tau_cmd, (0.0, 0.0, 1.0))) > 0.1 and not controller.yaw_free


# ---------------------------------------------------------------- the supervisor: setpoints and arming

def supervisor(default="relative"):
    controller = AttitudeController(ROBOT, CONFIG.replace(yaw_reference=default))
    return ControlSupervisor(controller, lambda q: 1500.0 + 600.0 * np.asarray(q))


def feed(sup, R, t):
    sup.set_imu(rot_to_quat(R), (0.0, 0.0, 0.0), t)
    return sup.tick(t, t)


def test_relative_setpoint_is_turned_by_the_heading_captured_at_each_arm():
    sup = supervisor()
    roll = rpy_to_rot(math.radians(45.0), 0.0, 0.0)
    sup.set_setpoint(roll)
    assert sup.yaw.mode == "relative"
    np.testing.assert_array_equal(sup.controller.setpoint, roll)  # no heading yet
    feed(sup, rpy_to_rot(0.05, 0.0, math.radians(70.0)), 0.0)
    sup.arm(True)
    assert sup.yaw.psi_0 == pytest.approx(math.radians(70.0))
    target = rpy_to_rot(math.radians(45.0), 0.0, math.radians(70.0))
    np.testing.assert_allclose(sup.controller.setpoint, target, atol=1e-12)
    out = feed(sup, rpy_to_rot(0.0, 0.0, math.radians(80.0)), 0.01)  # the heading is not followed while armed
    np.testing.assert_allclose(out.output.state.R_d, target, atol=1e-12)  # controller_state.setpoint: world R_d
    sup.arm(False)
    feed(sup, rpy_to_rot(0.0, 0.0, math.radians(-20.0)), 0.02)
    sup.arm(True)  # taken again at the next arm
    np.testing.assert_allclose(sup.controller.setpoint, rpy_to_rot(math.radians(45.0), 0.0, math.radians(-20.0)),
                               atol=1e-12)
    sup.set_setpoint(rpy_to_rot(0.0, 0.0, math.radians(10.0)))  # armed: a new setpoint from the same heading
    np.testing.assert_allclose(sup.controller.setpoint, rot_z(math.radians(-10.0)), atol=1e-12)


def test_armed_without_an_imu_sample_takes_the_heading_from_the_first_step():
    sup = supervisor()
    sup.set_setpoint(np.eye(3))
    sup.arm(True)
    assert sup.yaw.psi_0 is None
    out = feed(sup, rot_z(1.0), 0.0)
    assert sup.yaw.psi_0 == pytest.approx(1.0)
    np.testing.assert_allclose(out.output.state.R_d, rot_z(1.0), atol=1e-12)
    assert out.output.state.geodesic_error < 1e-9


def test_per_message_mode_overrides_the_default_and_a_refused_setpoint_changes_nothing():
    sup = supervisor("absolute")
    feed(sup, rot_z(0.5), 0.0)
    sup.arm(True)
    sup.set_setpoint(np.eye(3))
    np.testing.assert_array_equal(sup.controller.setpoint, np.eye(3))
    sup.set_setpoint(np.eye(3), "relative")
    np.testing.assert_allclose(sup.controller.setpoint, rot_z(0.5), atol=1e-12)
    for R, mode in ((np.eye(3), "north"), (2.0 * np.eye(3), "absolute")):
        with pytest.raises(ValueError):
            sup.set_setpoint(R, mode)
        assert sup.yaw.mode == "relative"
        np.testing.assert_allclose(sup.controller.setpoint, rot_z(0.5), atol=1e-12)
    sup.set_setpoint(rpy_to_rot(0.3, 0.0, 2.0), "tilt")
    out = feed(sup, rot_z(0.7), 0.01)
    assert sup.controller.yaw_free
    np.testing.assert_allclose(out.output.state.R_d, rpy_to_rot(0.3, 0.0, 0.7), atol=1e-12)


def test_the_tether_hold_holds_the_whole_attitude_the_robot_has():
    controller = AttitudeController(ROBOT, CONFIG)
    sup = ControlSupervisor(controller, lambda q: np.asarray(q), heartbeat_timeout=1.0, tether_action="hold")
    sup.set_heartbeat(0.0)
    feed(sup, rot_z(0.4), 0.0)
    sup.arm(True)
    sup.set_setpoint(rpy_to_rot(0.5, 0.0, 0.0), "tilt")
    R = rpy_to_rot(0.1, 0.2, 0.9)
    feed(sup, R, 2.0)
    assert sup.check_tether(2.0) == "hold"
    assert sup.yaw.mode == "absolute" and not controller.yaw_free
    np.testing.assert_allclose(controller.setpoint, R, atol=1e-12)


def test_absolute_setpoints_step_the_controller_as_before():
    """Bit for bit the outputs of a controller given the same world R_d directly (the behaviour before yaw
    references), from a heading far from the setpoint's."""
    R_d = rpy_to_rot(math.radians(45.0), 0.0, 0.0)
    bare = AttitudeController(ROBOT, CONFIG)
    bare.set_setpoint(R_d)
    sup = supervisor()
    sup.set_setpoint(R_d, "absolute")
    feed(sup, rot_z(math.radians(70.0)), 0.0)
    sup.arm(True)
    bare.reset()
    for k in range(1, 300):
        R = rpy_to_rot(0.002 * k, 0.0, math.radians(70.0) - 0.003 * k)
        omega = np.array([0.2, 0.0, -0.3])
        q = rot_to_quat(R)
        assert sup.set_imu(q, omega, 0.01 * k) is None
        mine = sup.tick(0.01 * k, 0.01 * k).output
        theirs = bare.step(0.01 * k, quat_to_rot(q / np.linalg.norm(q)), omega)
        np.testing.assert_array_equal(mine.joint_targets, theirs.joint_targets)
        np.testing.assert_array_equal(mine.state.tau_sat, theirs.state.tau_sat)
    assert abs(theirs.state.tau_sat[2]) > 0.01  # the yaw error is acted on
