"""Tests of quadruped_control.model.hydrodynamics: paw drag, its transmission, paw buoyancy, inertia-box drag.

The inertia-box body drag is checked against MuJoCo's own implementation of the same model.
"""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.config import ParameterError
from quadruped_common.robot import LEGS
from quadruped_common.so3 import exp_so3, rot_to_quat, rpy_to_rot
from quadruped_control.model import hydrodynamics as hd
from quadruped_control.model.kinematics import floating_base_jacobian, foot_position, joint_angles
from quadruped_control.model.params import load_robot_params

PARAMS = load_robot_params()

finite = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, allow_infinity=False)
vec3 = st.tuples(finite, finite, finite).map(np.array)


def nominal_joints():
    return np.array([joint_angles(PARAMS.nominal_foot_body(leg), leg, PARAMS) for leg in LEGS])


def nominal_feet():
    return np.array([PARAMS.nominal_foot_body(leg) for leg in LEGS])


def random_rotation(rng):
    return exp_so3(rng.uniform(-2.0, 2.0, 3))


# --------------------------------------------------------------------------------------------------
# Paw drag and leg wrench, eq. (drag), (force_leg), (torque_leg)
# --------------------------------------------------------------------------------------------------

def test_paw_drag_constant_is_half_rho_cd_area():
    area = math.pi * 0.0375 ** 2
    assert PARAMS.drag_constant == pytest.approx(0.5 * 1000.0 * 0.64 * area, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(vec3)
def test_paw_drag_opposes_velocity_with_quadratic_magnitude(v):
    force = hd.paw_drag_force(v, PARAMS)
    speed = float(np.linalg.norm(v))
    assert np.linalg.norm(force) == pytest.approx(PARAMS.drag_constant * speed ** 2, rel=1e-12, abs=1e-15)
    assert float(force @ v) <= 0.0
    np.testing.assert_allclose(np.cross(force, v), 0.0, atol=1e-12)


def test_paw_drag_vectorised_over_legs_matches_single_legs():
    rng = np.random.default_rng(1)
    velocities = rng.normal(size=(4, 3))
    stacked = hd.paw_drag_force(velocities, PARAMS)
    for row in range(4):
        np.testing.assert_allclose(stacked[row], hd.paw_drag_force(velocities[row], PARAMS), rtol=1e-15)


def test_leg_torque_is_r_cross_force_in_body_frame():
    rng = np.random.default_rng(2)
    for _ in range(20):
        R = random_rotation(rng)
        r = rng.uniform(-0.3, 0.3, 3)
        v = rng.normal(size=3)
        force, torque = hd.leg_wrench(v, r, R, PARAMS)
        np.testing.assert_allclose(force, -PARAMS.drag_constant * np.linalg.norm(v) * v, rtol=1e-13)
        np.testing.assert_allclose(torque, np.cross(r, R.T @ force), rtol=1e-12, atol=1e-15)


def test_leg_wrench_equals_virtual_work_with_floating_base_jacobian():
    """eq. (virtual_work): (F_i^W, tau_i^B) are the base rows of (J_P,i^W)^T F_D,i^W."""
    rng = np.random.default_rng(3)
    q = nominal_joints()
    for leg in LEGS:
        R = random_rotation(rng)
        u = rng.normal(size=9)
        jacobian = floating_base_jacobian(q[leg - 1], leg, R, PARAMS)
        v_foot = jacobian @ u
        force, torque = hd.leg_wrench(v_foot, foot_position(q[leg - 1], leg, PARAMS), R, PARAMS)
        generalized = jacobian.T @ hd.paw_drag_force(v_foot, PARAMS)
        np.testing.assert_allclose(force, generalized[0:3], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(torque, generalized[3:6], rtol=1e-12, atol=1e-15)


def test_leg_wrench_zero_when_foot_still():
    force, torque = hd.leg_wrench(np.zeros((4, 3)), nominal_feet(), rpy_to_rot(0.3, -0.2, 1.0), PARAMS)
    assert np.all(force == 0.0) and np.all(torque == 0.0)


def test_leg_wrench_rejects_bad_input():
    with pytest.raises(ValueError, match="non-finite"):
        hd.leg_wrench([np.nan, 0.0, 0.0], [0.1, 0.0, 0.0], np.eye(3), PARAMS)
    with pytest.raises(ValueError, match="shape"):
        hd.leg_wrench([1.0, 0.0], [0.1, 0.0, 0.0], np.eye(3), PARAMS)
    with pytest.raises(ValueError, match="does not match"):
        hd.leg_wrench(np.zeros((4, 3)), np.zeros(3), np.eye(3), PARAMS)
    with pytest.raises(ValueError, match="3x3"):
        hd.leg_wrench(np.zeros(3), np.zeros(3), np.eye(2), PARAMS)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 ** 32 - 1))
