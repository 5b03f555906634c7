"""Fuzz properties of the control path (issue 10): bounded hypothesis runs that keep these true:

* the controller never produces or keeps a NaN, for any input sequence and any gains and steps the
  interfaces allow; its integral stays within the limit;
* the anti-windup update is non-expansive (two integral states never drift apart) for every gain in the
  reconfigure range and every step up to max_step, including k_i 20, k_aw 10 and steps >= 12.5 ms that
  diverged with the explicit scheme;
* the supervisor never lets an implausible or non-fresh IMU sample reach the controller;
* a non-finite stamp or clock is never fresh;
* a live update (reconfigure) is applied whole or refused with a ParameterError, never another error;
* a mutated configuration file loads or is refused with a ParameterError naming the file.
"""
import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.config import ParameterError, config_path
from quadruped_common.imu_plausibility import SensorLimits
from quadruped_common.monitoring import imu_values_problem, time_problem
from quadruped_common.so3 import quat_to_rot
from quadruped_common.tunables import TUNABLES, bounds
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import Gains, apply_tunables, load_controller_config
from quadruped_control.control.supervisor import ControlSupervisor
from quadruped_control.model.kinematics import within_limits
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.config_files import LOADERS

ROBOT = load_robot_params()
BASE = load_controller_config(gain_set="experiment")
LIMITS = bounds()
LIMITS_IMU = SensorLimits()

any_float = st.floats(allow_nan=True, allow_infinity=True)
unit_quaternion = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1).map(lambda q: np.asarray(q) / np.linalg.norm(q))


def tunable(name):
    low, high = LIMITS[name]
    return st.floats(low, high)


gain_sets = st.builds(Gains, k_p=tunable("k_p"), k_i=tunable("k_i"), k_d=tunable("k_d"), k_aw=tunable("k_aw"))


def controller(gains, tau_max=2.0):
    return AttitudeController(ROBOT, BASE.with_gains(gains).replace(tau_max=tau_max))


@settings(max_examples=40, deadline=None)
@given(gains=gain_sets, tau_max=tunable("tau_max"),
       steps=st.lists(st.tuples(st.floats(-0.05, 0.1), unit_quaternion,
                                st.lists(st.floats(-40.0, 40.0), min_size=3, max_size=3)), min_size=1, max_size=40))
def test_controller_never_produces_or_keeps_nan(gains, tau_max, steps):
    ctl = controller(gains, tau_max)
    ctl.set_setpoint(quat_to_rot(np.array([0.3, -0.2, 0.5, 0.78]) / np.linalg.norm([0.3, -0.2, 0.5, 0.78])))
    t = 0.0
    for dt, q, omega in steps:
        t += dt
        try:
            out = ctl.step(t, quat_to_rot(q), omega)
        except ValueError:
            assert np.max(np.abs(omega)) > ctl.config.max_angular_rate
            out = ctl.hold(t, "rate beyond range")
        state = out.state
        for vector in (state.e_R, state.tau_cmd, state.tau_sat, state.integral, state.tau_feedforward,
                       state.foot_targets, out.joint_targets):
            assert np.all(np.isfinite(vector))
        assert np.linalg.norm(state.integral) <= ctl.config.integral_limit * (1 + 1e-12)
        assert np.linalg.norm(state.tau_sat) <= tau_max * (1 + 1e-12)
        assert all(within_limits(qj, ROBOT, tol=1e-9) for qj in out.joint_targets)


@settings(max_examples=30, deadline=None)
@given(gains=gain_sets, h=st.floats(0.0, BASE.max_step), angle=st.floats(0.0, math.pi),
       z0=st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3),
       z1=st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3))
def test_anti_windup_update_is_non_expansive(gains, h, angle, z0, z1):
    """Two integral states fed the same measurements never move apart (controller docstring's proof)."""
    a, b = controller(gains), controller(gains)
    a._integral, b._integral = tuple(z0), tuple(z1)
    R = quat_to_rot(np.array([math.sin(angle / 2), 0.0, 0.0, math.cos(angle / 2)]))
    omega = np.array([0.3, -0.1, 0.2])
    gap = np.linalg.norm(np.subtract(z0, z1))
    for k in range(20):
        t = k * h
        a.step(t, R, omega)
        b.step(t, R, omega)
        new_gap = np.linalg.norm(np.subtract(a._integral, b._integral))
        assert new_gap <= gap * (1 + 1e-9) + 1e-12
        gap = new_gap


@pytest.mark.parametrize("h", [0.0125, 0.02, 0.05])
def test_extreme_reconfigure_gains_stay_bounded_where_the_explicit_scheme_diverged(h):
    """k_i 20, k_aw 10 (reconfigure maxima) with steps of 12.5..50 ms: the explicit anti-windup passed 1e6
    in under a second; now the integral settles without oscillating and the output stays finite."""
    gains = Gains(k_p=LIMITS["k_p"][1], k_i=LIMITS["k_i"][1], k_d=LIMITS["k_d"][1], k_aw=LIMITS["k_aw"][1])
    ctl = AttitudeController(ROBOT, BASE.with_gains(gains).replace(max_step_factor=10.0, buoyancy_feedforward=False))
    R = quat_to_rot(np.array([math.sin(0.6), 0.0, 0.0, math.cos(0.6)]))
    history = []
    for k in range(int(30.0 / h)):  # 30 s
        out = ctl.step(k * h, R, np.zeros(3))
        history.append(out.state.integral.copy())
        assert np.all(np.isfinite(out.state.tau_cmd))
    history = np.array(history)
    assert np.max(np.abs(history)) <= ctl.config.integral_limit
    np.testing.assert_allclose(history[-1], history[-2], atol=1e-9)  # converged (no feedforward: fixed point), no limit cycle


