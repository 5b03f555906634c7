"""Leg kinematics (quadruped_control.model.kinematics): FK/IK round trips, workspace, hip wrap, Jacobians."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from quadruped_common.robot import LEGS, JointLimits
from quadruped_common.so3 import exp_so3, hat, quat_to_rot
from quadruped_control.model.kinematics import (UnreachableError, _five_bar_closure, _five_bar_rates, body_to_leg, clamp_to_limits, five_bar_fk,
                                                five_bar_ik, five_bar_jacobian, floating_base_jacobian,
                                                foot_jacobian, foot_position, joint_angles, joint_angles_floats,
                                                joint_angles_full, leg_fk, leg_ik_full, leg_kinematics,
                                                leg_kinematics_rows, leg_row, within_limits, wrap_into_range)
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.simulation import nominal_joint_angles

PARAMS = load_robot_params()
GEOM = PARAMS.five_bar
LIM = PARAMS.joint_limits
SETTINGS = settings(max_examples=150, deadline=None)

legs = st.sampled_from(LEGS)
theta1s = st.floats(*LIM.theta1)
theta2s = st.floats(*LIM.theta2)
theta3s = st.floats(*LIM.theta3)


def elbows_out(theta1, theta2):
    """True if (theta1, theta2) is in the IK's working mode (theta4 >= 0, theta5 <= 0), away from singularity."""
    _, _, _, theta4, theta5 = five_bar_fk(theta1, theta2, GEOM)
    return 1e-3 < theta4 < math.pi - 1e-3 and -math.pi + 1e-3 < theta5 < -1e-3


def central_difference(f, x, h=1e-6):
    x = np.asarray(x, dtype=float)
    cols = []
    for k in range(x.size):
        step = np.zeros_like(x)
        step[k] = h
        cols.append((np.asarray(f(x + step)) - np.asarray(f(x - step))) / (2.0 * h))
    return np.column_stack(cols)


# --------------------------------------------------------------------------------------------------
# Five-bar
# --------------------------------------------------------------------------------------------------

def test_five_bar_nominal_example_by_hand():
    # Foot on the symmetry line x = c/2: elbows-out solution is mirror symmetric, theta1 + theta2 = -pi.
    x, y = 0.5 * GEOM.c, -0.13
    t1, t2, t4, t5 = five_bar_ik(x, y, GEOM)
    assert t1 + t2 == pytest.approx(-math.pi, abs=1e-12)
    assert t4 == pytest.approx(-t5, abs=1e-12)
    elbow1 = np.array([GEOM.a1 * math.cos(t1), GEOM.a1 * math.sin(t1)])
    assert elbow1[0] < 0.0  # elbow of motor 1 outwards (-x), i.e. "elbows out"
    assert np.linalg.norm(np.array([x, y]) - elbow1) == pytest.approx(GEOM.a3, abs=1e-12)


@SETTINGS
@given(theta1s, theta2s)
def test_five_bar_fk_then_ik_round_trip(theta1, theta2):
    assume(elbows_out(theta1, theta2))
    x, y, phi, t4, t5 = five_bar_fk(theta1, theta2, GEOM)
    # The passive links really have their lengths.
    assert math.hypot(x - GEOM.a1 * math.cos(theta1), y - GEOM.a1 * math.sin(theta1)) == pytest.approx(GEOM.a3)
    assert math.hypot(x - GEOM.c - GEOM.a2 * math.cos(theta2), y - GEOM.a2 * math.sin(theta2)) == \
        pytest.approx(GEOM.a4)
    assert phi == pytest.approx(math.remainder(theta2 + t5, 2 * math.pi), abs=1e-9)
    i1, i2, i4, i5 = five_bar_ik(x, y, GEOM)
    assert wrap_into_range(i1, *LIM.theta1) == pytest.approx(theta1, abs=1e-8)
    assert wrap_into_range(i2, *LIM.theta2) == pytest.approx(theta2, abs=1e-8)
    assert (i4, i5) == pytest.approx((t4, t5), abs=1e-8)