def test_paw_drag_wrench_fast_path_equals_summed_leg_wrench(seed):
    """The float fast path (body axes, all legs) against leg_wrench (world frame, per leg), with the foot
    velocities of eq. (fb_jac): v_e,i^W = v_B^W + R (omega x r_i + c_i)."""
    rng = np.random.default_rng(seed)
    R = random_rotation(rng)
    v = rng.uniform(-0.5, 0.5, 3)
    omega = rng.uniform(-2.0, 2.0, 3)
    feet = nominal_feet() + rng.normal(scale=0.02, size=(4, 3))
    joint_velocities = rng.uniform(-0.5, 0.5, (4, 3))  # c_i = J_P,i^B q_dot_i
    foot_velocities = v + (np.cross(omega, feet) + joint_velocities) @ R.T
    forces, torques = hd.leg_wrench(foot_velocities, feet, R, PARAMS)
    rows = np.hstack((feet, joint_velocities)).tolist()
    fast = hd.paw_drag_wrench_f(rows, PARAMS.drag_constant, *(R.T @ v).tolist(), *omega.tolist())
    np.testing.assert_allclose(fast[:3], R.T @ forces.sum(axis=0), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fast[3:], torques.sum(axis=0), rtol=1e-12, atol=1e-15)


def test_paw_drag_wrench_fast_path_zero_when_feet_still():
    rows = np.hstack((nominal_feet(), np.zeros((4, 3)))).tolist()
    assert hd.paw_drag_wrench_f(rows, PARAMS.drag_constant, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == (0.0,) * 6


# --------------------------------------------------------------------------------------------------
# Paw buoyancy, eq. (buoy_force), (buoy_torque)
# --------------------------------------------------------------------------------------------------

def test_paw_buoyancy_force_is_sum_of_paws():
    force, _ = hd.paw_buoyancy(nominal_feet(), rpy_to_rot(0.4, 0.1, -0.7), PARAMS)
    expected = 4.0 * PARAMS.gravity * (PARAMS.rho * PARAMS.paw_volume - PARAMS.paw_mass)
    np.testing.assert_allclose(force, [0.0, 0.0, expected], rtol=1e-14)


def test_paw_buoyancy_torque_zero_for_symmetric_feet_upright():
    feet = nominal_feet()
    # The configured leg origins are mirror-symmetric about the x_B z_B and y_B z_B planes.
    np.testing.assert_allclose(feet[:, :2].sum(axis=0), 0.0, atol=1e-15)
    for yaw in (0.0, 0.8, -2.5):
        _, torque = hd.paw_buoyancy(feet, rpy_to_rot(0.0, 0.0, yaw), PARAMS)
        np.testing.assert_allclose(torque, 0.0, atol=1e-15)


def test_paw_buoyancy_torque_per_paw_when_tilted():
    rng = np.random.default_rng(4)
    feet = nominal_feet() + rng.normal(scale=0.02, size=(4, 3))
    R = rpy_to_rot(0.5, -0.3, 0.2)
    paw_force = np.array([0.0, 0.0, PARAMS.paw_net_buoyancy])
    expected = sum(np.cross(r, R.T @ paw_force) for r in feet)
    _, torque = hd.paw_buoyancy(feet, R, PARAMS)
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-16)
    # Heavy paws (negative net buoyancy) below the centre of mass pull a rolled body back upright.
    _, torque_roll = hd.paw_buoyancy(nominal_feet(), rpy_to_rot(0.3, 0.0, 0.0), PARAMS)
    assert PARAMS.paw_net_buoyancy < 0.0 and torque_roll[0] < 0.0


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 32 - 1))
def test_paw_buoyancy_fast_path_equals_paw_buoyancy(seed):
    """(F_z, U) of the float fast path: F_buoyancy^W = (0, 0, F_z) and tau_buoyancy^B = U R^T z_hat."""
    rng = np.random.default_rng(seed)
    feet = nominal_feet() + rng.normal(scale=0.02, size=(4, 3))
    R = random_rotation(rng)
    force, torque = hd.paw_buoyancy(feet, R, PARAMS)
    rows = np.hstack((feet, rng.normal(size=(4, 3)))).tolist()  # the joint velocities play no part
    lift, up_torque = hd.paw_buoyancy_f(rows, PARAMS.paw_net_buoyancy)
    np.testing.assert_array_equal(force, [0.0, 0.0, lift])
    np.testing.assert_allclose(np.reshape(up_torque, (3, 3)) @ R[2, :], torque, rtol=1e-12, atol=1e-16)