rates = st.lists(st.one_of(st.floats(-40.0, 40.0), st.sampled_from([1e3, -1e6, 3.4e38, 1e154, math.nan, math.inf])),
                 min_size=3, max_size=3)
quaternions = st.one_of(unit_quaternion, st.lists(any_float, min_size=4, max_size=4))
accelerations = st.lists(st.one_of(st.floats(-200.0, 200.0), any_float), min_size=3, max_size=3)
stamps = st.one_of(st.floats(-0.1, 0.1), st.sampled_from([math.nan, math.inf, -math.inf, 1e300]))


@settings(max_examples=40, deadline=None)
@given(samples=st.lists(st.tuples(quaternions, rates, accelerations, stamps,
                                  st.sampled_from([0.0, math.nan, math.inf])), min_size=1, max_size=30))
def test_no_unusable_imu_sample_reaches_the_controller(samples):
    ctl = AttitudeController(ROBOT, BASE)
    used = []
    original_step = ctl.step

    def recording_step(t, R, omega):
        used.append((R.copy(), np.array(omega, dtype=float)))
        return original_step(t, R, omega)

    ctl.step = recording_step
    supervisor = ControlSupervisor(ctl, lambda angles: np.clip(1500.0 + 600.0 * angles, 500.0, 2500.0), armed=True)
    accepted = []
    for k, (q, w, a, stamp_offset, clock_fault) in enumerate(samples):
        now = 0.01 * k + clock_fault
        stamp = 0.01 * k + stamp_offset
        if supervisor.set_imu(q, w, stamp, a) is None:
            accepted.append((np.asarray(q, dtype=float), np.asarray(w, dtype=float), stamp))
        before = len(used)
        output = supervisor.tick(0.01 * k, now)
        assert np.all(np.isfinite(output.pulse_widths_us))
        if len(used) > before:
            q_used, w_used, stamp_used = accepted[-1]
            assert imu_values_problem(q_used, w_used, None, LIMITS_IMU) is None
            assert time_problem(stamp_used, now, supervisor.max_imu_age) is None
            assert math.isfinite(now) and math.isfinite(stamp_used)
            np.testing.assert_array_equal(used[-1][1], w_used)


@given(stamp=any_float, now=any_float, max_age=st.floats(1e-3, 1.0))
def test_non_finite_time_is_never_fresh(stamp, now, max_age):
    problem = time_problem(stamp, now, max_age)
    if not (math.isfinite(stamp) and math.isfinite(now)):
        assert problem is not None and "not finite" in problem
    elif problem is None:
        assert abs(now - stamp) <= max_age


@settings(max_examples=60, deadline=None)
@given(values=st.fixed_dictionaries({t.name: st.one_of(st.floats(t.low, t.high), any_float) for t in TUNABLES}))
def test_live_update_is_applied_whole_or_refused(values):
    try:
        config = apply_tunables(BASE, values)
    except ParameterError:
        return
    for t in TUNABLES:
        got = getattr(config.gains if t.name.startswith("k_") else config, t.name)
        assert t.low <= got <= t.high and got == values[t.name]


CONFIG_FILES = ("robot.yaml", "controller.yaml", "hardware.yaml", "servo_calibration.yaml", "simulation.yaml",
                "vn100.yaml")
MUTANT_VALUES = st.one_of(any_float, st.integers(-10 ** 400, 10 ** 400), st.booleans(), st.none(),
                          st.text(max_size=5), st.lists(st.floats(allow_nan=True), max_size=4))


def _leaves(tree, path=()):
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from _leaves(value, path + (key,))
    elif isinstance(tree, list):
        for index, value in enumerate(tree):
            yield from _leaves(value, path + (index,))
    yield path


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(CONFIG_FILES), pick=st.integers(0, 10 ** 6), value=MUTANT_VALUES,
       duplicate=st.booleans())
def test_mutated_config_loads_or_is_refused_naming_the_file(tmp_path_factory, name, pick, value, duplicate):
    text = open(config_path(name)).read()
    tree = yaml.safe_load(text)
    paths = [p for p in _leaves(tree) if p]
    path = paths[pick % len(paths)]
    node = tree
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    mutated = yaml.safe_dump(tree, sort_keys=False) if not duplicate else text + "\n%s: 1\n" % next(iter(tree))
    target = tmp_path_factory.mktemp("cfg") / name
    target.write_text(mutated)
    try:
        LOADERS[name](str(target))
    except ParameterError as exc:
        assert str(exc).startswith(str(target))
