"""The tank plant: added-mass closed forms, rope and hydrostatics, and passive physics of the robot hanging
in the tank (controller off, legs at the nominal pose)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from quadruped_common.config import ParameterError, config_path
from quadruped_common.so3 import exp_so3, rpy_to_rot
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants import TankModel, TankParams, load_tank_params, make_plant
from quadruped_control.sim.plants.added_mass import (ellipsoid_added_mass, ellipsoid_coefficients, kirchhoff_terms,
                                                 point_mass_matrix)
from quadruped_control.sim.plants.paper import FloatingBaseModel, RigidBodyState
from quadruped_control.sim.plants.tank import hydrostatic_wrench, torso_ellipsoid
from quadruped_control.sim.plants.tank_dynamics import rope_force, solve_mass
from quadruped_control.sim.simulation import ClosedLoopSimulation, PlantSimulator, nominal_joint_angles

ROBOT = load_robot_params()
TANK = load_tank_params()
OFF = TankParams(suspension=False, hydrostatics=False, torso_added_mass=False, paw_added_mass=False)
DT = 0.01


# ---- added mass: closed forms ----------------------------------------------------------------------

def test_sphere_coefficients_and_added_mass() -> None:
    assert ellipsoid_coefficients(0.1, 0.1, 0.1) == pytest.approx((2 / 3,) * 3, abs=1e-9)
    M = ellipsoid_added_mass(0.1, 0.1, 0.1, 1000.0)
    m_f = 1000.0 * 4 / 3 * math.pi * 0.1 ** 3
    np.testing.assert_allclose(np.diag(M), [m_f / 2] * 3 + [0.0] * 3, atol=1e-9)


@pytest.mark.parametrize("a, b", [(0.3, 0.1), (0.2, 0.15), (1.0, 0.1)])
def test_prolate_spheroid_matches_fossen_closed_form(a: float, b: float) -> None:
    """Fossen (2011) section 6.4.1: prolate spheroid, e = sqrt(1 - (b/a)^2)."""
    e = math.sqrt(1.0 - (b / a) ** 2)
    log = math.log((1 + e) / (1 - e))
    alpha = 2 * (1 - e * e) / e ** 3 * (0.5 * log - e)
    beta = 1 / e ** 2 - (1 - e * e) / (2 * e ** 3) * log
    assert ellipsoid_coefficients(a, b, b) == pytest.approx((alpha, beta, beta), rel=1e-8)
    m_f = 1000.0 * 4 / 3 * math.pi * a * b * b
    M = ellipsoid_added_mass(a, b, b, 1000.0)
    n_rdot = 0.2 * m_f * (b * b - a * a) ** 2 * (alpha - beta) / (2 * (b * b - a * a) + (b * b + a * a) * (beta - alpha))
    np.testing.assert_allclose(np.diag(M), [alpha / (2 - alpha) * m_f, beta / (2 - beta) * m_f,
                                            beta / (2 - beta) * m_f, 0.0, n_rdot, n_rdot], rtol=1e-8, atol=1e-12)
    assert sum(ellipsoid_coefficients(a, 0.7 * b, b)) == pytest.approx(2.0, rel=1e-9)


def test_bad_ellipsoid_input_is_rejected() -> None:
    with pytest.raises(ValueError):
        ellipsoid_coefficients(0.1, -0.1, 0.1)
    with pytest.raises(ValueError):
        ellipsoid_added_mass(0.1, 0.1, 0.1, 0.0)


def test_kirchhoff_terms_do_no_work_and_give_rigid_body_gyroscopics() -> None:
    rng = np.random.default_rng(3)
    M = ellipsoid_added_mass(0.3, 0.17, 0.08, 1000.0) + point_mass_matrix(0.1, [0.2, -0.1, -0.1])
    for _ in range(20):
        nu = rng.normal(size=6)
        assert float(nu @ kirchhoff_terms(M, nu)) == pytest.approx(0.0, abs=1e-10)
    rigid = np.diag([4.9] * 3 + [0.05, 0.15, 0.19])
    nu = rng.normal(size=6)
    v, w = nu[:3], nu[3:]
    np.testing.assert_allclose(kirchhoff_terms(rigid, nu),
                               np.concatenate((4.9 * np.cross(w, v), np.cross(w, rigid[3:, 3:] @ w))), atol=1e-12)


def test_torso_ellipsoid_displaces_the_robots_volume() -> None:
    a, b, c = torso_ellipsoid(ROBOT)
    assert 4 / 3 * math.pi * a * b * c == pytest.approx(ROBOT.mass / ROBOT.rho)
    assert a / b == pytest.approx(ROBOT.body_dimensions[0] / ROBOT.body_dimensions[1])


def test_body_accelerated_from_rest_by_its_net_weight() -> None:
    """Released at rest with no rope: the only force is the net weight, so a_z = -W_net / (m + A_33)."""
    neutral_paws = dataclasses.replace(ROBOT, paw_mass=ROBOT.rho * ROBOT.paw_volume)
    tank = TANK.with_values(suspension=False, paw_added_mass=False, center_of_buoyancy=(0.0, 0.0, 0.0))
    model = TankModel(neutral_paws, tank)
    q = nominal_joint_angles(neutral_paws)
    state = model.step(RigidBodyState(), q, np.zeros((4, 3)), 1e-4)
    a33 = model.torso_added_mass[2, 2]
    assert a33 > 1.0  # a flat ellipsoid has a large heave added mass
    assert state.velocity[2] / 1e-4 == pytest.approx(-tank.net_weight / (ROBOT.mass + a33), rel=1e-6)
    np.testing.assert_allclose(state.omega, 0.0, atol=1e-12)


def test_schur_mass_solve_matches_numpy() -> None:
    model = TankModel(ROBOT, TANK)
    rng = np.random.default_rng(0)
    for _ in range(5):
        feet = rng.normal(scale=0.2, size=(4, 3))
        g = rng.normal(size=6)
        solver = model._mass_solver(tuple(feet.sum(axis=0)), tuple((feet.T @ feet).ravel()))
        np.testing.assert_allclose(solve_mass(solver, *g), np.linalg.solve(model.mass_matrix(feet.tolist()), g),
                                   rtol=1e-10, atol=1e-12)


# ---- rope and hydrostatics ---------------------------------------------------------------------------

def test_rope_pulls_only_when_taut() -> None:
    anchor = (0.0, 0.0, 1.0)
    assert rope_force((0, 0, 0.6), (0, 0, 0), anchor, 0.5, 100.0, 10.0) == (0.0, 0.0, 0.0)  # slack
    assert rope_force((0, 0, 0.4), (0, 0, 0), anchor, 0.5, 100.0, 10.0) == pytest.approx((0, 0, 10.0))
    # moving up fast while taut: damping would push; a rope cannot
    assert rope_force((0, 0, 0.49), (0, 0, 5.0), anchor, 0.5, 100.0, 10.0) == (0.0, 0.0, 0.0)
    assert rope_force((0, 0, 0.4), (0, 0, -1.0), anchor, 0.5, 100.0, 10.0)[2] == pytest.approx(20.0)


def test_hydrostatic_wrench_rights_a_robot_with_buoyancy_above() -> None:
    force, torque = hydrostatic_wrench(rpy_to_rot(0.3, 0, 0), 48.0, 47.0, (0, 0, 0.01))
    np.testing.assert_allclose(force, [0, 0, -1.0])
    assert torque[0] == pytest.approx(-47.0 * 0.01 * math.sin(0.3))  # rolls back
    assert np.allclose(hydrostatic_wrench(np.eye(3), 48.0, 48.0, (0, 0, 0.01))[1], 0.0)


def test_tank_params_are_validated() -> None:
    with pytest.raises(ParameterError):
        TankParams(rope_length=0.0)
    with pytest.raises(ParameterError):
        TankParams(hook=(0.0, float("nan"), 0.0))
    with pytest.raises(ParameterError):
        load_tank_params(tree={"suspension": {}})


@pytest.mark.parametrize("edit, key", [
    (("suspension: true", "suspension: 1"), "effects.suspension"),           # a number is not a switch
    (("drag: true", "drag: 'no'"), "effects.drag"),                        # bool('no') would be True
    (("rope_length: 0.5", "rope_length: true"), "suspension.rope_length"),   # true is not 1
    (("rope_stiffness: 2000.0", "rope_stiffness: .nan"), "suspension.rope_stiffness"),
    (("net_weight: 1.0", "net_weight: 1.0e+300"), "hydrostatics.net_weight"),
    (("added_mass_scale: 1.0", "added_mass_scale: -1.0"), "added_mass.added_mass_scale"),
    (("hook: [0.0, 0.0, 0.077]", "hook: [0.0, 0.077]"), "suspension.hook"),
    (("paw_drag:", "paw_dragg:"), "paw_dragg"),                              # unknown key
])
def test_malformed_tank_yaml_is_refused_naming_file_and_key(tmp_path, edit, key) -> None:
    text = open(config_path("tank.yaml")).read()
    old, new = edit
    assert old in text, old
    path = tmp_path / "tank.yaml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ParameterError) as info:
        load_tank_params(str(path))
    assert str(path) in str(info.value) and key in str(info.value)
    with pytest.raises(ValueError):
        make_plant("ocean", ROBOT)


def test_all_effects_off_is_the_paper_model() -> None:
    rng = np.random.default_rng(1)
    q = nominal_joint_angles(ROBOT) + rng.normal(scale=0.05, size=(4, 3))
    q_dot = rng.normal(scale=2.0, size=(4, 3))
    state = RigidBodyState(velocity=np.array([0.1, -0.05, 0.02]), rotation=rpy_to_rot(0.3, -0.2, 1.0),
                           omega=np.array([0.4, -0.3, 0.2]))
    paper = FloatingBaseModel(ROBOT).step(state, q, q_dot, DT)
    tank = TankModel(ROBOT, OFF).step(state, q, q_dot, DT)
    np.testing.assert_allclose(tank.to_vector(), paper.to_vector(), rtol=0, atol=1e-12)


# ---- passive physics in the tank -----------------------------------------------------------------

def _hang(model: TankModel, roll_deg: float, seconds: float, robot=ROBOT):
    plant = PlantSimulator(robot, initial_rotation=rpy_to_rot(math.radians(roll_deg), 0, 0), model=model, dt=DT)
    q = nominal_joint_angles(robot).ravel()
    states = [plant.state]
    for _ in range(int(round(seconds / DT))):
        states.append(plant.step(q))
    return plant, states


def _roll(states) -> np.ndarray:
    return np.array([math.atan2(s.rotation[2, 1], s.rotation[2, 2]) for s in states])


def _reduced_roll_model(model: TankModel, robot=ROBOT):
    """Roll-swing prediction from the restoring torque and the total (rigid + added) inertia.

    Coordinates (y, theta): sideways position of the centre of mass and roll. The stiff rope holds the
    hook at its depth, so the centre of mass rises and falls with z = z_hook - h cos(theta) (h: hook
    height above it). Body-axes velocity nu = J(theta) (y', theta') with v^W = (0, y', h sin(theta)
    theta'); kinetic energy 1/2 nu^T M nu with M the total mass matrix (rigid + torso and paw added
    mass), so Lagrange's equations read

        M_q q'' + (dM_q/dtheta theta') q' - 1/2 (q'^T dM_q/dtheta q') e_theta + grad V = Q_drag,
        M_q = J^T M J,

    V: torso weight and buoyancy, paw net buoyancy and the rope's pendulum term T0 (y_hook - y_anchor)^2 / (2 L);
    Q_drag = J^T (drag wrench): the paper's paw and body drag (:mod:`quadruped_control.model.hydrodynamics`,
    the readable functions) for that motion."""
    from quadruped_control.model import hydrodynamics

    q = nominal_joint_angles(robot)
    feet = model.leg_input(q, np.zeros((4, 3))).foot_positions
    M = model.mass_matrix(feet.tolist())
    hydro = TankModel(robot, model.tank.with_values(suspension=False))
    h = float(model.hook[2])
    tension = model.static_rope_tension()
    length = model.tank.rope_length

    def jacobian(theta: float) -> np.ndarray:
        R = rpy_to_rot(theta, 0.0, 0.0)
        J = np.zeros((6, 2))
        J[:3, 0] = R.T @ [0.0, 1.0, 0.0]
        J[:3, 1] = R.T @ [0.0, 0.0, h * math.sin(theta)]
        J[3, 1] = 1.0
        return J

    def mass(theta: float) -> np.ndarray:
        J = jacobian(theta)
        return J.T @ M @ J

    def potential(y: float, theta: float) -> float:
        R = rpy_to_rot(theta, 0.0, 0.0)
        position = np.array([0.0, y, h - float(R[2, :] @ model.hook)])  # hook at its depth
        hook_y = y + float(R[1, :] @ model.hook) - float(model.anchor[1])  # the anchor is above the start
        return hydro.potential_energy(RigidBodyState(position=position, rotation=R), q) \
            + 0.5 * tension * hook_y ** 2 / length

    def gradient(y: float, theta: float) -> np.ndarray:
        e = 1e-6
        return np.array([(potential(y + e, theta) - potential(y - e, theta)) / (2 * e),
                         (potential(y, theta + e) - potential(y, theta - e)) / (2 * e)])

    def drag(theta: float, rates: np.ndarray) -> np.ndarray:
        if not model.tank.drag:
            return np.zeros(2)
        R = rpy_to_rot(theta, 0.0, 0.0)
        nu = jacobian(theta) @ rates
        v, omega = R @ nu[:3], nu[3:]
        feet_velocity = v + np.cross(omega, feet) @ R.T
        forces, torques = hydrodynamics.leg_wrench(feet_velocity, feet, R, robot)
        body_force, body_torque = hydrodynamics.body_drag(nu[:3], omega, robot)
        wrench = np.concatenate((R.T @ forces.sum(axis=0) + body_force, torques.sum(axis=0) + body_torque))
        return jacobian(theta).T @ wrench

    def rhs(_t, x):
        y, theta, rates = x[0], x[1], np.array(x[2:])
        e = 1e-6
        dM = (mass(theta + e) - mass(theta - e)) / (2 * e)
        force = drag(theta, rates) - gradient(y, theta) - dM @ rates * rates[1] \
            + np.array([0.0, 0.5 * float(rates @ dM @ rates)])
        return list(rates) + list(np.linalg.solve(mass(theta), force))
    return rhs, mass(0.0)


def _extrema(t: np.ndarray, x: np.ndarray):
    """Times and values of the local extrema of x (parabolic refinement)."""
    out = []
    for k in range(1, x.size - 1):
        if (x[k] - x[k - 1]) * (x[k + 1] - x[k]) < 0:
            a, b, c = x[k - 1], x[k], x[k + 1]
            d = a - 2 * b + c
            off = 0.5 * (a - c) / d if d != 0 else 0.0
            out.append((t[k] + off * (t[1] - t[0]), b - 0.25 * (a - c) * off))
    return out


def test_suspended_robot_swings_back_with_the_predicted_period_and_decay() -> None:
    model = TankModel(ROBOT, TANK)
    seconds = 12.0
    _, states = _hang(model, 30.0, seconds)
    t = np.arange(len(states)) * DT
    roll = _roll(states)
    rhs, mass = _reduced_roll_model(model)
    assert mass[1, 1] > ROBOT.inertia[0, 0] * 1.3  # added inertia counts
    ref = solve_ivp(rhs, (0, seconds), [0.0, math.radians(30.0), 0.0, 0.0], t_eval=t, rtol=1e-8, atol=1e-10)
    sim_ext, ref_ext = _extrema(t, roll), _extrema(t, ref.y[1])
    assert len(sim_ext) >= 3 and len(ref_ext) >= 3
    # period: twice the time between the first two extrema (after release)
    sim_period, ref_period = 2 * (sim_ext[1][0] - sim_ext[0][0]), 2 * (ref_ext[1][0] - ref_ext[0][0])
    assert sim_period == pytest.approx(ref_period, rel=0.05)
    # decay: the first overshoot and the next extremum
    for k in (0, 1):
        assert abs(sim_ext[k][1]) == pytest.approx(abs(ref_ext[k][1]), rel=0.05)
    assert abs(roll[-1]) < math.radians(5.0)


def test_buoyancy_equal_to_weight_at_the_same_point_gives_no_torque_and_a_slack_rope() -> None:
    robot = dataclasses.replace(ROBOT, paw_mass=ROBOT.rho * ROBOT.paw_volume)  # neutral paws
    model = TankModel(robot, TANK.with_values(net_weight=0.0, center_of_buoyancy=(0.0, 0.0, 0.0)))
    assert model.static_rope_tension() == 0.0
    _, states = _hang(model, 30.0, 5.0, robot)
    roll = _roll(states)
    assert np.max(np.abs(roll - math.radians(30.0))) < 1e-9
    for s in states:
        hook = s.position + s.rotation @ model.hook
        assert np.linalg.norm(model.anchor - hook) <= model.tank.rope_length + 1e-9  # never stretched


def test_energy_never_grows_with_drag_off() -> None:
    model = TankModel(ROBOT, TANK.with_values(drag=False, rope_damping=0.0))
    q = nominal_joint_angles(ROBOT)
    _, states = _hang(model, 30.0, 6.0)
    energy = np.array([model.kinetic_energy(s, q) + model.potential_energy(s, q) for s in states])
    swing = energy[0] - np.min([model.potential_energy(s, q) for s in states])  # energy in the swing
    assert swing > 0.01
    assert np.max(energy - energy[0]) < 1e-6 * swing  # never grows (beyond rounding)
    assert np.max(np.abs(energy - energy[0])) < 1e-5 * swing  # RK4 conserves it closely


def test_depth_stays_at_the_rope_length_in_closed_loop() -> None:
    config = load_controller_config(None, "experiment")
    model = TankModel(ROBOT, TANK)
    sim = ClosedLoopSimulation(ROBOT, config, "rate-limited", setpoint_R=rpy_to_rot(math.radians(45), 0, 0),
                               model=model)
    result = sim.run(20.0)
    hook_z = np.array([(p + R @ model.hook)[2] for p, R in zip(result.position, result.rotation)])
    assert np.max(np.abs(hook_z - hook_z[0])) < 0.03
    assert result.info["plant"] == "tank"
    assert np.ptp(result.rpy[:, 0]) > math.radians(10)  # it did move


def test_controller_off_holds_the_nominal_pose() -> None:
    config = load_controller_config(None, "experiment")
    sim = ClosedLoopSimulation(ROBOT, config, setpoint_R=rpy_to_rot(1.0, 0, 0), model=TankModel(ROBOT, TANK),
                               controller_enabled=False, initial_R=rpy_to_rot(0.2, 0, 0))
    result = sim.run(2.0)
    np.testing.assert_allclose(result.joint_targets, np.tile(nominal_joint_angles(ROBOT).ravel(), (201, 1)))
    assert result.info["controller"] == "off"
    assert abs(result.rpy[-1, 0]) < 0.2  # swung back towards level, not driven to the setpoint


def test_empty_optional_tank_section_means_defaults_but_a_wrong_type_is_refused(tmp_path) -> None:
    text = open(config_path("tank.yaml")).read()
    assert "  servo_speed_scale: 1.0" in text and "  servo_stall_torque: 0.0 " in text
    text = "\n".join(line for line in text.splitlines()
                     if not line.startswith(("  servo_stall_torque:", "  servo_lag_scale:", "  servo_dead_band:")))
    path = tmp_path / "tank.yaml"
    path.write_text(text.replace("  servo_speed_scale: 1.0", "", 1))          # 'servos:' left empty (null)
    assert load_tank_params(str(path)).servo_speed_scale == 1.0
    path.write_text(text.replace("  servo_speed_scale: 1.0", "", 1).replace("servos:", "servos: 3", 1))
    with pytest.raises(ParameterError, match="'servos' must be a mapping"):
        load_tank_params(str(path))


# ---- candidate effects of the identification (neutral by default) ----------------------------------

BARE = TankParams(suspension=False, hydrostatics=False, torso_added_mass=False, paw_added_mass=False, drag=False)


def _spin(model: TankModel, state: RigidBodyState, seconds: float) -> list:
    q = nominal_joint_angles(ROBOT)
    states = [state]
    for _ in range(int(round(seconds / DT))):
        states.append(model.step(states[-1], q, np.zeros((4, 3)), DT))
    return states


def test_candidate_effects_are_off_unless_configured() -> None:
    for params in (TankParams(), TANK):
        assert params.appendage_damping_linear == params.appendage_damping_quadratic == (0.0, 0.0, 0.0)
        assert params.rope_torsion_stiffness == params.rope_torsion_damping == 0.0
        assert params.rope_torsion_relaxing_stiffness == 0.0
        assert params.paw_wake_fraction == params.body_wake_fraction == 0.0
        assert params.block_mass == 0.0  # the anchor is fixed
        assert params.hook_friction_arm == 0.0


@pytest.mark.parametrize("linear, quadratic", [(0.02, 0.0), (0.0, 0.05), (0.0, 0.0)])
def test_appendage_damping_slows_a_spin_as_its_law_says(linear: float, quadratic: float) -> None:
    """A free body spinning about z (no other force): I w' = -(c + k |w|) w, whose solutions are
    w0 exp(-c t / I) (linear) and w0 / (1 + k w0 t / I) (quadratic); no damping keeps the spin."""
    model = TankModel(ROBOT, BARE.with_values(appendage_damping_linear=(0.0, 0.0, linear),
                                              appendage_damping_quadratic=(0.0, 0.0, quadratic)))
    w0, seconds, inertia = 2.0, 3.0, ROBOT.inertia[2, 2]
    end = _spin(model, RigidBodyState(omega=np.array([0.0, 0.0, w0])), seconds)[-1]
    expected = w0 * math.exp(-linear * seconds / inertia) / (1.0 + quadratic * w0 * seconds / inertia)
    assert end.omega[2] == pytest.approx(expected, rel=1e-6)
    assert np.allclose(end.omega[:2], 0.0, atol=1e-12)


def test_rope_twist_is_the_rotation_about_the_vertical() -> None:
    from quadruped_control.sim.plants.tank_dynamics import rope_twist
    flat = lambda R: np.asarray(R).ravel().tolist()  # noqa: E731
    for yaw in (-2.5, -0.3, 0.0, 0.7, 3.0):
        for tilt in (0.0, 0.4, -1.2):
            assert rope_twist(flat(rpy_to_rot(tilt, 0.0, yaw)), flat(np.eye(3))) == pytest.approx(yaw, abs=1e-12)
    R0 = rpy_to_rot(0.2, -0.1, 1.0)
    assert rope_twist(flat(rpy_to_rot(0.0, 0.0, 0.5) @ R0), flat(R0)) == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize("untwisted_rpy, rpy", [((0.0, 0.0, 0.0), (0.6, 0.0, 1.2)),
                                              ((0.2, -0.1, 1.0), (1.1, 0.7, -0.4)),
                                              ((0.0, 0.0, 0.0), (0.0, 0.0, 0.8)),
                                              ((0.3, 0.2, -2.0), (-1.3, 0.5, 2.2))])
def test_rope_torsion_is_the_twists_spring_and_damper_at_any_tilt(untwisted_rpy, rpy) -> None:
    """The torsion torque is -k_t theta times the twist's gradient (body axes: theta(R exp(d)) - theta(R) =
    g_B . d, by central differences), so the spring does no work round a closed path of attitudes even
    tilted, and its damper is -c_t theta_dot g with theta_dot = g_B . omega, which only takes energy out; a
    turn about the vertical alone is the torque about the world vertical."""
    from quadruped_control.sim.plants.tank_dynamics import rope_torsion_torque, rope_twist
    flat = lambda R: np.asarray(R).ravel().tolist()  # noqa: E731
    R0, R = rpy_to_rot(*untwisted_rpy), rpy_to_rot(*rpy) @ rpy_to_rot(*untwisted_rpy)
    gradient = np.array([(rope_twist(flat(R @ exp_so3(1e-6 * e)), flat(R0))
                          - rope_twist(flat(R @ exp_so3(-1e-6 * e)), flat(R0))) / 2e-6 for e in np.eye(3)])
    theta = rope_twist(flat(R), flat(R0))
    spring = np.array(rope_torsion_torque(flat(R), flat(R0), (0.0, 0.0, 0.0), 0.7, 0.0, 0.0, 0.0, 0.0))
    np.testing.assert_allclose(spring, -0.7 * theta * gradient, rtol=1e-7, atol=1e-9)
    omega = (0.3, -0.2, 0.5)
    damper = np.array(rope_torsion_torque(flat(R), flat(R0), omega, 0.0, 0.4, 0.0, 0.0, 0.0))
    np.testing.assert_allclose(damper, -0.4 * float(gradient @ omega) * gradient, rtol=1e-7, atol=1e-9)
    assert float(damper @ omega) <= 0.0
    if rpy[:2] == (0.0, 0.0) and untwisted_rpy == (0.0, 0.0, 0.0):  # about the vertical: along R^T z_hat
        np.testing.assert_allclose(spring, -0.7 * theta * R[2, :], rtol=1e-12)


@pytest.mark.parametrize("turn", [-7.0, -3.5, -0.4, 3.3, 5.0, 10.0])
def test_the_whole_twist_is_the_integral_of_the_turn_about_the_vertical(turn) -> None:
    """whole_twist carried over small steps: a body turned about the vertical by any angle, tilted all the
    while, holds that angle of twist (every turn counted, where rope_twist wraps to [-pi, pi]); a tilt and
    its return, with no turn, leave none."""
    from quadruped_control.sim.plants.tank_dynamics import rope_twist, whole_twist
    flat = lambda M: M.ravel().tolist()  # noqa: E731
    tilt = rpy_to_rot(0.3, 0.4, 0.0)
    R_ref, twist = flat(tilt), 0.0
    for k in range(1, 201):
        R = rpy_to_rot(0.0, 0.0, turn * k / 200.0) @ tilt
        twist, R_ref = whole_twist(flat(R), R_ref, twist), flat(R)
    assert twist == pytest.approx(turn, abs=1e-12)
    assert abs(rope_twist(R_ref, flat(tilt))) <= math.pi
    R_ref, twist = flat(np.eye(3)), 0.0
    for k in list(range(1, 101)) + list(range(99, -1, -1)):  # roll to 100 deg and back
        R = rpy_to_rot(math.radians(k), 0.0, 0.0)
        twist, R_ref = whole_twist(flat(R), R_ref, twist), flat(R)
    assert abs(twist) < 1e-12


@pytest.mark.parametrize("swing_deg", [0.0, 30.0, 90.0, 170.0])
def test_the_ropes_torsion_acts_about_the_world_vertical_at_any_tilt(swing_deg) -> None:
    """With the twist's reference at the current attitude (the plants' step start), the spring's torque is
    -k_t theta about the world vertical whatever the tilt: a rope is twisted by turns about itself, not by
    tilts. (From the attitude at attach instead, the gradient's horizontal part grows as tan(swing / 2), so
    a twisted rope pushed the tilt: at 170 deg of swing, with 11 times its torque.)"""
    from quadruped_control.sim.plants.tank_dynamics import rope_torsion_torque
    R = rpy_to_rot(math.radians(swing_deg), 0.0, 0.8)
    flat = R.ravel().tolist()
    world = R @ np.array(rope_torsion_torque(flat, flat, (0.0, 0.0, 0.0), 0.1, 0.0, 2.0, 0.0, 0.0))
    np.testing.assert_allclose(world, [0.0, 0.0, -0.2], atol=1e-12)
    level = np.eye(3).ravel().tolist()
    if swing_deg == 170.0:  # the earlier measure, from the level attitude the rope hung in
        torque = R @ np.array(rope_torsion_torque(flat, level, (0.0, 0.0, 0.0), 0.1, 0.0, 0.0, 0.0, 0.0))
        assert np.hypot(torque[0], torque[1]) == pytest.approx(0.1 * 0.8 * math.tan(math.radians(85.0)), rel=1e-9)


def test_a_body_that_rolls_over_on_a_twisted_rope_keeps_its_energy_and_counts_the_turn() -> None:
    """A body rolling at 3 rad/s on a rope wound 1.5 rad (hung at a heading 1.5 rad away), nothing but the
    rope acting (its damping off): it rolls far over, the rope unwinding it about the vertical, the energy
    (1/2 nu^T M nu + 1/2 k_t theta^2 + the rope's stretch) stays, and the carried twist is 1.5 rad plus the
    integral of the rate about the world vertical."""
    model = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_stiffness=0.1, rope_damping=0.0))
    model.attach(RigidBodyState(rotation=rpy_to_rot(0.0, 0.0, -1.5)))
    q = nominal_joint_angles(ROBOT)
    state = RigidBodyState(omega=np.array([3.0, 0.0, 0.0]))
    energy, swing, turned = [], [], 1.5
    for _ in range(150):
        start = state
        state = model.step(state, q, np.zeros((4, 3)), DT)
        energy.append(model.kinetic_energy(state, q) + model.potential_energy(state, q))
        swing.append(math.degrees(math.acos(max(-1.0, min(1.0, state.rotation[2, 2])))))
        # the integral of the rate about the world vertical, by the trapezoid rule
        turned += 0.5 * DT * float((start.rotation @ start.omega)[2] + (state.rotation @ state.omega)[2])
        assert model.twist == pytest.approx(turned, abs=1e-3)
    assert max(swing) > 150.0  # rolled far over
    assert np.ptp(energy) < 1e-4 * energy[0]
    assert model.twist < 0.5  # and the rope has turned the body back about the vertical


def test_a_rope_twisted_past_half_a_turn_turns_the_robot_back_and_keeps_the_energy() -> None:
    """Released at rest twist with a yaw rate that winds the rope to 1.4 pi (252 deg), nothing else acting:
    the spring's k_t theta^2 / 2 stops the body there and turns it back through zero a quarter period later
    (theta'' = -(k_t / I_zz) theta, linear in the whole twist), the energy kept. A twist read modulo a turn
    would flip the spring at 180 deg and throw the body on round."""
    k_t = 0.05
    model = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_stiffness=k_t))
    model.attach(RigidBodyState())
    largest = 1.4 * math.pi
    rate = largest * math.sqrt(k_t / ROBOT.inertia[2, 2])
    start = RigidBodyState(omega=np.array([0.0, 0.0, rate]))
    period = 2.0 * math.pi * math.sqrt(ROBOT.inertia[2, 2] / k_t)
    q = nominal_joint_angles(ROBOT)
    twists, energy, states = [], [], [start]
    for _ in range(int(round(0.5 * period / DT))):
        states.append(model.step(states[-1], q, np.zeros((4, 3)), DT))
        twists.append(model.twist)
        energy.append(model.kinetic_energy(states[-1], q) + model.potential_energy(states[-1], q))
    assert max(twists) == pytest.approx(largest, rel=1e-3)
    assert abs(twists[-1]) < 0.02 * largest  # back through the untwisted attitude half a period later
    assert np.ptp(energy) < 1e-6 * 0.5 * k_t * largest ** 2


def test_rope_torsion_turns_the_robot_back_with_its_period_and_keeps_the_energy() -> None:
    """Small twist, nothing else acting: theta'' = -(k_t / I_zz) theta, period 2 pi sqrt(I_zz / k_t);
    without torsion damping the energy (1/2 I w^2 + 1/2 k_t theta^2) stays."""
    k_t = 0.05
    model = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_stiffness=k_t))
    model.attach(RigidBodyState())
    start = RigidBodyState(rotation=rpy_to_rot(0.0, 0.0, math.radians(10.0)))
    period = 2.0 * math.pi * math.sqrt(ROBOT.inertia[2, 2] / k_t)
    states = _spin(model, start, 0.75 * period)
    yaw = np.array([math.atan2(s.rotation[1, 0], s.rotation[0, 0]) for s in states])
    crossing = np.flatnonzero(np.diff(np.sign(yaw)) != 0)[0]
    t_cross = DT * (crossing + yaw[crossing] / (yaw[crossing] - yaw[crossing + 1]))
    assert t_cross == pytest.approx(0.25 * period, rel=2e-3)
    assert np.min(yaw) == pytest.approx(-math.radians(10.0), rel=1e-3)  # half a period later: the other side
    q = nominal_joint_angles(ROBOT)
    energy = [model.kinetic_energy(s, q) + model.potential_energy(s, q) for s in states]
    assert np.ptp(energy) < 1e-7 * 0.5 * k_t * math.radians(10.0) ** 2  # of the twist's energy
    damped = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_stiffness=k_t, rope_torsion_damping=0.02))
    damped.attach(RigidBodyState())
    assert abs(math.atan2(*_spin(damped, start, 2.0 * period)[-1].rotation[[1, 0], 0])) < math.radians(5.0)


def test_the_relaxing_twist_is_a_spring_on_the_twist_less_its_relaxed_part() -> None:
    """The torsion's relaxing branch k_r against the relaxed twist s is the rope's spring of stiffness k_r on the
    whole twist less s, at any tilt; with k_r = 0 the torque is the two-branch torque, bit for bit."""
    from quadruped_control.sim.plants.tank_dynamics import rope_torsion_torque

    R = rpy_to_rot(0.4, -0.7, 1.1)
    R0 = (R @ exp_so3(np.array([0.01, -0.02, 0.03]))).ravel().tolist()
    flat, omega = R.ravel().tolist(), (0.2, -0.1, 0.4)
    for twist, relaxed in ((1.3, 0.4), (-2.0, 0.5), (0.0, -0.3)):
        relaxing = rope_torsion_torque(flat, R0, omega, 0.0, 0.0, twist, 0.07, relaxed)
        spring = rope_torsion_torque(flat, R0, omega, 0.07, 0.0, twist - relaxed, 0.0, 0.0)
        np.testing.assert_allclose(relaxing, spring, rtol=1e-12, atol=1e-15)
        assert rope_torsion_torque(flat, R0, omega, 0.03, 0.02, twist, 0.0, relaxed) == \
            rope_torsion_torque(flat, R0, omega, 0.03, 0.02, twist, 0.0, 0.0)


def test_the_relaxed_twist_follows_the_twist_exactly() -> None:
    """ds/dt = (theta - s) / tau_r with theta held: any number of steps of dt is one step of their sum."""
    from quadruped_control.sim.plants.tank_dynamics import twist_relaxation_update

    relaxed = 0.0
    for _ in range(250):
        relaxed = twist_relaxation_update(0.8, relaxed, 4.0, DT)
    assert relaxed == pytest.approx(0.8 * (1.0 - math.exp(-2.5 / 4.0)), rel=1e-12)
    assert twist_relaxation_update(0.8, 0.8, 4.0, DT) == 0.8


def test_a_held_turn_meets_the_relaxing_twist_at_once_and_then_less_and_less() -> None:
    """The body held still 0.3 rad from the heading the rope hung in: the relaxing branch resists with
    k_r 0.3 at once, and the torque fades as exp(-t / tau_r) while the rope and the tether let go."""
    k_r, tau = 0.04, 1.5
    model = TankModel(ROBOT, BARE.with_values(suspension=True, rope_damping=0.0, rope_torsion_relaxing_stiffness=k_r,
                                              rope_torsion_relaxation_time=tau))
    assert model.relaxes_twist and model.counts_twist
    model.attach(RigidBodyState())
    held = RigidBodyState(rotation=rpy_to_rot(0.0, 0.0, 0.3))
    q = nominal_joint_angles(ROBOT)
    for step in range(301):
        if step % 100 == 0:
            torque = model.held_wrench(held, q, np.zeros_like(q))[3:6]
            expected = -k_r * 0.3 * math.exp(-step * DT / tau)
            np.testing.assert_allclose(torque, [0.0, 0.0, expected], rtol=1e-3, atol=1e-9)
        model.step(held, q, np.zeros_like(q), DT)  # handed the held state each step: the body does not move


def test_a_relaxing_twist_that_never_relaxes_is_the_ropes_spring_and_one_that_relaxes_takes_energy_out() -> None:
    """Limiting cases, nothing else acting: with tau_r far past the run the branch is the rope's spring k_t =
    k_r (the same swing, within tau's reach); with tau_r comparable to the swing's period the stored energy
    (1/2 I w^2 + 1/2 k_r (theta - s)^2) only falls, and the turn dies out."""
    k, q = 0.05, nominal_joint_angles(ROBOT)
    start = RigidBodyState(rotation=rpy_to_rot(0.0, 0.0, math.radians(10.0)))
    period = 2.0 * math.pi * math.sqrt(ROBOT.inertia[2, 2] / k)
    spring = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_stiffness=k))
    lasting = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_relaxing_stiffness=k,
                                                rope_torsion_relaxation_time=10000.0))
    yaws = []
    for model in (spring, lasting):
        model.attach(RigidBodyState())
        yaws.append([math.atan2(s.rotation[1, 0], s.rotation[0, 0]) for s in _spin(model, start, 0.75 * period)])
    np.testing.assert_allclose(yaws[1], yaws[0], atol=math.radians(10.0) * period / 10000.0)
    relaxing = TankModel(ROBOT, BARE.with_values(suspension=True, rope_torsion_relaxing_stiffness=k,
                                                 rope_torsion_relaxation_time=0.2 * period))
    relaxing.attach(RigidBodyState())
    def swing_energy(state: RigidBodyState) -> float:  # at the state the plant last stepped to
        return relaxing.kinetic_energy(state, q) + 0.5 * k * (relaxing.twist - relaxing.twist_relaxed) ** 2

    state = _spin(relaxing, start, 0.25 * period)[-1]
    energy = [swing_energy(state)]
    for _ in range(int(round(3.0 * period / DT))):
        state = relaxing.step(state, q, np.zeros((4, 3)), DT)
        energy.append(swing_energy(state))
    assert energy[0] > 0.2 * 0.5 * k * math.radians(10.0) ** 2  # a good part of the twist's energy is left
    assert np.all(np.diff(energy) < 1e-9 * energy[0])
    assert energy[-1] < 0.01 * energy[0]


@pytest.mark.parametrize("section, key, value", [("appendage_damping", "appendage_damping_linear", [0.0, -0.1, 0.0]),
                                                 ("suspension", "rope_torsion_stiffness", -1.0),
                                                 ("suspension", "rope_torsion_relaxing_stiffness", -1.0),
                                                 ("suspension", "rope_torsion_relaxation_time", 0.01),
                                                 ("paw_wake", "paw_wake_fraction", 1.0),
                                                 ("paw_wake", "paw_wake_time_constant", 0.0),
                                                 ("paw_wake", "paw_wake_body_share", 1.5),
                                                 ("appendage_damping", "body_wake_fraction", 1.0),
                                                 ("appendage_damping", "body_wake_time_constant", 0.01),
                                                 ("suspension", "block_mass", -1.0),
                                                 ("suspension", "block_drag", -1.0),
                                                 ("suspension", "block_tie_stiffness", 1.0e4),
                                                 ("hydrostatics", "paw_buoyancy_offset", 1.5)])
def test_candidate_effect_keys_are_checked(tmp_path, section, key, value) -> None:
    import yaml
    with open(config_path("tank.yaml")) as stream:
        tree = yaml.safe_load(stream)
    tree.setdefault(section, {})[key] = value
    path = tmp_path / "tank.yaml"
    path.write_text(yaml.safe_dump(tree))
    with pytest.raises(ParameterError, match="%s.%s" % (section, key)):
        load_tank_params(str(path))
    tree[section][key] = [0.0, 0.1, 0.2] if key == "appendage_damping_linear" else 0.3
    path.write_text(yaml.safe_dump(tree))
    params = load_tank_params(str(path))
    assert params.appendage_damping_linear == (0.0, 0.1, 0.2) or 0.3 in (
        params.rope_torsion_stiffness, params.rope_torsion_relaxing_stiffness, params.rope_torsion_relaxation_time,
        params.paw_wake_fraction, params.paw_wake_time_constant,
        params.paw_wake_body_share, params.body_wake_fraction, params.body_wake_time_constant, params.block_mass,
        params.block_drag, params.block_tie_stiffness, params.paw_buoyancy_offset)


def test_the_paws_buoyancy_offset_moves_the_plants_paws_alone() -> None:
    """Buoyant paws: the plant's paw buoyancy is robot.yaml's plus the offset (0: today's model, exactly);
    the difference of the restoring torque is the paws' buoyancy moment plus the rope's lighter load at the
    hook, in closed form; the controller's feedforward keeps robot.yaml's value."""
    delta = 0.05
    base = TankParams(center_of_buoyancy=(0.0, 0.0, 0.002))
    assert TankModel(ROBOT, base).net_paw_buoyancy == ROBOT.paw_net_buoyancy
    buoyant = TankModel(ROBOT, base.with_values(paw_buoyancy_offset=delta))
    assert buoyant.net_paw_buoyancy == ROBOT.paw_net_buoyancy + delta
    assert buoyant.static_rope_tension() == pytest.approx(TankModel(ROBOT, base).static_rope_tension() - 4 * delta)
    q = nominal_joint_angles(ROBOT)
    R = rpy_to_rot(0.4, -0.3, 0.2)
    up = R.T @ np.array([0.0, 0.0, 1.0])  # the world's up in body axes
    feet = sum(ROBOT.nominal_foot_body(leg) for leg in (1, 2, 3, 4))
    expected = np.cross(feet, delta * up) + np.cross(np.array(base.hook), -4 * delta * up)
    difference = buoyant.restoring_torque(R, q) - TankModel(ROBOT, base).restoring_torque(R, q)
    np.testing.assert_allclose(difference, expected, atol=1e-12)
    with pytest.raises(ParameterError, match="paw_buoyancy_offset"):
        TankParams(paw_buoyancy_offset=float("nan"))


def _wake_rows(u, wake, fraction, tau, dt):
    """One paw_wake_update of four paws that all move at u (body axes) with the body at rest."""
    from quadruped_control.sim.plants.tank_dynamics import paw_wake_update
    feet = [(0.2, 0.1, -0.05) + tuple(u)] * 4
    rows = np.zeros((4, 6))
    paw_wake_update(feet, wake, fraction, tau, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, dt, rows)
    return rows


def test_paw_wake_relaxes_exactly_and_a_steady_stroke_loses_drag_as_1_minus_kappa_squared() -> None:
    """dw/dt = (kappa u - w) / tau: after one step w = kappa u (1 - exp(-dt / tau)) exactly; after many
    time constants w = kappa u, so the drag law sees (1 - kappa) u: the steady drag is (1 - kappa)^2 of
    the quasi-steady one."""
    u, kappa, tau, dt = np.array([0.5, -0.2, 0.1]), 0.4, 0.25, 0.01
    wake = np.zeros((4, 3))
    rows = _wake_rows(u, wake, kappa, tau, dt)
    np.testing.assert_allclose(wake[0], kappa * u * (1.0 - math.exp(-dt / tau)), rtol=1e-14)
    np.testing.assert_allclose(rows[:, 3:], u - wake, rtol=1e-14)
    np.testing.assert_array_equal(rows[:, :3], [[0.2, 0.1, -0.05]] * 4)
    for _ in range(int(20 * tau / dt)):
        rows = _wake_rows(u, wake, kappa, tau, dt)
    np.testing.assert_allclose(rows[0, 3:], (1.0 - kappa) * u, rtol=1e-8)
    # kappa = 0: no wake, the drag sees the paw's own velocity (today's model)
    still = np.zeros((4, 3))
    np.testing.assert_array_equal(_wake_rows(u, still, 0.0, tau, dt)[0, 3:], u)


def test_a_paw_reversing_into_its_wake_meets_more_drag_than_in_still_water() -> None:
    """The recovery stroke retraces the power stroke: right after a long stroke at u, the paw moving at
    -u meets the water at -(1 + kappa) u: (1 + kappa)^2 of the still-water drag, against the stroke."""
    u, kappa, tau, dt = np.array([0.4, 0.0, 0.0]), 0.3, 0.2, 0.01
    wake = np.zeros((4, 3))
    for _ in range(200):
        _wake_rows(u, wake, kappa, tau, dt)
    rows = _wake_rows(-u, wake, kappa, tau, dt)
    relative = rows[0, 3]
    assert relative == pytest.approx(-(1.0 + kappa) * 0.4, rel=0.05)  # one step of relaxation already done


def test_a_passive_spin_builds_a_wake_that_lowers_its_damping_and_kappa_zero_is_todays_model() -> None:
    """A spinning body with still legs: its paws move at omega x r and build a wake, so it slows down
    less than in still water (less passive damping); kappa = 0 gives exactly today's spin-down."""
    drag = BARE.with_values(drag=True)
    start = RigidBodyState(omega=np.array([0.0, 0.0, 1.5]))
    plain = _spin(TankModel(ROBOT, drag), start, 2.0)[-1].omega[2]
    off = _spin(TankModel(ROBOT, drag.with_values(paw_wake_time_constant=0.1)), start, 2.0)[-1].omega[2]
    assert off == plain < 1.0
    waked = _spin(TankModel(ROBOT, drag.with_values(paw_wake_fraction=0.5, paw_wake_time_constant=0.1)), start,
                  2.0)[-1].omega[2]
    assert plain < waked < 1.5


def test_a_wake_of_the_strokes_alone_leaves_the_passive_damping_and_body_share_one_is_the_whole_velocity() -> None:
    """paw_wake_body_share 0: the body's motion builds no wake, so a passive spin (legs still) slows down
    exactly as without a wake; share 1 is the paw's whole velocity of paw_velocity_f, bit for bit; a share
    in between builds the wake from c_i + s_b (b + omega x r_i)."""
    from quadruped_control.model.hydrodynamics import paw_velocity_f
    from quadruped_control.sim.plants.tank_dynamics import paw_wake_update
    drag = BARE.with_values(drag=True)
    start = RigidBodyState(omega=np.array([0.0, 0.0, 1.5]))
    plain = _spin(TankModel(ROBOT, drag), start, 2.0)[-1].omega[2]
    strokes_only = drag.with_values(paw_wake_fraction=0.5, paw_wake_time_constant=0.1, paw_wake_body_share=0.0)
    assert _spin(TankModel(ROBOT, strokes_only), start, 2.0)[-1].omega[2] == plain
    row = (0.2, 0.1, -0.05, 0.3, -0.4, 0.2)
    body = (0.05, -0.02, 0.01, 0.3, -0.7, 1.1)  # b, omega
    for share in (1.0, 0.25):
        wake, rows = np.zeros((4, 3)), np.zeros((4, 6))
        paw_wake_update([row] * 4, wake, 0.4, 0.2, share, *body, 0.01, rows)
        u = np.array(paw_velocity_f(*row, *body))
        g = np.array(paw_velocity_f(*row[:3], 0.0, 0.0, 0.0, *body))
        target = u if share == 1.0 else np.array(row[3:]) + share * g
        np.testing.assert_array_equal(wake[0], 0.4 * target + (0.0 - 0.4 * target) * math.exp(-0.01 / 0.2))


def test_a_paws_wake_is_water_so_it_turns_back_in_body_axes_as_the_body_turns() -> None:
    """The wake is water moving in the tank: with nothing building it (kappa 0) and no time to relax
    (tau_w 1e12 s), one step of a body turning at omega leaves it exp(-hat(omega) dt) w in body axes, its
    speed kept; a body that does not turn leaves it where it was, bit for bit."""
    from quadruped_control.sim.plants.tank_dynamics import paw_wake_update
    row, omega, dt = (0.2, 0.1, -0.05, 0.0, 0.0, 0.0), np.array([0.3, -0.5, 1.2]), 0.01
    before = np.array([[0.1, -0.2, 0.05], [0.0, 0.3, 0.1], [-0.2, 0.0, 0.0], [0.05, 0.05, -0.3]])
    wake, rows = before.copy(), np.zeros((4, 6))
    paw_wake_update([row] * 4, wake, 0.0, 1e12, 1.0, 0.0, 0.0, 0.0, *omega, dt, rows)
    np.testing.assert_allclose(wake, before @ exp_so3(-omega * dt).T, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(wake, axis=1), np.linalg.norm(before, axis=1), rtol=1e-12)
    held = before.copy()
    paw_wake_update([row] * 4, held, 0.0, 1e12, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, dt, rows)
    np.testing.assert_array_equal(held, before * math.exp(-dt / 1e12))


def test_paw_joint_loads_are_the_jacobian_transpose_of_the_paw_drag_and_drag_takes_power_from_the_stroke() -> None:
    """tau_j = J_P,i^B[:, j] . F_i with J of foot_jacobian and F_i = -k |u_i| u_i; with the body at rest
    a stroke's paw drag does negative work on its joints: tau . q_dot = F . J q_dot = -k |c|^3 < 0."""
    from quadruped_control.model.kinematics import _geometry, foot_jacobian, leg_kinematics_rows
    from quadruped_control.sim.plants.tank_dynamics import paw_joint_loads
    q = np.array(nominal_joint_angles(ROBOT)) + 0.05
    q_dot = np.array([[1.5, -2.0, 0.7]] * 4)
    rows = np.array(leg_kinematics_rows(q.tolist(), q_dot.tolist(), ROBOT)).reshape(4, 6)
    geometry = _geometry(ROBOT)
    k, body = 1.4, (0.02, -0.01, 0.03, 0.2, -0.1, 0.3)
    loads = np.zeros((4, 3))
    assert paw_joint_loads(q, np.array(geometry.frame_rows), geometry.five_bar_hip, rows, k, *body, loads)
    for leg in range(4):
        J = foot_jacobian(q[leg], leg + 1, ROBOT)
        r, c = rows[leg, :3], rows[leg, 3:]
        u = np.array(body[:3]) + np.cross(body[3:], r) + c
        np.testing.assert_allclose(loads[leg], J.T @ (-k * np.linalg.norm(u) * u), rtol=1e-12, atol=1e-15)
    still = np.zeros((4, 3))
    paw_joint_loads(q, np.array(geometry.frame_rows), geometry.five_bar_hip, rows, k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, still)
    for leg in range(4):
        c = rows[leg, 3:]
        assert float(still[leg] @ q_dot[leg]) == pytest.approx(-k * np.linalg.norm(c) ** 3, rel=1e-12)


def test_loaded_servos_slow_the_strokes_and_no_stall_torque_is_todays_model() -> None:
    """A tank trial with the experiment gains: stall torque 0 gives today's trajectory bit for bit (the
    loads are not even computed); a stall torque slows the joints (their mean speed drops) and changes the
    trajectory; the servo model receives the plant's loads."""
    from quadruped_control.sim.servo_model import RateLimitedServo, load_servo_params
    config = load_controller_config(None, "experiment")

    def run(stall):
        tank = load_tank_params().with_values(servo_stall_torque=stall)
        servo = RateLimitedServo(dataclasses.replace(load_servo_params(), stall_torque=stall))
        sim = ClosedLoopSimulation(ROBOT, config, servo, initial_R=np.eye(3), setpoint_R=rpy_to_rot(0.5, 0.0, 0.0),
                                   model=TankModel(ROBOT, tank))
        result = sim.run(6.0)
        return result, servo, sim.plant.model.joint_loads

    plain, plain_servo, plain_loads = run(0.0)
    again, _, _ = run(0.0)
    np.testing.assert_array_equal(plain.rpy, again.rpy)
    assert plain_loads is None and plain_servo.loads is None
    loaded, loaded_servo, loads = run(1.0)
    assert loads is not None and loaded_servo.loads is loads and np.abs(loads).max() > 0.0
    speed = lambda result: np.abs(np.diff(result.joint_positions, axis=0)).mean()  # noqa: E731
    assert speed(loaded) < speed(plain)
    assert not np.array_equal(plain.rpy, loaded.rpy)


def test_the_tank_servos_lag_and_speed_scales_reach_the_servo_model() -> None:
    """servos.servo_speed_scale and servos.servo_lag_scale of the tank scale simulation.yaml's servo (trial_setup, the
    one place both engines take their servo parameters from); stall_torque and dead_band are passed on as
    they are."""
    import argparse
    from quadruped_control.studies.paper_experiments import experiment_specs
    from quadruped_control.studies.trial import trial_setup
    args = argparse.Namespace(seed=0, tank_yaml=None, robot_yaml=None)
    spec = experiment_specs(args, "tank", "experiment", "rate-limited", 10.0, keep_trace=False)[0][0]
    plain = trial_setup(spec).servo_params
    scaled = trial_setup(dataclasses.replace(spec, tank_overrides=(("servo_lag_scale", 4.0), ("servo_speed_scale", 0.5),
                                                                   ("servo_stall_torque", 2.0),
                                                                   ("servo_dead_band", 0.01)))).servo_params
    assert scaled.time_constant == 4.0 * plain.time_constant and scaled.max_speed == 0.5 * plain.max_speed
    assert scaled.stall_torque == 2.0 and plain.stall_torque == 0.0
    assert scaled.dead_band == 0.01 and plain.dead_band == 0.0


def test_body_wake_relaxes_exactly_in_world_axes_and_is_seen_in_body_axes() -> None:
    """One body_wake_update: W <- kappa R omega + (W - kappa R omega) exp(-dt / tau) in world axes; it
    returns R^T W."""
    from quadruped_control.sim.plants.tank_dynamics import body_wake_update
    R = rpy_to_rot(0.3, -0.5, 1.1)
    omega, start = np.array([0.2, -0.4, 0.7]), np.array([0.05, 0.1, -0.2])
    kappa, tau, dt = 0.6, 2.0, 0.01
    water = start.copy()
    seen = body_wake_update(water, kappa, tau, R.ravel().tolist(), *omega, dt)
    target = kappa * R @ omega
    np.testing.assert_allclose(water, target + (start - target) * math.exp(-dt / tau), rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(seen, R.T @ water, rtol=1e-14, atol=1e-16)


def test_a_spin_against_turning_water_follows_the_coupled_law_and_kappa_zero_is_todays_model() -> None:
    """A free body spinning about z with linear appendage damping c, nothing else acting:
    I w' = -c (w - W), W' = (kappa w - W) / tau, whose solution is exp(A t) (w0, 0) with
    A = [[-c/I, c/I], [kappa/tau, -1/tau]]: the water takes up part of the spin and gives it back, so the
    body slows less than exp(-c t / I); kappa = 0 (any tau) is today's spin-down bit for bit."""
    from scipy.linalg import expm
    c, kappa, tau, w0, seconds = 0.05, 0.6, 1.5, 1.0, 4.0
    inertia = ROBOT.inertia[2, 2]
    damped = BARE.with_values(appendage_damping_linear=(0.0, 0.0, c))
    start = RigidBodyState(omega=np.array([0.0, 0.0, w0]))
    plain = _spin(TankModel(ROBOT, damped), start, seconds)[-1].omega[2]
    off = _spin(TankModel(ROBOT, damped.with_values(body_wake_time_constant=0.3)), start, seconds)[-1].omega[2]
    assert off == plain == pytest.approx(w0 * math.exp(-c * seconds / inertia), rel=1e-6)
    model = TankModel(ROBOT, damped.with_values(body_wake_fraction=kappa, body_wake_time_constant=tau))
    end = _spin(model, start, seconds)[-1]
    A = np.array([[-c / inertia, c / inertia], [kappa / tau, -1.0 / tau]])
    expected_w, expected_water = expm(A * seconds) @ np.array([w0, 0.0])
    assert end.omega[2] == pytest.approx(expected_w, rel=2e-3)  # the water is held over each 10 ms step
    assert model.body_wake[2] == pytest.approx(expected_water, rel=2e-3)
    assert plain < end.omega[2] < w0


def test_turning_water_pushes_a_still_body_on_and_attach_stills_it() -> None:
    """The water keeps turning after the body stops: a body at rest in water turning about the world
    vertical is dragged along (the overshoot mechanism); attach() starts from still water."""
    params = BARE.with_values(appendage_damping_linear=(0.05, 0.05, 0.05), body_wake_fraction=0.5,
                              body_wake_time_constant=3.0)
    tilted = RigidBodyState(rotation=rpy_to_rot(0.4, 1.2, -0.3))
    still, model = TankModel(ROBOT, params), TankModel(ROBOT, params)
    model.body_wake[:] = (0.0, 0.0, 0.4)
    # the paws' buoyancy turns the tilted body too: the water's push is the difference
    dragged, alone = _spin(model, tilted, 0.1)[-1], _spin(still, tilted, 0.1)[-1]
    # angular momentum gained, world axes: about the water's axis (the torque is; the rate is not, I is not
    # isotropic), about c * 0.4 rad/s * 0.1 s
    push = dragged.rotation @ ROBOT.inertia @ dragged.omega - alone.rotation @ ROBOT.inertia @ alone.omega
    assert push[2] == pytest.approx(0.05 * 0.4 * 0.1, rel=0.1) and abs(push[0]) + abs(push[1]) < 0.1 * push[2]
    model.attach(tilted)
    assert not model.body_wake.any()


# ---- the floating block the rope hangs from -----------------------------------------------------------

def _block_at(offset_x: float, tension: float, rope=(0.5, 2000.0, 0.0)) -> np.ndarray:
    """A block straight above a still hook at h = (0, 0, 0.077), the rope stretched by ``tension``, moved
    ``offset_x`` along x: (a, a_dot)."""
    return np.array([offset_x, 0.0, 0.077 + rope[0] + tension / rope[1], 0.0, 0.0, 0.0])


def _block_steps(block, rest, rope, mass, drag, tie, seconds):
    from quadruped_control.sim.plants.tank_dynamics import floating_block_update
    still, identity = (0.0, 0.0, 0.0), tuple(np.eye(3).ravel().tolist())
    xs = [block[0]]
    for _ in range(int(round(seconds / DT))):
        floating_block_update(block, rest, still, still, identity, still, (0.0, 0.0, 0.077), rope, mass, drag, tie, DT)
        xs.append(block[0])
    return np.array(xs)


def test_a_block_swings_on_its_rope_and_tie_with_the_pendulum_period() -> None:
    """No drag: m_b x'' = -(k_g + T / l) x for small x (the rope's pull, T x / l, and the tie): the block
    keeps its amplitude and swings with 2 pi sqrt(m_b / (k_g + T / l)); the vertical stays put."""
    mass, tie, tension, rope = 0.5, 3.0, 1.0, (0.5, 2000.0, 0.0)
    # 1 mm: the stretch that a swing adds, k x^2 / (2 l), stays small against T (1 cm would add 0.2 N)
    block = _block_at(0.001, tension, rope)
    rest = block[:3] - np.array([0.001, 0.0, 0.0])
    height = block[2] - 0.077
    xs = _block_steps(block, rest, rope, mass, 0.0, tie, 8.0)
    period = 2.0 * math.pi * math.sqrt(mass / (tie + tension / height))
    t = np.arange(xs.size) * DT
    crossings = [t[k] - xs[k] * DT / (xs[k + 1] - xs[k]) for k in range(xs.size - 1) if xs[k] > 0.0 >= xs[k + 1]]
    assert len(crossings) >= 3
    assert np.mean(np.diff(crossings)) == pytest.approx(period, rel=5e-3)
    assert np.max(np.abs(xs[-int(period / DT):])) == pytest.approx(0.001, rel=0.02)
    assert block[2] == _block_at(0.0, tension, rope)[2] and block[5] == 0.0


def test_a_slack_rope_leaves_the_block_to_its_quadratic_drag() -> None:
    """Slack rope, no tie: m_b v' = -c_b |v| v, so v(t) = v_0 / (1 + c_b v_0 t / m_b)."""
    mass, drag, v0 = 0.4, 2.0, 0.3
    block = np.array([0.0, 0.0, 0.3, v0, 0.0, 0.0])  # 0.22 m above the hook: the 0.5 m rope is slack
    _block_steps(block, block[:3].copy(), (0.5, 2000.0, 150.0), mass, drag, 0.0, 2.0)
    assert block[3] == pytest.approx(v0 / (1.0 + drag * v0 * 2.0 / mass), rel=2e-3)
    assert block[4] == 0.0


def test_a_light_block_on_a_steep_damped_rope_stays_stable_and_settles_above_the_hook() -> None:
    """The rope's dashpot (150 N s/m) against a 0.1 kg block: explicit Euler would need dt < 1.3 ms; the
    implicit dashpot settles the block above the hook from a 30 degree tilt."""
    rope = (0.5, 2000.0, 150.0)
    block = _block_at(0.25, 1.0, rope)
    xs = _block_steps(block, block[:3].copy(), rope, 0.1, 2.0, 0.0, 60.0)
    assert np.all(np.isfinite(xs)) and np.max(np.abs(xs)) <= 0.25 + 1e-12
    assert abs(xs[-1]) < 0.01


def test_a_free_block_follows_the_swinging_robot_and_a_stiff_tie_is_the_fixed_anchor() -> None:
    """The robot released at 30 degrees of roll: with a free block (no tie) the block drifts over the hook
    and the rope ends vertical; with a tie far stiffer than the rope's pendulum (T / l ~ 2 N/m) the swing is
    the fixed anchor's; block_mass 0 is the fixed anchor bit for bit, whatever the other block values."""
    fixed = _roll(_hang(TankModel(ROBOT, TANK), 30.0, 6.0)[1])
    ignored = _roll(_hang(TankModel(ROBOT, TANK.with_values(block_drag=5.0, block_tie_stiffness=7.0)), 30.0, 6.0)[1])
    assert np.array_equal(fixed, ignored)
    stiff = _roll(_hang(TankModel(ROBOT, TANK.with_values(block_mass=1.0, block_tie_stiffness=1000.0)), 30.0, 6.0)[1])
    assert np.max(np.abs(stiff - fixed)) < 0.02 * math.radians(30.0)
    model = TankModel(ROBOT, TANK.with_values(block_mass=0.3, block_drag=2.0))
    plant, states = _hang(model, 30.0, 40.0)
    start_anchor = model.block_rest
    hook = states[-1].position + states[-1].rotation @ model.hook
    assert np.linalg.norm(model.anchor[:2] - start_anchor[:2]) > 0.01  # the block moved
    assert np.linalg.norm(model.anchor[:2] - hook[:2]) < 0.002  # and hangs above the hook
    free = _roll(states[:601])
    assert np.max(np.abs(free - fixed)) > 0.02 * math.radians(30.0)  # a free block changes the swing
    model.attach(states[-1])
    assert np.array_equal(model.block[:3], model.block_rest) and not model.block[3:].any()


def test_block_parameters_are_validated() -> None:
    for values in ({"block_mass": -1.0}, {"block_mass": 0.001}, {"block_drag": -0.1}, {"block_drag": float("nan")},
                   {"block_tie_stiffness": 2000.0}):
        with pytest.raises(ParameterError, match="block"):
            TANK.with_values(**values)
    # the explicit rope pull on the block is stable while (k + k_g) dt^2 / m_b < 4: 0.04 kg rings on a 2 kN/m
    # rope at 10 ms, 0.06 kg does not, and rings at 20 ms (checked when the plant is asked for that step)
    with pytest.raises(ParameterError, match="block_mass"):
        TankModel(ROBOT, TANK.with_values(block_mass=0.04))
    light = TankModel(ROBOT, TANK.with_values(block_mass=0.06))
    light.attach(RigidBodyState())
    light.step(RigidBodyState(), nominal_joint_angles(ROBOT), np.zeros((4, 3)), DT)
    with pytest.raises(ParameterError, match="0.02 s step cannot resolve: suspension.block_mass"):
        light.step(RigidBodyState(), nominal_joint_angles(ROBOT), np.zeros((4, 3)), 0.02)


def test_a_servo_dead_band_is_read_from_tank_yaml_and_a_unit_slip_is_refused(tmp_path) -> None:
    """servos.servo_dead_band (rad) reaches TankParams; 0 (the default) is today's trajectory bit for bit; a value
    in degrees or microseconds (past 0.1 rad) or negative is refused with the key's name; a dead band
    changes a tank trial."""
    from quadruped_control.sim.servo_model import RateLimitedServo, load_servo_params, tank_servo_params
    text = open(config_path("tank.yaml")).read()
    assert "  servo_dead_band: 0.0 " in text and load_tank_params().servo_dead_band == 0.0
    path = tmp_path / "tank.yaml"
    path.write_text(text.replace("  servo_dead_band: 0.0 ", "  servo_dead_band: 0.008 ", 1))
    assert load_tank_params(str(path)).servo_dead_band == 0.008
    for wrong in ("0.5", "-0.001", "8"):
        path.write_text(text.replace("  servo_dead_band: 0.0 ", "  servo_dead_band: %s " % wrong, 1))
        with pytest.raises(ParameterError, match="servos.servo_dead_band"):
            load_tank_params(str(path))
    with pytest.raises(ParameterError, match="servo_dead_band"):
        load_tank_params().with_values(servo_dead_band=0.2)
    config = load_controller_config(None, "experiment")

    def run(band):
        tank = load_tank_params().with_values(servo_dead_band=band)
        servo = RateLimitedServo(tank_servo_params(load_servo_params(), tank))
        sim = ClosedLoopSimulation(ROBOT, config, servo, initial_R=np.eye(3), setpoint_R=rpy_to_rot(0.5, 0.0, 0.0),
                                   model=TankModel(ROBOT, tank))
        return sim.run(4.0)

    plain, banded = run(0.0), run(0.01)
    before = ClosedLoopSimulation(ROBOT, config, RateLimitedServo(load_servo_params()), initial_R=np.eye(3),
                                  setpoint_R=rpy_to_rot(0.5, 0.0, 0.0),
                                  model=TankModel(ROBOT, load_tank_params())).run(4.0)
    np.testing.assert_array_equal(plain.rpy, before.rpy)
    lag = np.abs(banded.joint_targets - banded.joint_positions)
    assert lag.max() > 0.01 and not np.array_equal(plain.rpy, banded.rpy)


# ---- hook friction ---------------------------------------------------------------------------------

def _hook_friction_step(friction, rate, limit=0.004, angle=0.005, velocity=(0.0, 0.0, 0.0), slack=False, dt=DT,
                        static_ratio=1.0, stribeck_rate=0.02, roll_ratio=1.0):
    """One hook_friction_update of a level body at the origin whose rope (length 0.5 m) runs straight up from
    the hook at (0, 0, 0.077) to an anchor 0.51 m above it (0.49 m: slack)."""
    from quadruped_control.sim.plants.tank_dynamics import hook_friction_update
    anchor = (0.0, 0.0, 0.077 + (0.49 if slack else 0.51), 0.0, 0.0, 0.0)
    return np.array(hook_friction_update(friction, limit, angle, static_ratio, stribeck_rate, roll_ratio,
                                         (0.0, 0.0, 0.0), tuple(velocity), np.eye(3).ravel().tolist(), tuple(rate),
                                         (0.0, 0.0, 0.077), anchor, 0.5, dt))


def test_hook_friction_follows_dahls_law_across_the_rope() -> None:
    """d tau_f/dt = (tau_c s - |s| tau_f) / theta_p on the rate s across the rope, exact for a held rate: one
    step builds tau_c s^ (1 - exp(-|s| dt / theta_p)); a long turn slides at tau_c; the body feels -tau_f; the
    twist about the (vertical) rope is left to the rope torsion; a reversal unloads the tie and then slides the
    other way; a still body keeps what the tie holds; a slack rope holds nothing."""
    limit, angle = 0.004, 0.005
    friction = np.zeros(3)
    felt = _hook_friction_step(friction, (0.2, 0.0, 0.3), limit, angle)
    # turning about x swings the hook (0.077 m above the centre) sideways, and the rope (0.51 m) the other way
    rate = 0.2 * (1.0 + 0.077 / 0.51)
    expected = limit * (1.0 - math.exp(-rate * DT / angle))
    np.testing.assert_allclose(friction, [expected, 0.0, 0.0], rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(felt, -friction, rtol=0, atol=0)
    for _ in range(50):  # 0.1 rad of relative turn: 20 presliding angles
        _hook_friction_step(friction, (0.2, 0.0, 0.3), limit, angle)
    np.testing.assert_allclose(friction, [limit, 0.0, 0.0], rtol=1e-8)
    history = []
    for _ in range(50):  # reversed: through zero to the other side, never past tau_c
        _hook_friction_step(friction, (-0.2, 0.0, 0.0), limit, angle)
        history.append(np.linalg.norm(friction))
    assert max(history) <= limit
    np.testing.assert_allclose(friction, [-limit, 0.0, 0.0], rtol=1e-8)
    held = friction.copy()
    _hook_friction_step(friction, (0.0, 0.0, 0.5), limit, angle)  # a twist along the rope moves nothing
    np.testing.assert_array_equal(friction, held)
    assert not _hook_friction_step(friction, (0.2, 0.0, 0.0), limit, angle, slack=True).any()
    assert not friction.any()


def test_hook_friction_holds_its_static_level_when_slow_and_slides_at_tau_c_when_fast() -> None:
    """The Stribeck curve g(|s|) = tau_c (1 + (r - 1) exp(-(|s| / s_s)^2)) at Dahl's stiffness sigma_0 =
    tau_c / theta_p: one held step builds g s^ (1 - exp(-sigma_0 |s| dt / g)); a long slow turn (|s| << s_s)
    settles at r tau_c, a fast one (|s| >> s_s) at tau_c, and a tie that has stuck at r tau_c drops to tau_c
    once the body breaks away, never passing g on the way; ratio 1 is Dahl's law bit for bit, whatever s_s."""
    limit, angle, ratio, stribeck = 0.004, 0.005, 1.8, 0.02
    slow = 0.002 / (1.0 + 0.077 / 0.51)  # the relative rate across the rope is 0.002 rad/s (s_s / 10)
    friction = np.zeros(3)
    _hook_friction_step(friction, (slow, 0.0, 0.0), limit, angle, static_ratio=ratio, stribeck_rate=stribeck)
    level = limit * (1.0 + (ratio - 1.0) * math.exp(-(0.002 / stribeck) ** 2))
    expected = level * (1.0 - math.exp(-limit / angle * 0.002 * DT / level))
    np.testing.assert_allclose(friction, [expected, 0.0, 0.0], rtol=1e-12, atol=1e-18)
    for _ in range(8000):  # 0.16 rad of relative turn: 18 static presliding angles r theta_p
        _hook_friction_step(friction, (slow, 0.0, 0.0), limit, angle, static_ratio=ratio, stribeck_rate=stribeck)
    np.testing.assert_allclose(friction, [level, 0.0, 0.0], rtol=1e-6)
    assert level > 1.7 * limit
    history = []
    for _ in range(100):  # breaks away at 0.2 rad/s (10 s_s): down to tau_c
        _hook_friction_step(friction, (0.2, 0.0, 0.0), limit, angle, static_ratio=ratio, stribeck_rate=stribeck)
        history.append(friction[0])
    np.testing.assert_allclose(friction, [limit, 0.0, 0.0], rtol=1e-8)
    assert max(history) <= level and all(b <= a for a, b in zip(history, history[1:]))
    dahl, stribeck_off = np.zeros(3), np.zeros(3)
    for rate in ((0.2, 0.0, 0.0), (0.01, 0.0, 0.0), (-0.3, 0.1, 0.0)):
        _hook_friction_step(dahl, rate, limit, angle)
        _hook_friction_step(stribeck_off, rate, limit, angle, static_ratio=1.0, stribeck_rate=0.3)
        np.testing.assert_array_equal(stribeck_off, dahl)


def test_hook_friction_holds_more_about_roll_than_pitch_by_its_roll_ratio() -> None:
    """The tie's Coulomb torque about the body's x axis is roll_ratio m times the one about y: a long turn about
    x slides at m tau_c, one about y at tau_c, a diagonal one on the ellipse tau_c (m s_x, s_y) / |s|, which
    still dissipates (tau_f . s > 0); the first step builds m times the isotropic one about x and the
    presliding angle is the same; m = 1 is the isotropic tie, the static friction's included."""
    limit, angle, m = 0.004, 0.005, 2.5
    factor = 1.0 + 0.077 / 0.51  # the rope swings the other way: the relative rate across it
    for rate, expected in (((0.2, 0.0, 0.0), (m * limit, 0.0, 0.0)), ((0.0, 0.2, 0.0), (0.0, limit, 0.0)),
                           ((0.2, 0.2, 0.0), (m * limit / math.sqrt(2.0), limit / math.sqrt(2.0), 0.0))):
        friction = np.zeros(3)
        for _ in range(100):  # 0.23-0.33 rad of relative turn: 46-66 presliding angles
            _hook_friction_step(friction, rate, limit, angle, roll_ratio=m)
        np.testing.assert_allclose(friction, expected, rtol=1e-8, atol=1e-15)
        assert float(np.dot(friction, rate)) > 0.0  # the tie holds against the turn: it takes energy out
    isotropic, rolled = np.zeros(3), np.zeros(3)
    _hook_friction_step(isotropic, (0.2, 0.0, 0.0), limit, angle)
    _hook_friction_step(rolled, (0.2, 0.0, 0.0), limit, angle, roll_ratio=m)
    np.testing.assert_allclose(rolled, m * isotropic, rtol=1e-14)
    assert rolled[0] == pytest.approx(m * limit * (1.0 - math.exp(-0.2 * factor * DT / angle)), rel=1e-14)
    # m = 1 is the isotropic tie: one step of a diagonal turn, static friction on, against its closed form
    # g s^ (1 - exp(-sigma_0 |s| dt / g)) (the twist along the vertical rope left out)
    ratio, stribeck = 1.5, 0.02
    for rate in ((0.2, -0.1, 0.05), (-0.003, 0.004, 0.0)):
        relative = factor * np.array([rate[0], rate[1], 0.0])
        speed = float(np.linalg.norm(relative))
        level = limit * (1.0 + (ratio - 1.0) * math.exp(-(speed / stribeck) ** 2))
        expected = level * relative / speed * (1.0 - math.exp(-limit / angle * speed * DT / level))
        friction = np.zeros(3)
        felt = _hook_friction_step(friction, rate, limit, angle, static_ratio=ratio, stribeck_rate=stribeck,
                                   roll_ratio=1.0)
        np.testing.assert_allclose(friction, expected, rtol=1e-12, atol=1e-18)
        np.testing.assert_array_equal(felt, -friction)


def test_the_stribeck_rate_moves_a_released_robot_between_its_sliding_and_its_static_tie() -> None:
    """Released at rest at 3 deg of roll under a restoring torque r, with tau_c = 0.75 r and tau_s = 1.5 tau_c
    (the robot and its rope swing together as a pendulum, which a tie does not resist, so even a tie that
    holds moves the roll). The two limits of the Stribeck rate s_s: far above every rate of the swing (1
    rad/s), the tie is Dahl's with tau_s and the presliding angle 1.5 theta_p (its limit is tau_s at Dahl's
    stiffness tau_c / theta_p); far below (1e-4 rad/s), Dahl's with tau_c. Between them (0.02 rad/s) the tie
    holds the robot further from level than tau_c alone and less far than tau_s."""
    base = TankParams(center_of_buoyancy=(0.0, 0.0, 0.0))
    model = TankModel(ROBOT, base)
    restoring = abs(model.restoring_torque(rpy_to_rot(math.radians(3.0), 0.0, 0.0), nominal_joint_angles(ROBOT))[0])
    arm, angle = 0.75 * restoring / model.static_rope_tension(), 0.005

    def final_roll(**values: float) -> float:
        return float(_released_tilt(base.with_values(hook_friction_arm=arm, hook_friction_angle=angle,
                                                     **values), 3.0, 10.0)[0][-1])

    sliding = final_roll()
    static = float(_released_tilt(base.with_values(hook_friction_arm=1.5 * arm, hook_friction_angle=1.5 * angle),
                                  3.0, 10.0)[0][-1])
    assert sliding < 1.0 and sliding + 0.4 < static
    assert final_roll(hook_friction_static_ratio=1.5, hook_friction_stribeck_rate=1.0) == pytest.approx(static,
                                                                                                          abs=0.01)
    assert final_roll(hook_friction_static_ratio=1.5, hook_friction_stribeck_rate=1e-4) == pytest.approx(sliding,
                                                                                                           abs=0.01)
    assert sliding + 0.1 < final_roll(hook_friction_static_ratio=1.5, hook_friction_stribeck_rate=0.02) < static - 0.1


def test_hook_friction_sees_the_body_turn_relative_to_the_swinging_rope() -> None:
    """A body that does not turn while its hook moves sideways turns relative to the rope, whose swing rate
    is Omega = -(u x q_dot) / d (d = 0.51 m): the hook moving along +x at 0.05 m/s turns the rope about -y,
    so the body turns about +y relative to it; turning with the rope (omega_y = -v / (d + h), the hook then
    moving at v + omega_y h), it does not slide at all."""
    limit, angle, d = 0.004, 0.005, 0.51
    friction = np.zeros(3)
    _hook_friction_step(friction, (0.0, 0.0, 0.0), limit, angle, velocity=(0.05, 0.0, 0.0))
    np.testing.assert_allclose(friction, [0.0, limit * (1.0 - math.exp(-0.05 / d * DT / angle)), 0.0], rtol=1e-12)
    friction[:] = 0.0
    _hook_friction_step(friction, (0.0, -0.05 / (d + 0.077), 0.0), limit, angle, velocity=(0.05, 0.0, 0.0))
    np.testing.assert_allclose(friction, 0.0, atol=1e-18)


def _released_tilt(tank: TankParams, tilt_deg: float, seconds: float, pitch: bool = False) -> tuple:
    """Roll angles (deg) of the hanging robot released at rest from ``tilt_deg`` of roll (or pitch angles from
    ``tilt_deg`` of pitch), legs still, and its rate at the end."""
    model = TankModel(ROBOT, tank)
    tilt = math.radians(tilt_deg)
    state = RigidBodyState(rotation=rpy_to_rot(0.0, tilt, 0.0) if pitch else rpy_to_rot(tilt, 0.0, 0.0))
    model.attach(state)
    states = _spin(model, state, seconds)[1:]
    if pitch:
        angles = [math.asin(-s.rotation[2, 0]) for s in states]
    else:
        angles = [math.atan2(s.rotation[2, 1], s.rotation[2, 2]) for s in states]
    return np.degrees(angles), float(np.abs(states[-1].omega).max())


def test_hook_friction_holds_what_it_can_and_stops_the_swing_in_its_dead_zone() -> None:
    """The robot released at 3 deg of roll under a restoring torque r: without friction it swings through
    level and is still swinging after 20 s; a tie that holds 2 r keeps it on its side of level, where it
    stops; one that holds r / 2 lets it swing back and stops it within the dead zone tau_c / k = 1.5 deg of
    level (k = r / 3 deg the restoring stiffness)."""
    base = TankParams(center_of_buoyancy=(0.0, 0.0, 0.0))
    model = TankModel(ROBOT, base)
    restoring = abs(model.restoring_torque(rpy_to_rot(math.radians(3.0), 0.0, 0.0), nominal_joint_angles(ROBOT))[0])
    assert restoring > 1e-3
    free, free_rate = _released_tilt(base, 3.0, 20.0)
    assert free.min() < -1.5 and free_rate > 1e-2
    arm = 2.0 * restoring / model.static_rope_tension()
    held, held_rate = _released_tilt(base.with_values(hook_friction_arm=arm), 3.0, 20.0)
    assert held.min() > 1.5 and held_rate < 2e-3
    slipping, slipping_rate = _released_tilt(base.with_values(hook_friction_arm=arm / 4.0), 3.0, 20.0)
    assert slipping.min() < 0.0 and abs(slipping[-1]) <= 1.5 and slipping_rate < 1e-3


def test_a_tie_that_holds_more_about_roll_keeps_a_rolled_robot_and_lets_a_pitched_one_swing() -> None:
    """The roll ratio on the plant: a tie that slips in both axes at half the restoring torque (tau_c = r / 2)
    holds a rolled robot on its side of level when it holds four times as much about roll (m = 4), and leaves
    the pitched robot's swing as it was, to the bit (a pure pitch swing turns the body about y alone)."""
    base = TankParams(center_of_buoyancy=(0.0, 0.0, 0.0))
    model = TankModel(ROBOT, base)
    restoring = abs(model.restoring_torque(rpy_to_rot(math.radians(3.0), 0.0, 0.0), nominal_joint_angles(ROBOT))[0])
    arm = 0.5 * restoring / model.static_rope_tension()
    slipping, _ = _released_tilt(base.with_values(hook_friction_arm=arm), 3.0, 20.0)
    assert slipping.min() < 0.0
    held, held_rate = _released_tilt(base.with_values(hook_friction_arm=arm, hook_friction_roll_ratio=4.0), 3.0, 20.0)
    assert held.min() > 1.5 and held_rate < 2e-3
    pitched, pitched_rate = _released_tilt(base.with_values(hook_friction_arm=arm), 3.0, 10.0, pitch=True)
    assert pitched.min() < 0.0
    rolled_tie, rolled_tie_rate = _released_tilt(base.with_values(hook_friction_arm=arm, hook_friction_roll_ratio=4.0),
                                                 3.0, 10.0, pitch=True)
    np.testing.assert_array_equal(rolled_tie, pitched)
    assert rolled_tie_rate == pitched_rate


def test_the_wound_tether_grows_the_ties_friction_by_the_capstan_law() -> None:
    """wound_friction_limit: tau_c exp(mu_w |phi|) with phi the turn about the world vertical since the rope
    hung untwisted, either way round; a tilt is no turn; mu_w = 0 returns tau_c itself whatever the turn."""
    from quadruped_control.sim.plants.tank_dynamics import whole_twist, wound_friction_limit
    untwisted = rpy_to_rot(0.3, -0.2, 0.4).ravel().tolist()
    for turn in (math.pi / 2.0, -2.1, 4.0):  # 4 rad: past half a turn the tether goes on winding
        assert wound_friction_limit(0.004, 0.3, turn) == pytest.approx(0.004 * math.exp(0.3 * abs(turn)), rel=1e-12)
        assert wound_friction_limit(0.004, 0.0, turn) == 0.004
    assert wound_friction_limit(0.004, 0.3, whole_twist(untwisted, untwisted, 0.0)) == 0.004
    # a tilt about a horizontal world axis is no turn about the rope (the twist of the swing-twist is 0)
    tilted = (rpy_to_rot(0.5, 0.0, 0.0) @ rpy_to_rot(0.3, -0.2, 0.4)).ravel().tolist()
    assert wound_friction_limit(0.004, 0.3, whole_twist(tilted, untwisted, 0.0)) == pytest.approx(0.004, rel=1e-12)


def test_a_tie_whose_limit_falls_slips_down_to_what_it_now_holds_even_with_the_body_still() -> None:
    """The tether unwinding lowers the tie's limit: a tie that slid at a wound limit 1.9 tau_c, then a step
    with the body still (s = 0, where Dahl's update keeps what is stored) and the limit back at tau_c, holds
    tau_c along the same direction; with static friction, r tau_c; with a roll ratio m, the ellipse's point
    (m tau_c s_x, tau_c s_y) / |s| scaled back along itself; a stored torque already below the new limit
    is kept to the bit."""
    limit, angle, wound = 0.004, 0.005, 0.004 * math.exp(0.4 * math.pi / 2.0)
    for ratio, m in ((1.0, 1.0), (1.5, 1.0), (1.0, 2.5)):
        friction = np.zeros(3)
        for _ in range(100):  # slides at the wound limit, diagonally across the rope
            _hook_friction_step(friction, (0.2, 0.1, 0.0), wound, angle, static_ratio=ratio, stribeck_rate=0.02,
                                roll_ratio=m)
        before = friction.copy()
        assert math.hypot(before[0] / m, before[1]) == pytest.approx(wound, rel=1e-8)  # slid at tau_c: no static
        felt = _hook_friction_step(friction, (0.0, 0.0, 0.0), limit, angle, static_ratio=ratio, stribeck_rate=0.02,
                                   roll_ratio=m)
        most = limit * max(1.0, ratio)
        assert math.hypot(friction[0] / m, friction[1]) == pytest.approx(most, rel=1e-12)
        np.testing.assert_allclose(friction, before * most / wound, rtol=1e-8)
        np.testing.assert_array_equal(felt, -friction)
    kept = np.array([0.5 * limit, -0.3 * limit, 0.0])
    friction = kept.copy()
    _hook_friction_step(friction, (0.0, 0.0, 0.0), limit, angle)
    np.testing.assert_array_equal(friction, kept)


@pytest.mark.parametrize("values, named", [
    ({"appendage_damping_linear": (20.0, 0.0, 0.0)}, "appendage_damping.appendage_damping_linear[0] (x)"),
    ({"appendage_damping_quadratic": (0.0, 0.0, 30.0)}, "appendage_damping.appendage_damping_quadratic[2] (z)"),
    ({"rope_torsion_damping": 60.0}, "suspension.rope_torsion_damping"),
    ({"rope_torsion_stiffness": 1e4, "rope_torsion_relaxing_stiffness": 1e4}, "suspension.rope_torsion_stiffness"),
    ({"rope_damping": 1e4}, "suspension.rope_damping"),
    ({"rope_stiffness": 1e7}, "suspension.rope_stiffness"),
    ({"hook_friction_arm": 0.05, "hook_friction_angle": 0.001, "hook_friction_wrap": 1.0}, "presliding stiffness"),
    ({"net_weight": 60.0}, "hydrostatics.net_weight"),
])
def test_a_set_a_control_step_cannot_resolve_is_refused_by_key(values, named) -> None:
    """Stiff terms the 10 ms step would ring on (a tie that pumps energy into the swing, a rope that
    chatters, damping past RK4's stability) and a torso without buoyancy: TankModel refuses them by name."""
    with pytest.raises(ParameterError, match="step cannot resolve") as error:
        TankModel(ROBOT, TankParams().with_values(**values))
    assert named in str(error.value)


def test_the_step_check_passes_the_shipped_sets_and_stops_at_its_stated_limits() -> None:
    """config/tank.yaml and config/tank_identified.yaml pass; the linear appendage damping is refused just
    past 2.5 I / dt and taken just below it, and a finer step takes what the 10 ms step refuses."""
    for name in ("tank.yaml", "tank_identified.yaml"):
        TankModel(ROBOT, load_tank_params(config_path(name)))
    model = TankModel(ROBOT, TankParams())
    edge = 2.5 * float(model.body_mass_matrix[3, 3]) / 0.01
    TankModel(ROBOT, TankParams().with_values(appendage_damping_linear=(0.99 * edge, 0.0, 0.0)))
    with pytest.raises(ParameterError):
        TankModel(ROBOT, TankParams().with_values(appendage_damping_linear=(1.01 * edge, 0.0, 0.0)))
    stiff = TankModel(ROBOT, TankParams())
    stiff.tank = TankParams().with_values(rope_damping=1e4)
    stiff.check_step_stability(0.001)
    with pytest.raises(ParameterError):
        stiff.check_step_stability(0.01)


def test_the_paper_models_continuous_time_methods_are_refused_on_the_tank() -> None:
    """wrench, derivative, step_continuous and the generic chart derivative are the paper model's: on the
    tank they would leave out the rope and everything else, so they raise and name what to use."""
    model = TankModel(ROBOT, TankParams())
    q, still = nominal_joint_angles(ROBOT), np.zeros((4, 3))
    calls = (lambda: model.wrench(RigidBodyState(), q, still), lambda: model.derivative(RigidBodyState(), q, still),
             lambda: model.step_continuous(RigidBodyState(), 0.0, DT, lambda t: (q, still)),
             lambda: model._chart_derivative(None, None, [0.0] * 12))  # noqa: SLF001
    for call in calls:
        with pytest.raises(NotImplementedError, match="held_wrench"):
            call()


def test_the_plant_holds_a_body_turned_since_the_rope_hung_with_the_wound_tie() -> None:
    """TankModel: a level body rolling at 0.3 rad/s, its rope hung untwisted a quarter turn ago (attached at
    heading -90 deg), builds exp(mu_w pi / 2) times the friction of an unturned body in one step; with
    mu_w = 0 the quarter turn changes nothing, to the bit."""
    tank = TankParams(center_of_buoyancy=(0.0, 0.0, 0.0), hook_friction_arm=0.002)
    rolling = RigidBodyState(rotation=np.eye(3), omega=np.array([0.3, 0.0, 0.0]))
    held = {}
    for wrap in (0.0, 0.4):
        for heading in (0.0, -math.pi / 2.0):
            model = TankModel(ROBOT, tank.with_values(hook_friction_wrap=wrap))
            model.attach(RigidBodyState(rotation=rpy_to_rot(0.0, 0.0, heading)))
            end = model.step(rolling, nominal_joint_angles(ROBOT), np.zeros((4, 3)), DT)
            held[wrap, heading] = (model.hook_friction.copy(), end.omega.copy())
    assert held[0.0, 0.0][0][0] > 1e-5
    np.testing.assert_array_equal(held[0.0, -math.pi / 2.0][0], held[0.0, 0.0][0])
    np.testing.assert_array_equal(held[0.0, -math.pi / 2.0][1], held[0.0, 0.0][1])
    np.testing.assert_array_equal(held[0.4, 0.0][0], held[0.0, 0.0][0])
    np.testing.assert_allclose(held[0.4, -math.pi / 2.0][0], held[0.0, 0.0][0] * math.exp(0.4 * math.pi / 2.0),
                               rtol=1e-12)


def test_hook_friction_tends_to_todays_model_as_it_vanishes() -> None:
    """The limiting case: arm 0 is today's model exactly (whatever the presliding angle), and a vanishing arm
    tends to it (1e-9 m: states within 1e-9 after 5 s of a released swing)."""
    base = TankParams(center_of_buoyancy=(0.0, 0.0, 0.001))
    today, _ = _released_tilt(base, 3.0, 5.0)
    off, _ = _released_tilt(base.with_values(hook_friction_angle=0.02), 3.0, 5.0)
    np.testing.assert_array_equal(off, today)
    tiny, _ = _released_tilt(base.with_values(hook_friction_arm=1e-9), 3.0, 5.0)
    assert 0.0 < np.abs(tiny - today).max() < 1e-9 * 180.0 / math.pi * 1e3


@pytest.mark.parametrize("key, value, good", [
    ("hook_friction_arm", -0.001, 0.003), ("hook_friction_arm", 0.06, 0.003), ("hook_friction_arm", "x", 0.003),
    ("hook_friction_angle", 0.0, 0.003), ("hook_friction_angle", 0.6, 0.003),
    ("hook_friction_static_ratio", 0.9, 1.6), ("hook_friction_static_ratio", 3.5, 1.6),
    ("hook_friction_static_ratio", "x", 1.6), ("hook_friction_stribeck_rate", 0.0, 0.05),
    ("hook_friction_stribeck_rate", 2.0, 0.05), ("hook_friction_roll_ratio", 0.05, 3.0),
    ("hook_friction_roll_ratio", 12.0, 0.3), ("hook_friction_wrap", -0.1, 0.3), ("hook_friction_wrap", 1.5, 0.3)])
def test_hook_friction_keys_are_checked(tmp_path, key: str, value, good: float) -> None:
    """Each of tank.yaml's suspension.hook_friction_* keys: a value out of its bounds is refused by name, one inside
    reaches TankParams; the static friction and the roll ratio are off by default."""
    import yaml
    with open(config_path("tank.yaml")) as stream:
        tree = yaml.safe_load(stream)
    assert tree["suspension"]["hook_friction_static_ratio"] == 1.0  # off by default
    assert tree["suspension"]["hook_friction_roll_ratio"] == 1.0
    assert tree["suspension"]["hook_friction_wrap"] == 0.0
    tree["suspension"][key] = value
    path = tmp_path / "tank.yaml"
    path.write_text(yaml.safe_dump(tree))
    with pytest.raises(ParameterError, match="suspension.%s" % key):
        load_tank_params(str(path))
    tree["suspension"][key] = good
    path.write_text(yaml.safe_dump(tree))
    params = load_tank_params(str(path))
    assert getattr(params, key) == good
    with pytest.raises(ParameterError, match="hook_friction_angle"):
        TankParams(hook_friction_angle=float("nan"))
    with pytest.raises(ParameterError, match="hook_friction_static_ratio"):
        TankParams(hook_friction_static_ratio=float("nan"))
    with pytest.raises(ParameterError, match="hook_friction_stribeck_rate"):
        TankParams(hook_friction_stribeck_rate=0.0)
    with pytest.raises(ParameterError, match="hook_friction_roll_ratio"):
        TankParams(hook_friction_roll_ratio=float("inf"))
    with pytest.raises(ParameterError, match="hook_friction_wrap"):
        TankParams(hook_friction_wrap=float("nan"))


@pytest.mark.parametrize("value, message", [([0.0, 0.0, 0.96], "imu.imu_field_residual"),
                                            ([0.0, "x", 0.0], "imu.imu_field_residual"),
                                            ([0.7, 0.7, 0.0], "norm at most"), ([0.0, 0.0], "imu.imu_field_residual")])
def test_the_imu_field_residual_key_is_checked(tmp_path, value, message: str) -> None:
    """tank.yaml's imu.imu_field_residual: off (zeros) by default; a component past 0.95 of the earth's horizontal
    field, a norm past it (some headings would have no true one) or a malformed vector is refused."""
    import yaml
    with open(config_path("tank.yaml")) as stream:
        tree = yaml.safe_load(stream)
    assert tree["imu"]["imu_field_residual"] == [0.0, 0.0, 0.0]
    assert not load_tank_params().heading_disturbed and TankModel(load_robot_params(), load_tank_params()).imu_field_residual is None
    tree["imu"]["imu_field_residual"] = value
    path = tmp_path / "tank.yaml"
    path.write_text(yaml.safe_dump(tree))
    with pytest.raises(ParameterError, match=message):
        load_tank_params(str(path))
    tree["imu"]["imu_field_residual"] = [0.1, -0.4, 0.5]
    path.write_text(yaml.safe_dump(tree))
    params = load_tank_params(str(path))
    assert params.imu_field_residual == (0.1, -0.4, 0.5) and params.heading_disturbed
    np.testing.assert_array_equal(TankModel(load_robot_params(), params).imu_field_residual, [0.1, -0.4, 0.5])


# ---- the tether bent where it leaves the body --------------------------------------------------------------

def test_the_tether_is_off_unless_configured_and_no_stiffness_is_todays_model_to_the_bit() -> None:
    """tank.yaml ships the tether off; both stiffnesses 0 with any relaxation time steps as without it, and a
    vanishing bend tends to it."""
    assert TANK.tether_stiffness == TANK.tether_relaxing_stiffness == 0.0
    assert not TankModel(ROBOT, TANK).bends_tether
    _, today = _hang(TankModel(ROBOT, TANK), 30.0, 3.0)
    _, timed = _hang(TankModel(ROBOT, TANK.with_values(tether_relaxation_time=0.5)), 30.0, 3.0)
    _, faint = _hang(TankModel(ROBOT, TANK.with_values(tether_relaxing_stiffness=1e-9, tether_stiffness=1e-9)), 30.0,
                     3.0)
    for a, b, c in zip(today, timed, faint):
        np.testing.assert_array_equal(a.rotation, b.rotation)
        np.testing.assert_array_equal(a.omega, b.omega)
        np.testing.assert_allclose(c.rotation, a.rotation, atol=1e-8)


@pytest.mark.parametrize("values", [{"tether_stiffness": 0.05}, {"tether_relaxing_stiffness": 0.05,
                                                                  "tether_relaxation_time": 1e4}])
def test_a_bent_tether_swings_the_robot_back_with_its_period_and_keeps_the_energy(values) -> None:
    """Small roll, nothing else acting: theta'' = -(k / I_xx) theta, period 2 pi sqrt(I_xx / k), for the
    elastic branch and for a relaxing one that relaxes far slower than it swings; the energy (1/2 I w^2 plus
    the bend's) stays. The paws are made neutral, so that their buoyancy's moment does not swing the body too."""
    model = TankModel(ROBOT, BARE.with_values(paw_buoyancy_offset=-float(ROBOT.paw_net_buoyancy), **values))
    model.attach(RigidBodyState())
    start = RigidBodyState(rotation=rpy_to_rot(math.radians(10.0), 0.0, 0.0))
    period = 2.0 * math.pi * math.sqrt(float(model.body_mass_matrix[3, 3]) / 0.05)
    states = _spin(model, start, 0.75 * period)
    roll = np.array([math.atan2(s.rotation[2, 1], s.rotation[2, 2]) for s in states])
    crossing = np.flatnonzero(np.diff(np.sign(roll)) != 0)[0]
    t_cross = DT * (crossing + roll[crossing] / (roll[crossing] - roll[crossing + 1]))
    assert t_cross == pytest.approx(0.25 * period, rel=2e-3)
    assert np.min(roll) == pytest.approx(-math.radians(10.0), rel=2e-3)
    if "tether_stiffness" in values:
        q = nominal_joint_angles(ROBOT)
        energy = [model.kinetic_energy(s, q) + model.potential_energy(s, q) for s in states]
        assert np.ptp(energy) < 1e-6 * 0.5 * 0.05 * math.radians(10.0) ** 2


def test_a_relaxing_tether_takes_energy_out_of_the_swing() -> None:
    """The relaxing branch with a relaxation time near the swing's period is a damper (the standard linear
    solid's loss peak): the swing's energy, the relaxing bend's included, only falls."""
    model = TankModel(ROBOT, BARE.with_values(paw_buoyancy_offset=-float(ROBOT.paw_net_buoyancy), tether_stiffness=0.02,
                                              tether_relaxing_stiffness=0.05, tether_relaxation_time=1.0))
    model.attach(RigidBodyState())
    q = nominal_joint_angles(ROBOT)
    state, energy = RigidBodyState(rotation=rpy_to_rot(math.radians(10.0), 0.0, 0.0)), []
    for _ in range(1000):
        state = model.step(state, q, np.zeros((4, 3)), DT)
        energy.append(model.kinetic_energy(state, q) + model.potential_energy(state, q))
    assert np.all(np.diff(energy) < 1e-12)
    assert energy[-1] < 0.5 * energy[0]


def test_the_tether_holds_a_tilt_back_then_lets_it_go_and_attach_relaxes_it() -> None:
    """On the tank plant at rest at a 20 deg roll: attached there, the tether is relaxed and only the elastic
    branch pulls; attached upright, both branches pull back; held at the tilt, the relaxing branch fades
    with its relaxation time."""
    roll = math.radians(20.0)
    R = rpy_to_rot(roll, 0.0, 0.0)
    q = nominal_joint_angles(ROBOT)
    plain = TankModel(ROBOT, TANK)
    model = TankModel(ROBOT, TANK.with_values(tether_stiffness=0.02, tether_relaxing_stiffness=0.1,
                                              tether_relaxation_time=4.0))
    np.testing.assert_allclose(model.restoring_torque(R, q) - plain.restoring_torque(R, q), (-0.02 * roll, 0.0, 0.0),
                               atol=1e-12)
    held = RigidBodyState(rotation=R)
    for plant in (plain, model):
        plant.attach(RigidBodyState())  # the rope and the tether hang from the upright body
    bare = plain.held_wrench(held, q, np.zeros((4, 3)))[3:]
    np.testing.assert_allclose(model.held_wrench(held, q, np.zeros((4, 3)))[3:] - bare, (-0.12 * roll, 0.0, 0.0),
                               atol=1e-12)
    for _ in range(400):  # 4 s held at the tilt: one relaxation time
        model._relax_tether(tuple(R.ravel().tolist()), DT)  # noqa: SLF001 -- the plant's own carry of s
    np.testing.assert_allclose(model.held_wrench(held, q, np.zeros((4, 3)))[3:] - bare,
                               (-(0.02 + 0.1 * math.exp(-1.0)) * roll, 0.0, 0.0), atol=1e-12)


@pytest.mark.parametrize("key, value, message", [("tether_stiffness", -0.01, "tether.tether_stiffness"),
                                                 ("tether_stiffness", 2.5, "tether.tether_stiffness"),
                                                 ("tether_relaxing_stiffness", "x", "tether.tether_relaxing_stiffness"),
                                                 ("tether_relaxing_stiffness", 3.0, "tether.tether_relaxing_stiffness"),
                                                 ("tether_relaxation_time", 0.05, "tether.tether_relaxation_time"),
                                                 ("tether_relaxation_time", 2e4, "tether.tether_relaxation_time"),
                                                 ("bend", 0.1, "bend")])
def test_the_tether_keys_are_checked(tmp_path, key: str, value, message: str) -> None:
    """tank.yaml's tether section: off by default; a value out of its bounds (a unit slip, a relaxation
    faster than ten steps) or an unknown key is refused by name, good values reach TankParams."""
    import yaml
    with open(config_path("tank.yaml")) as stream:
        tree = yaml.safe_load(stream)
    assert tree["tether"] == {"tether_stiffness": 0.0, "tether_relaxing_stiffness": 0.0, "tether_relaxation_time": 10.0}
    tree["tether"][key] = value
    path = tmp_path / "tank.yaml"
    path.write_text(yaml.safe_dump(tree))
    with pytest.raises(ParameterError, match=message):
        load_tank_params(str(path))
    tree["tether"] = {"tether_stiffness": 0.01, "tether_relaxing_stiffness": 0.2, "tether_relaxation_time": 30.0}
    path.write_text(yaml.safe_dump(tree))
    params = load_tank_params(str(path))
    assert params.tether_stiffness == 0.01 and params.tether_relaxing_stiffness == 0.2
    assert params.tether_relaxation_time == 30.0
    for field, bad in (("tether_stiffness", float("nan")), ("tether_relaxing_stiffness", -1.0),
                       ("tether_relaxation_time", float("inf"))):
        with pytest.raises(ParameterError, match=field):
            TankParams(**{field: bad})


# ---- the constants the compiled kernels read ----------------------------------------------------------------

def test_the_constants_are_the_named_fields_and_a_step_carries_the_twist_and_the_relaxed_tilt_in_theirs() -> None:
    """TANK_CONSTANT_FIELDS names every field of the constants in order (the batch's arrays and the per-trial
    plant's replacements read it), tank_forces unpacks exactly that many, and a step writes the rope's twist
    and the tether's relaxed tilt into their named fields, leaving every other field as it was."""
    import inspect
    from quadruped_control.sim.plants import tank_dynamics
    from quadruped_control.sim.plants.tank_dynamics import TANK_CONSTANT_AT, TANK_CONSTANT_FIELDS

    sizes = {"drag": 8, "hook": 3, "anchor": 6, "rope": 3, "torsion": 6, "untwisted": 9, "linear": 3, "quadratic": 3,
             "body_m": 36, "tether": 6}
    model = TankModel(ROBOT, TANK.with_values(rope_torsion_stiffness=0.01, rope_torsion_relaxing_stiffness=0.02,
                                              rope_torsion_relaxation_time=3.0, tether_relaxing_stiffness=0.05,
                                              tether_relaxation_time=2.0))
    assert model.counts_twist and model.relaxes_twist and model.bends_tether
    model.attach(RigidBodyState())
    before = model.constants()
    assert len(before) == len(TANK_CONSTANT_FIELDS) == len(set(TANK_CONSTANT_FIELDS))
    for name, size in sizes.items():
        assert len(before[TANK_CONSTANT_AT[name]]) == size, name
    source = inspect.getsource(tank_dynamics.tank_forces)
    unpacked = source[source.index("    (drag_constant,"):source.index(") = k")]
    assert unpacked.count(",") + 1 == len(TANK_CONSTANT_FIELDS)
    q = nominal_joint_angles(ROBOT)
    state = RigidBodyState(rotation=rpy_to_rot(0.3, 0.0, 0.0), omega=np.array([0.0, 0.0, 0.5]))
    model.step(state, q, np.zeros_like(q), DT)
    after = model.constants()
    changed = {name for name, a, b in zip(TANK_CONSTANT_FIELDS, before, after) if a != b}
    assert changed == {"torsion", "untwisted", "tether"}
    torsion = before[TANK_CONSTANT_AT["torsion"]]
    assert after[TANK_CONSTANT_AT["torsion"]] == torsion[:2] + (model.twist,) + torsion[3:5] + (model.twist_relaxed,)
    assert torsion[5] == 0.0 and 0.0 != abs(model.twist_relaxed) < abs(model.twist)
    assert model.twist != 0.0 and after[TANK_CONSTANT_AT["untwisted"]] == model.twist_rotation
    assert after[TANK_CONSTANT_AT["tether"]] == before[TANK_CONSTANT_AT["tether"]][:3] + tuple(model.tether_relaxed)


# ---- the tank's disturbance ------------------------------------------------------------------------------

def test_the_disturbance_is_an_ornstein_uhlenbeck_process_stepped_exactly() -> None:
    """disturbance_update with disturbance_coefficients: the stationary variance sigma^2 is kept exactly by
    every step (decay^2 sigma^2 + spread^2 = sigma^2), two steps of dt decay as one of 2 dt, and a long run
    has the stationary standard deviation and the autocorrelation exp(-lag / tau_d)."""
    from quadruped_control.sim.plants.tank_dynamics import disturbance_coefficients, disturbance_update

    sigma, tau = 0.004, 0.5
    decay, spread = disturbance_coefficients(sigma, tau, DT)
    assert decay ** 2 * sigma ** 2 + spread ** 2 == pytest.approx(sigma ** 2, rel=1e-12)
    assert disturbance_coefficients(sigma, tau, 2 * DT)[0] == pytest.approx(decay ** 2, rel=1e-12)
    rng = np.random.default_rng(3)
    torque, samples = sigma * rng.standard_normal(3), []
    for noise in rng.standard_normal((200000, 3)):
        torque = disturbance_update(torque, decay, spread, noise)
        samples.append(torque)
    series = np.array(samples)  # 4,000 correlation times, three axes
    assert np.std(series, axis=0) == pytest.approx([sigma] * 3, rel=0.04)
    lag = int(round(tau / DT))
    correlation = np.mean(series[lag:] * series[:-lag], axis=0) / np.var(series, axis=0)
    np.testing.assert_allclose(correlation, math.exp(-1.0), atol=0.04)
    assert np.array_equal(disturbance_update(torque, 1.0, 0.0, np.ones(3)), torque)  # no decay, no spread: held


def test_a_still_tank_is_todays_model_and_a_disturbed_one_repeats_with_its_seed() -> None:
    """sigma = 0 is today's plant bit for bit whatever the other two keys; sigma > 0 runs the same disturbance
    with the same seed (and again after attach), another with another seed, and moves the body."""
    start = RigidBodyState(rotation=rpy_to_rot(0.2, -0.1, 0.4))

    def run(tank: TankParams, seconds: float = 3.0) -> np.ndarray:
        model = TankModel(ROBOT, tank)
        model.attach(start)
        return _spin(model, start, seconds)[-1].rotation

    today = run(TANK)
    assert np.array_equal(run(TANK.with_values(disturbance_correlation_time=0.3, disturbance_seed=5)), today)
    pushed = TANK.with_values(disturbance_torque_std=0.01, disturbance_correlation_time=2.0, disturbance_seed=5)
    first = run(pushed)
    assert np.array_equal(run(pushed), first)
    assert not np.array_equal(run(pushed.with_values(disturbance_seed=6)), first)
    assert np.degrees(np.arccos((np.trace(first.T @ today) - 1.0) / 2.0)) > 0.1
    model = TankModel(ROBOT, pushed)
    model.attach(start)
    assert np.linalg.norm(model.disturbance) > 0.0  # a stationary start, not zero
    started = model.disturbance.copy()
    _spin(model, start, 0.5)
    model.attach(start)
    assert np.array_equal(model.disturbance, started)


def test_the_disturbance_turns_a_free_body_as_its_torque_says() -> None:
    """Nothing else acting (no rope, hydrostatics, added mass or drag; neutral paws), a body at rest under the
    disturbance gains the world angular momentum R I omega = sum of its held torques times dt (to 0.1 %: the
    torque is held in body axes at each step's start and turns with the body within the step)."""
    neutral_paws = dataclasses.replace(ROBOT, paw_mass=ROBOT.rho * ROBOT.paw_volume)
    tank = BARE.with_values(disturbance_torque_std=0.02, disturbance_correlation_time=1.0, disturbance_seed=1)
    model = TankModel(neutral_paws, tank)
    state = RigidBodyState()
    model.attach(state)
    q = nominal_joint_angles(neutral_paws)
    impulse = np.zeros(3)
    inertia = model.body_mass_matrix[3:, 3:]
    for _ in range(50):
        impulse += model.disturbance * DT
        state = model.step(state, q, np.zeros((4, 3)), DT)
    momentum = state.rotation @ inertia @ state.omega
    assert np.linalg.norm(impulse) > 1e-4
    np.testing.assert_allclose(momentum, impulse, rtol=0.0, atol=1e-3 * np.linalg.norm(impulse))


@pytest.mark.parametrize("key, value", [("disturbance_torque_std", -0.001), ("disturbance_torque_std", 1.0),
                                        ("disturbance_correlation_time", 0.01), ("disturbance_seed", -1),
                                        ("disturbance_seed", 1.5), ("disturbance_seed", True), ("colour", 1)])
def test_the_disturbance_keys_are_checked(tmp_path, key, value) -> None:
    import yaml
    with open(config_path("tank.yaml")) as stream:
        tree = yaml.safe_load(stream)
    assert load_tank_params(tree=tree).disturbance_torque_std == 0.0  # the shipped tank is still
    tree["disturbance"] = {"disturbance_torque_std": 0.003, "disturbance_correlation_time": 20.0, "disturbance_seed": 4}
    params = load_tank_params(tree=tree)
    assert (params.disturbance_torque_std, params.disturbance_correlation_time, params.disturbance_seed) == \
        (0.003, 20.0, 4) and params.disturbed
    tree["disturbance"][key] = value
    with pytest.raises(ParameterError, match="disturbance"):
        load_tank_params(tree=tree)
    with pytest.raises(ParameterError, match="disturbance_seed"):
        TankParams(disturbance_seed=-2)