@SETTINGS
@given(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2))
def test_five_bar_ik_then_fk_round_trip_or_unreachable(x, y):
    try:
        t1, t2, t4, t5 = five_bar_ik(x, y, GEOM)
    except UnreachableError as exc:
        d13, d24 = math.hypot(x, y), math.hypot(x - GEOM.c, y)
        assert not (GEOM.a3 - GEOM.a1 < d13 < GEOM.a1 + GEOM.a3 and GEOM.a4 - GEOM.a2 < d24 < GEOM.a2 + GEOM.a4)
        assert "out of reach" in str(exc)
        return
    assert 0.0 <= t4 <= math.pi and -math.pi <= t5 <= 0.0
    fx, fy, _, f4, f5 = five_bar_fk(t1, t2, GEOM)
    assert (fx, fy) == pytest.approx((x, y), abs=1e-9)  # the printed "+" root of eq. (fk_phi) matches
    assume(0.0 < t4 < math.pi and -math.pi < t5 < 0.0)  # away from the +-pi wrap of the passive angles
    assert (f4, f5) == pytest.approx((t4, t5), abs=1e-7)


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi))
def test_five_bar_fk_is_one_assembly_mode(theta1, theta2):
    """The "+" root always puts the foot on the same side of the elbow-to-elbow line (no mode flips)."""
    x, y, _, _, _ = five_bar_fk(theta1, theta2, GEOM)
    ax, ay = GEOM.a1 * math.cos(theta1), GEOM.a1 * math.sin(theta1)
    bx, by = GEOM.c + GEOM.a2 * math.cos(theta2), GEOM.a2 * math.sin(theta2)
    cross = (bx - ax) * (y - ay) - (by - ay) * (x - ax)
    assert cross <= 1e-12


def test_five_bar_fk_raises_when_the_mechanism_cannot_close():
    short = dataclasses.replace(GEOM, a3=0.05, a4=0.05)  # elbows up to 0.19 m apart, passive reach 0.1 m
    with pytest.raises(UnreachableError, match="cannot close"):
        five_bar_fk(-math.pi, 0.0, short)
    with pytest.raises(UnreachableError, match="finite"):
        five_bar_fk(math.nan, 0.0, GEOM)


@pytest.mark.parametrize("target", [(0.015, -0.25), (0.015, -0.0), (0.0, 0.0), (0.03, 0.0), (0.3, 0.3)])
def test_five_bar_ik_rejects_out_of_reach(target):
    with pytest.raises(UnreachableError):
        five_bar_ik(target[0], target[1], GEOM)


def test_five_bar_ik_accepts_the_exact_boundary():
    # Both chains fully stretched on the symmetry line: d13 = d24 = a1 + a3 (up to rounding).
    reach = GEOM.a1 + GEOM.a3
    x, y = 0.5 * GEOM.c, -math.sqrt(reach ** 2 - (0.5 * GEOM.c) ** 2)
    t1, t2, t4, t5 = five_bar_ik(x, y, GEOM)
    assert t1 == pytest.approx(math.atan2(y, x), abs=1e-6) and t4 == pytest.approx(0.0, abs=1e-6)
    assert t2 == pytest.approx(math.atan2(y, x - GEOM.c), abs=1e-6) and t5 == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(UnreachableError, match="out of reach"):
        five_bar_ik(x, y * (1.0 + 1e-9), GEOM)


@SETTINGS
@given(theta1s, theta2s)
def test_five_bar_jacobian_matches_finite_differences(theta1, theta2):
    _, _, phi, t4, _ = five_bar_fk(theta1, theta2, GEOM)
    assume(abs(math.sin(phi - theta1 - t4)) > 0.05)  # away from the type-2 singularity
    numeric = central_difference(lambda t: five_bar_fk(t[0], t[1], GEOM)[:2], [theta1, theta2])
    np.testing.assert_allclose(five_bar_jacobian(theta1, theta2, GEOM), numeric, atol=1e-6)


def test_five_bar_jacobian_raises_at_singularity():
    # With a3 = a4 the passive links can only align when folded onto each other, i.e. when the elbows
    # A and B coincide: a1 (cos t1 - cos t2) = c, t2 = pi - t1. There phi = psi and the foot is
    # undetermined (type-2 singularity).
    t1 = math.acos(GEOM.c / (2.0 * GEOM.a1))
    with pytest.raises(UnreachableError, match="coincide"):
        five_bar_fk(t1, math.pi - t1, GEOM)
    with pytest.raises(UnreachableError, match="singular|coincide"):
        five_bar_jacobian(t1 + 1e-10, math.pi - t1, GEOM)
    # ... and nowhere near it inside the servo ranges.
    for theta1 in np.linspace(LIM.theta1[0], LIM.theta1[1], 25):
        for theta2 in np.linspace(LIM.theta2[0], LIM.theta2[1], 25):
            assert np.all(np.isfinite(five_bar_jacobian(theta1, theta2, GEOM)))