def test_paw_buoyancy_rejects_single_vector():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        hd.paw_buoyancy(np.zeros(3), np.eye(3), PARAMS)


# --------------------------------------------------------------------------------------------------
# Inertia box and body drag, eq. (inertia_box), (quad), (visc)
# --------------------------------------------------------------------------------------------------

def test_inertia_box_reproduces_inertia():
    r = np.array(hd.inertia_box(PARAMS))
    m = PARAMS.mass
    box_inertia = m / 3.0 * np.array([r[1] ** 2 + r[2] ** 2, r[2] ** 2 + r[0] ** 2, r[0] ** 2 + r[1] ** 2])
    np.testing.assert_allclose(box_inertia, np.diag(PARAMS.inertia), rtol=1e-12)
    # The configured inertia is a uniform box of the paper's body dimensions.
    np.testing.assert_allclose(2.0 * r, PARAMS.body_dimensions, rtol=1e-3)


def test_inertia_box_rejects_non_diagonal_inertia():
    inertia = PARAMS.inertia.copy()
    inertia[0, 1] = inertia[1, 0] = 0.01
    with pytest.raises(ParameterError, match="diagonal"):
        hd.inertia_box(dataclasses.replace(PARAMS, inertia=inertia))


def test_body_drag_coefficients_written_out():
    r_x, r_y, r_z = hd.inertia_box(PARAMS)
    rho, beta = PARAMS.rho, PARAMS.beta
    r_eq = (r_x + r_y + r_z) / 3.0
    v = np.array([0.3, -0.2, 0.1])
    w = np.array([-0.5, 0.7, 0.2])
    force, torque = hd.body_drag(v, w, PARAMS)
    expected_force = [-2 * rho * r_y * r_z * abs(v[0]) * v[0] - 6 * beta * math.pi * r_eq * v[0],
                      -2 * rho * r_z * r_x * abs(v[1]) * v[1] - 6 * beta * math.pi * r_eq * v[1],
                      -2 * rho * r_x * r_y * abs(v[2]) * v[2] - 6 * beta * math.pi * r_eq * v[2]]
    c_visc = 8 * beta * math.pi * r_eq ** 3
    expected_torque = [-0.5 * rho * r_x * (r_y ** 4 + r_z ** 4) * abs(w[0]) * w[0] - c_visc * w[0],
                       -0.5 * rho * r_y * (r_z ** 4 + r_x ** 4) * abs(w[1]) * w[1] - c_visc * w[1],
                       -0.5 * rho * r_z * (r_x ** 4 + r_y ** 4) * abs(w[2]) * w[2] - c_visc * w[2]]
    np.testing.assert_allclose(force, expected_force, rtol=1e-13)
    np.testing.assert_allclose(torque, expected_torque, rtol=1e-13)


@settings(max_examples=80, deadline=None)
@given(vec3, vec3)
def test_body_drag_is_dissipative_and_odd(v, w):
    force, torque = hd.body_drag(v, w, PARAMS)
    assert float(v @ force) <= 0.0
    assert float(w @ torque) <= 0.0
    force_neg, torque_neg = hd.body_drag(-v, -w, PARAMS)
    np.testing.assert_allclose(force_neg, -force, rtol=1e-15, atol=0.0)
    np.testing.assert_allclose(torque_neg, -torque, rtol=1e-15, atol=0.0)