# --------------------------------------------------------------------------------------------------
# Whole leg
# --------------------------------------------------------------------------------------------------

@SETTINGS
@given(legs, theta1s, theta2s, theta3s)
def test_leg_fk_then_ik_round_trip(leg, theta1, theta2, theta3):
    assume(elbows_out(theta1, theta2))
    # eq. (ik_theta3) takes the hip branch with the foot beyond the hip offset, l_y + y' < 0 (leg
    # pointing away from the hip axis in its plane); the other branch needs the foot above the motors.
    y_prime = five_bar_fk(theta1, theta2, GEOM)[1]
    assume(PARAMS.l_y + y_prime < -1e-3)
    q = np.array([theta1, theta2, theta3])
    r = foot_position(q, leg, PARAMS)
    np.testing.assert_allclose(r, PARAMS.leg_origins[leg] + PARAMS.mirror[leg] @ leg_fk(q, PARAMS), atol=1e-15)
    q_back = joint_angles(r, leg, PARAMS)
    np.testing.assert_allclose(q_back, q, atol=1e-7)
    assert within_limits(q_back, PARAMS)


def reachable_targets():
    """Body-frame targets near each leg's nominal foot (a box larger than the workspace)."""
    offset = st.floats(-0.15, 0.15)
    return st.tuples(legs, offset, offset, offset)


@settings(max_examples=400, deadline=None)
@given(reachable_targets())
def test_ik_then_fk_round_trip_or_unreachable(sample):
    """For any finite target: either UnreachableError, or finite in-limit angles whose FK hits the target."""
    leg, dx, dy, dz = sample
    r = PARAMS.nominal_foot_body(leg) + np.array([dx, dy, dz])
    try:
        q5 = joint_angles_full(r, leg, PARAMS)
    except UnreachableError as exc:
        assert exc.leg == leg and str(exc).startswith("leg %d: " % leg)
        return
    assert np.all(np.isfinite(q5))
    assert within_limits(q5[:3], PARAMS, tol=0.0)
    np.testing.assert_allclose(foot_position(q5[:3], leg, PARAMS), r, atol=1e-9)
    np.testing.assert_array_equal(joint_angles(r, leg, PARAMS), q5[:3])


@settings(max_examples=200, deadline=None)
@given(legs, st.tuples(*[st.floats(-1e6, 1e6)] * 3))
def test_any_finite_target_never_gives_nan(leg, target):
    try:
        q = joint_angles(np.array(target), leg, PARAMS)
    except UnreachableError:
        return
    assert np.all(np.isfinite(q)) and within_limits(q, PARAMS)
    np.testing.assert_allclose(foot_position(q, leg, PARAMS), target, atol=1e-9)


@pytest.mark.parametrize("leg", LEGS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_targets_raise(leg, bad):
    for axis in range(3):
        r = PARAMS.nominal_foot_body(leg).copy()
        r[axis] = bad
        with pytest.raises(UnreachableError, match="leg %d: .*not finite" % leg):
            joint_angles(r, leg, PARAMS)


@pytest.mark.parametrize("leg", LEGS)
def test_targets_at_hip_axis_and_beyond_reach_raise(leg):
    origin = PARAMS.leg_origins[leg]
    with pytest.raises(UnreachableError, match="hip axis"):
        joint_angles(origin, leg, PARAMS)
    # On the hip axis but displaced along it: R = 0 < l_z.
    with pytest.raises(UnreachableError, match="hip axis"):
        joint_angles(origin + np.array([0.05, 0.0, 0.0]), leg, PARAMS)
    far = PARAMS.nominal_foot_body(leg) + np.array([0.0, 0.0, -0.5])
    with pytest.raises(UnreachableError, match="out of reach"):
        joint_angles(far, leg, PARAMS)


def test_bad_leg_and_shape_are_rejected():
    with pytest.raises(ValueError):
        joint_angles(PARAMS.nominal_foot_body(1), 5, PARAMS)
    with pytest.raises(ValueError):
        joint_angles([0.0, 0.0], 1, PARAMS)
    with pytest.raises(ValueError):
        foot_position([0.0, 0.0, 0.0], 0, PARAMS)


def test_servo_range_violation_names_the_joint():
    # theta1 range shifted far away from the nominal foot's theta1 (-140 deg).
    shifted = dataclasses.replace(PARAMS, joint_limits=JointLimits(
        theta1=(math.radians(-20.0), math.radians(100.0)), theta2=LIM.theta2, theta3=LIM.theta3))
    with pytest.raises(UnreachableError, match="leg 2: theta1 .* outside its servo range"):
        joint_angles(PARAMS.nominal_foot_body(2), 2, shifted)


@SETTINGS
@given(legs, st.floats(math.radians(5.0), math.radians(175.0)), st.floats(0.09, 0.17))
def test_hip_wrap_keeps_theta3_in_range(leg, theta3, reach):
    """eq. (ik_theta3) gives theta3 - 2 pi for most hip angles; the result is wrapped into the servo range."""
    # Planar target straight below motor midpoint at distance ``reach``, hip rotated to theta3.
    x_d, y_prime = 0.5 * GEOM.c, -reach
    p = np.array([x_d, 0.0, 0.0])
    u = PARAMS.l_y + y_prime
    p[1] = math.cos(theta3) * u - math.sin(theta3) * PARAMS.l_z
    p[2] = math.sin(theta3) * u + math.cos(theta3) * PARAMS.l_z
    raw = math.atan2(p[2], p[1]) - math.acos(PARAMS.l_z / math.hypot(p[1], p[2])) - math.pi / 2
    # The unwrapped paper formula differs from the servo angle by a multiple of 2 pi (-2 pi for most
    # hip angles, e.g. -270 deg for the nominal foot at theta3 = 90 deg).
    assert abs(math.remainder(raw - theta3, 2 * math.pi)) < 1e-9
    r = PARAMS.leg_origins[leg] + PARAMS.mirror[leg] @ p
    q = joint_angles(r, leg, PARAMS)
    assert LIM.theta3[0] <= q[2] <= LIM.theta3[1]
    assert q[2] == pytest.approx(theta3, abs=1e-9)
    np.testing.assert_allclose(foot_position(q, leg, PARAMS), r, atol=1e-12)


def test_hip_wrap_of_the_nominal_foot():
    p = PARAMS.nominal_foot_leg
    raw = math.atan2(p[2], p[1]) - math.acos(PARAMS.l_z / math.hypot(p[1], p[2])) - math.pi / 2
    assert raw < -math.pi
    q = joint_angles(PARAMS.nominal_foot_body(4), 4, PARAMS)
    assert q[2] == pytest.approx(raw + 2 * math.pi, abs=1e-12)
    assert LIM.theta3[0] <= q[2] <= LIM.theta3[1]


def test_hip_outside_servo_range_raises():
    # theta3 = -90 deg (foot above the hip) is the hip range's gap [180, 360) deg.
    p = np.array([0.5 * GEOM.c, 0.0, 0.0])
    u = PARAMS.l_y - 0.13
    t3 = math.radians(-90.0)
    p[1] = math.cos(t3) * u - math.sin(t3) * PARAMS.l_z
    p[2] = math.sin(t3) * u + math.cos(t3) * PARAMS.l_z
    with pytest.raises(UnreachableError, match="leg 3: hip angle"):
        leg_ik_full(p, PARAMS, leg=3)


def test_wrap_into_range():
    lo, hi = math.radians(-230.0), math.radians(-50.0)
    assert wrap_into_range(math.radians(130.0), lo, hi) == pytest.approx(math.radians(-230.0))
    assert wrap_into_range(math.radians(-100.0), lo, hi) == pytest.approx(math.radians(-100.0))
    assert wrap_into_range(math.radians(-100.0) + 6 * math.pi, lo, hi) == pytest.approx(math.radians(-100.0))
    assert wrap_into_range(math.radians(0.0), lo, hi) is None


# --------------------------------------------------------------------------------------------------
# Jacobians
# --------------------------------------------------------------------------------------------------

def away_from_singularity(theta1, theta2):
    _, _, phi, t4, _ = five_bar_fk(theta1, theta2, GEOM)
    return abs(math.sin(phi - theta1 - t4)) > 0.05


@SETTINGS
@given(legs, theta1s, theta2s, theta3s)
def test_foot_jacobian_matches_finite_differences(leg, theta1, theta2, theta3):
    assume(away_from_singularity(theta1, theta2))
    q = np.array([theta1, theta2, theta3])
    numeric = central_difference(lambda x: foot_position(x, leg, PARAMS), q)
    np.testing.assert_allclose(foot_jacobian(q, leg, PARAMS), numeric, atol=1e-6)


def test_foot_jacobian_matches_printed_structure():
    """eq. (J_leg): M_i [R_x(theta3) [J_fb col, 0], ..., x_hat x p_e^L]."""
    q = joint_angles(PARAMS.nominal_foot_body(1), 1, PARAMS)
    j = five_bar_jacobian(q[0], q[1], GEOM)
    c3, s3 = math.cos(q[2]), math.sin(q[2])
    rx = np.array([[1, 0, 0], [0, c3, -s3], [0, s3, c3]])
    cols = [rx @ np.array([j[0, 0], j[1, 0], 0.0]), rx @ np.array([j[0, 1], j[1, 1], 0.0]),
            np.cross([1.0, 0.0, 0.0], leg_fk(q, PARAMS))]
    np.testing.assert_allclose(foot_jacobian(q, 1, PARAMS), PARAMS.mirror[1] @ np.column_stack(cols), atol=1e-15)


@SETTINGS
@given(legs, theta1s, theta2s, theta3s,
       st.tuples(*[st.floats(-1, 1)] * 4).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_floating_base_jacobian_matches_finite_differences(leg, theta1, theta2, theta3, quat):
    assume(away_from_singularity(theta1, theta2))
    q = np.array([theta1, theta2, theta3])
    R = quat_to_rot(quat)
    p_base = np.array([0.3, -0.2, 1.0])

    def foot_world(u):
        # Base moved by v dt (world), rotated by exp(hat(omega) dt) (body rate), joints by qdot dt.
        return p_base + u[0:3] + R @ exp_so3(u[3:6]) @ foot_position(q + u[6:9], leg, PARAMS)

    numeric = central_difference(foot_world, np.zeros(9))
    J = floating_base_jacobian(q, leg, R, PARAMS)
    assert J.shape == (3, 9)
    np.testing.assert_allclose(J, numeric, atol=1e-6)
    r = foot_position(q, leg, PARAMS)
    np.testing.assert_allclose(J[:, 3:6], -R @ hat(r), atol=1e-15)


def test_floating_base_jacobian_rejects_bad_rotation_shape():
    with pytest.raises(ValueError):
        floating_base_jacobian([-2.4, -0.7, 1.5], 1, np.eye(2), PARAMS)


# --------------------------------------------------------------------------------------------------
# Placement, nominal foot and workspace
# --------------------------------------------------------------------------------------------------

def test_legs_are_placed_as_in_the_paper():
    """Legs 3, 4 front (+x), 1, 2 back; leg-frame y points inwards; feet hang below and outside the hips."""
    for leg in LEGS:
        o = PARAMS.leg_origins[leg]
        assert (o[0] > 0) == (leg in (3, 4))
        inward_body = PARAMS.mirror[leg] @ np.array([0.0, 1.0, 0.0])
        assert np.sign(inward_body[1]) == -np.sign(o[1])
        foot = PARAMS.nominal_foot_body(leg)
        assert foot[2] < o[2]
        assert abs(foot[1]) > abs(o[1])


def workspace_extent(leg, axis, sign, step=0.002, limit=0.3):
    """How far (m) the foot can move from nominal along +-axis (body frame) before IK fails."""
    r0 = PARAMS.nominal_foot_body(leg)
    distance = 0.0
    while distance < limit:
        r = r0.copy()
        r[axis] += sign * (distance + step)
        try:
            joint_angles(r, leg, PARAMS)
        except UnreachableError:
            break
        distance += step
    return distance


@pytest.mark.parametrize("leg", LEGS)
def test_nominal_foot_is_reachable_with_margin(leg):
    r0 = PARAMS.nominal_foot_body(leg)
    q = joint_angles(r0, leg, PARAMS)
    bounds = LIM.as_array()
    margin = np.minimum(q - bounds[:, 0], bounds[:, 1] - q)
    assert np.all(margin > math.radians(30.0)), np.degrees(margin)
    np.testing.assert_allclose(foot_position(q, leg, PARAMS), r0, atol=1e-12)
    # The stroke cycle integrates the foot from here until IK fails: a few cm in every direction.
    for axis in range(3):
        for sign in (1.0, -1.0):
            assert workspace_extent(leg, axis, sign) >= 0.04, (leg, axis, sign)


def test_workspace_is_mirror_symmetric_between_legs():
    for axis in range(3):
        for sign in (1.0, -1.0):
            base = workspace_extent(4, axis, sign)
            for leg in (1, 2, 3):
                body_sign = sign * PARAMS.mirror[leg][axis, axis]
                assert workspace_extent(leg, axis, body_sign) == pytest.approx(base, abs=1e-9)


# --------------------------------------------------------------------------------------------------
# Limits helpers
# --------------------------------------------------------------------------------------------------

def test_within_limits_and_clamp():
    inside = np.array([-2.0, -0.5, 1.0])
    assert within_limits(inside, PARAMS)
    assert not within_limits([0.0, -0.5, 1.0], PARAMS)
    assert not within_limits([-2.0, math.nan, 1.0], PARAMS)
    clamped = clamp_to_limits([0.0, -10.0, 1.0], PARAMS)
    np.testing.assert_allclose(clamped, [LIM.theta1[1], LIM.theta2[0], 1.0])
    assert within_limits(clamped, PARAMS)
    with pytest.raises(ValueError):
        clamp_to_limits([math.inf, 0.0, 0.0], PARAMS)


def test_body_to_leg_inverts_ee_body():
    for leg in LEGS:
        p = np.array([0.01, -0.04, -0.12])
        r = PARAMS.leg_origins[leg] + PARAMS.mirror[leg] @ p
        np.testing.assert_allclose(body_to_leg(r, leg, PARAMS), p, atol=1e-15)


# --------------------------------------------------------------------------------------------------
# Float fast paths against the readable functions
# --------------------------------------------------------------------------------------------------

Q0 = np.array([joint_angles(PARAMS.nominal_foot_body(leg), leg, PARAMS) for leg in LEGS])


@settings(max_examples=60)
@given(st.integers(0, 2 ** 32 - 1))
def test_leg_kinematics_matches_foot_position_and_jacobian(seed) -> None:
    rng = np.random.default_rng(seed)
    q = Q0 + rng.uniform(-0.4, 0.4, (4, 3))
    q_dot = rng.uniform(-5.0, 5.0, (4, 3))
    rows = np.array(leg_kinematics(q.tolist(), q_dot.tolist(), PARAMS))
    for row, leg in enumerate(LEGS):
        np.testing.assert_allclose(rows[row, :3], foot_position(q[row], leg, PARAMS), rtol=0, atol=1e-14)
        np.testing.assert_allclose(rows[row, 3:], foot_jacobian(q[row], leg, PARAMS) @ q_dot[row],
                                   rtol=1e-12, atol=1e-13)
    assert leg_kinematics_rows(q.tolist(), q_dot.tolist(), PARAMS) == tuple(map(tuple, rows.tolist()))


def test_leg_kinematics_raises_the_kinematics_error_for_irregular_input() -> None:
    q = Q0.copy()
    q[2, 0] = np.nan
    with pytest.raises(UnreachableError):
        leg_kinematics(q.tolist(), np.zeros((4, 3)).tolist(), PARAMS)
    # Elbows coincide (a1 cos t1 = c + a1 cos t2, sin t1 = sin t2): the same error as five_bar_fk's.
    elbow = math.acos(0.5 * GEOM.c / GEOM.a1)
    q = Q0.copy()
    q[1, :2] = (elbow, math.pi - elbow)
    with pytest.raises(UnreachableError, match="elbows coincide") as info:
        leg_kinematics_rows(q.tolist(), np.zeros((4, 3)).tolist(), PARAMS)
    with pytest.raises(UnreachableError) as reference:
        five_bar_fk(elbow, math.pi - elbow, GEOM)
    assert str(info.value) == str(reference.value)
    with pytest.raises(ValueError):
        leg_kinematics(Q0[:3].tolist(), np.zeros((3, 3)).tolist(), PARAMS)


@settings(max_examples=300)
@given(st.sampled_from(LEGS), st.tuples(*[st.floats(-0.08, 0.08)] * 3))
def test_joint_angles_floats_equals_reference_ik(leg, offset) -> None:
    target = np.array(PARAMS.nominal_foot_body(leg)) + np.array(offset)
    try:
        expected = joint_angles_full(target, leg, PARAMS)[:3].tolist()
    except UnreachableError as exc:
        with pytest.raises(UnreachableError) as info:
            joint_angles_floats(*target.tolist(), leg, PARAMS)
        assert str(info.value) == str(exc)
        return
    assert list(joint_angles_floats(*target.tolist(), leg, PARAMS)) == expected  # bit for bit
    assert joint_angles(target, leg, PARAMS).tolist() == expected


@pytest.mark.parametrize("target", [(math.nan, 0.0, 0.0), (math.inf, 0.1, 0.1), (0.0, -math.inf, 0.0)])
def test_joint_angles_floats_rejects_non_finite_targets(target) -> None:
    with pytest.raises(UnreachableError):
        joint_angles_floats(*target, 1, PARAMS)


def test_joint_angles_floats_rejects_bad_leg() -> None:
    with pytest.raises(ValueError):
        joint_angles_floats(0.1, 0.1, -0.1, 5, PARAMS)


def test_ik_row_is_joint_angles_floats_and_compiles_to_the_same_angles():
    """ik_row (the float IK core the robot and the compiled batch controller share) against the raising
    float path inside and outside the workspace, and compiled against plain Python."""
    from quadruped_common import jit
    from quadruped_control.model.kinematics import _geometry, ik_row

    robot = PARAMS
    geometry = _geometry(robot)
    frames = np.array(geometry.frame_rows)
    constants = geometry.ik
    rng = np.random.default_rng(3)
    nominal = np.array([robot.nominal_foot_body(leg) for leg in (1, 2, 3, 4)])
    targets = nominal + rng.normal(0.0, 0.04, (300, 4, 3))  # many beyond reach

    def all_rows(targets, frames, constants, out):
        for n in range(targets.shape[0]):
            for leg in range(4):
                ok, t1, t2, t3 = ik_row(targets[n, leg, 0], targets[n, leg, 1], targets[n, leg, 2], frames[leg],
                                        constants)
                out[n, leg, 0], out[n, leg, 1], out[n, leg, 2], out[n, leg, 3] = ok, t1, t2, t3

    plain = np.zeros((300, 4, 4))
    all_rows(targets, frames, constants, plain)
    reached = 0
    for n in range(300):
        for leg in range(4):
            try:
                expected = joint_angles_floats(*targets[n, leg].tolist(), leg + 1, robot)
            except UnreachableError:
                assert not plain[n, leg, 0]
                continue
            if plain[n, leg, 0]:
                reached += 1
                assert tuple(plain[n, leg, 1:]) == expected
    assert 100 < reached < 1200  # both cases exercised
    if jit.AVAILABLE:
        compiled = np.zeros((300, 4, 4))
        jit.kernel(all_rows)(targets, frames, constants, compiled)
        np.testing.assert_array_equal(compiled[..., 0], plain[..., 0])
        np.testing.assert_allclose(compiled[..., 1:], plain[..., 1:], rtol=0, atol=1e-12)


def test_leg_row_flags_five_bars_that_cannot_close_where_the_float_cores_raise():
    """leg_row (the compiled plants' per-leg kinematics) says ok exactly where the raising cores of
    leg_kinematics_rows succeed; with short passive links many motor angles cannot close the five-bar."""
    fb = PARAMS.five_bar
    a1, a2, a3, a4, c = fb.a1, fb.a2, 0.6 * fb.a3, 0.6 * fb.a4, fb.c
    frame = (0.1, 0.2, 0.0, 1.0, 1.0, 1.0)
    rng = np.random.default_rng(7)
    outcomes = set()
    for t1, t2, t3 in rng.uniform(-math.pi, math.pi, (300, 3)):
        ok = leg_row(t1, t2, t3, 0.1, -0.2, 0.3, frame, a1, a2, a3, a4, c, PARAMS.l_y, PARAMS.l_z)[0]
        try:
            _, _, links = _five_bar_closure(t1, t2, a1, a2, a3, a4, c)
            _five_bar_rates(t1, t2, links, a1, a2)  # the singularity check
            closes = True
        except UnreachableError:
            closes = False
        assert ok == closes
        outcomes.add(ok)
    assert outcomes == {True, False}


def test_leg_kinematics_rows_says_why_a_leg_cannot_close():
    """Where leg_row says no, the float path raises the raising cores' error (here: a NaN angle; the
    robot's own five-bar closes at every motor angle)."""
    q = nominal_joint_angles(PARAMS).tolist()
    q[2] = [math.nan, q[2][1], q[2][2]]
    with pytest.raises(UnreachableError, match="finite"):
        leg_kinematics_rows(q, np.zeros((4, 3)).tolist(), PARAMS)