def test_body_drag_fast_path_is_the_coefficients_formula():
    """body_drag_f, the one implementation (body_drag wraps it), against the element-wise formula of
    BodyDragCoefficients' docstring."""
    coefficients = hd.body_drag_coefficients(PARAMS)
    rng = np.random.default_rng(6)
    for _ in range(20):
        v, w = rng.normal(size=3), rng.normal(scale=2.0, size=3)
        fast = hd.body_drag_f(coefficients.flat, *v.tolist(), *w.tolist())
        np.testing.assert_allclose(
            fast[:3], -coefficients.quad_force * np.abs(v) * v - coefficients.visc_force * v, rtol=1e-14, atol=0)
        np.testing.assert_allclose(
            fast[3:], -coefficients.quad_torque * np.abs(w) * w - coefficients.visc_torque * w, rtol=1e-14, atol=0)
        force, torque = hd.body_drag(v, w, PARAMS)
        assert force.tolist() == list(fast[:3]) and torque.tolist() == list(fast[3:])


def test_body_drag_zero_at_rest():
    force, torque = hd.body_drag(np.zeros(3), np.zeros(3), PARAMS)
    assert np.all(force == 0.0) and np.all(torque == 0.0)


def test_body_drag_rejects_bad_input():
    with pytest.raises(ValueError, match="non-finite"):
        hd.body_drag([0.0, np.inf, 0.0], np.zeros(3), PARAMS)
    with pytest.raises(ValueError, match="shape"):
        hd.body_drag(np.zeros((2, 3)), np.zeros(3), PARAMS)


MUJOCO_FREE_BODY = """
<mujoco>
  <compiler inertiafromgeom="false"/>
  <option density="{rho!r}" viscosity="{beta!r}" gravity="0 0 0" wind="0 0 0"/>
  <worldbody>
    <body name="torso">
      <freejoint/>
      <inertial pos="0 0 0" mass="{mass!r}" diaginertia="{ixx!r} {iyy!r} {izz!r}"/>
      <geom type="sphere" size="0.05" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize("inertia_diag", [None, (0.02, 0.05, 0.06)])
def test_body_drag_matches_mujoco_inertia_box_model(inertia_diag):
    mujoco = pytest.importorskip("mujoco")
    params = PARAMS if inertia_diag is None else dataclasses.replace(PARAMS, inertia=np.diag(inertia_diag))
    ixx, iyy, izz = np.diag(params.inertia)
    model = mujoco.MjModel.from_xml_string(MUJOCO_FREE_BODY.format(
        rho=params.rho, beta=params.beta, mass=params.mass, ixx=ixx, iyy=iyy, izz=izz))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(5)
    for trial in range(12):
        R = np.eye(3) if trial == 0 else random_rotation(rng)
        v_world = rng.uniform(-1.0, 1.0, 3)
        omega_body = rng.uniform(-3.0, 3.0, 3)
        x, y, z, w = rot_to_quat(R)
        data.qpos[:] = [0.1, -0.2, 0.3, w, x, y, z]  # MuJoCo quaternions are scalar-first
        # Free joint: linear velocity in the world frame, angular velocity in the body frame.
        data.qvel[:] = np.concatenate((v_world, omega_body))
        mujoco.mj_forward(model, data)
        np.testing.assert_allclose(data.xmat[1].reshape(3, 3), R, atol=1e-12)
        # Generalised free-joint force: world-frame force, body-frame torque about the CoM.
        mujoco_force_body = R.T @ data.qfrc_fluid[0:3]
        mujoco_torque_body = data.qfrc_fluid[3:6].copy()
        np.testing.assert_allclose(data.qfrc_passive, data.qfrc_fluid, rtol=1e-15)  # nothing else passive
        force, torque = hd.body_drag(R.T @ v_world, omega_body, params)
        assert np.linalg.norm(force - mujoco_force_body) <= 1e-9 * np.linalg.norm(mujoco_force_body)
        assert np.linalg.norm(torque - mujoco_torque_body) <= 1e-9 * np.linalg.norm(mujoco_torque_body)
