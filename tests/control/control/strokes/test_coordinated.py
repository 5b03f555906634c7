"""Coordinated stroke scheme and the scheme interface (quadruped_control.control.strokes)."""
import math

import numpy as np
import pytest

from quadruped_common.config import ParameterError
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import controller_config_from_dict, load_controller_config
from quadruped_control.control.strokes import CoordinatedParams, CoordinatedStrokes, StrokeCycle, make_stroke_scheme
from quadruped_control.control.strokes.coordinated import DRAG_OPTIMAL_RECOVERY_RATIO
from quadruped_control.control.strokes.workspace import fibonacci_directions, leg_workspace
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.simulation import ClosedLoopSimulation

PARAMS = load_robot_params()
DT = 0.01


def _in_ranges(joints):
    limits = PARAMS.joint_limits
    for t1, t2, t3 in joints:
        assert limits.theta1[0] <= t1 <= limits.theta1[1]
        assert limits.theta2[0] <= t2 <= limits.theta2[1]
        assert limits.theta3[0] <= t3 <= limits.theta3[1]


def test_make_stroke_scheme_by_name():
    assert isinstance(make_stroke_scheme("paper", PARAMS, ((1, 3), (2, 4)), 1.5, 0.5), StrokeCycle)
    assert isinstance(make_stroke_scheme("coordinated", PARAMS, ((1, 3), (2, 4)), 1.5, 0.5), CoordinatedStrokes)
    with pytest.raises(ParameterError):
        make_stroke_scheme("bogus", PARAMS, ((1, 3), (2, 4)), 1.5, 0.5)


def test_config_reads_the_scheme_and_rejects_bad_values():
    tree = {"gain_sets": {"s": {"k_p": 1.0, "k_i": 0.0, "k_d": 0.0, "k_aw": 0.0}}}
    assert controller_config_from_dict(tree, "s").stroke_scheme == "paper"
    config = controller_config_from_dict(dict(tree, stroke={"scheme": "coordinated",
                                                            "coordinated": {"speed_fraction": 0.5}}), "s")
    assert config.stroke_scheme == "coordinated" and config.coordinated.speed_fraction == 0.5
    for bad in ({"scheme": "fast"}, {"scheme": "paper", "extra": 1}, {"coordinated": {"speed_fraction": 2.0}},
                {"coordinated": {"unknown": 1.0}}, {"coordinated": {"recovery_ratio": math.nan}}):
        with pytest.raises(ParameterError):
            controller_config_from_dict(dict(tree, stroke=bad), "s")


def test_fibonacci_directions_are_unit_and_spread():
    d = fibonacci_directions(64)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert abs(d.mean(axis=0)).max() < 0.05


def test_workspace_best_starts_are_inside_and_reachable():
    ws = leg_workspace(PARAMS, joint_margin=math.radians(5.0), radius=0.035)
    scheme = CoordinatedStrokes(PARAMS)
    for start, chord in zip(ws.start_points[::16], ws.chords[::16]):
        assert ws.inside(*start.tolist()) and chord > 0.0
        for leg in (1, 2, 3, 4):
            body = scheme._to_body(tuple(start.tolist()), leg)
            assert scheme._inside(body, leg) is not None
    # the longest stroke from the best start is at least as long as the one from the nominal point
    nominal = PARAMS.nominal_foot_leg.tolist()
    for direction in fibonacci_directions(20):
        _, best = ws.best_start(*direction)
        assert best + 1e-12 >= ws.chord_from(*nominal, *direction)
    assert ws.best_start(0.0, 0.0, 0.0) == (tuple(nominal), 0.0)


def _closed_loop(scheme="coordinated", rpy=(45.0, 45.0, 45.0), seconds=30.0, servo="rate-limited"):
    config = load_controller_config().replace(stroke_scheme=scheme)
    sim = ClosedLoopSimulation(PARAMS, config, servo, setpoint_R=rpy_to_rot(*np.radians(rpy)))
    return sim, sim.run(seconds)


def test_coordinated_closed_loop_is_safe_alternates_and_turns():
    sim, result = _closed_loop()
    phases = result.pair_phase
    assert not np.any(np.all(phases == "power", axis=1)), "both pairs in power at once"
    assert np.any(phases == "power")
    assert np.all(np.isfinite(result.joint_targets))
    for row in result.joint_targets.reshape(-1, 4, 3):
        _in_ranges(row)
    assert sim.plant.clamped_joints == 0
    # joint steps the rate-limited servos can follow in one period (the recovery plan leaves margin)
    steps = np.abs(np.diff(result.joint_targets, axis=0)).max()
    assert steps <= PARAMS.servo_no_load_speed * DT * 1.0 + 1e-9
    assert math.degrees(result.geodesic[-300:].mean()) < 15.0  # it turned towards the setpoint (from 65 deg)


def test_recovery_ratio_maximises_mean_torque_of_a_leg_cycle():
    # mean torque of one leg per cycle ~ (1/T_p - 1/T_r) / (T_p + T_r), T_p = 1
    ratios = np.linspace(1.01, 10.0, 2000)
    mean = (1.0 - 1.0 / ratios) / (1.0 + ratios)
    assert ratios[np.argmax(mean)] == pytest.approx(DRAG_OPTIMAL_RECOVERY_RATIO, abs=0.01)


def test_hold_returns_to_nominal_without_jumps_and_resumes():
    ctl = AttitudeController(PARAMS, load_controller_config().replace(stroke_scheme="coordinated"))
    ctl.set_setpoint_rpy(0.8, 0.0, 0.0)
    feet = []
    for k in range(150):
        feet.append(ctl.step(k * DT, np.eye(3), np.zeros(3)).state.foot_targets)
    for k in range(150, 400):
        out = ctl.hold(k * DT, "test")
        feet.append(out.state.foot_targets)
        _in_ranges(out.joint_targets)
    assert ctl.stroke.at_rest and out.state.pair_phase == ("hold", "hold")
    assert np.allclose(out.state.foot_targets, np.array(ctl.stroke.nominal))
    out = ctl.step(400 * DT, np.eye(3), np.zeros(3))
    feet.append(out.state.foot_targets)
    jumps = np.linalg.norm(np.diff(np.array(feet), axis=0), axis=2).max()
    assert jumps < 0.03


@pytest.mark.parametrize("first, second", [("paper", "coordinated"), ("coordinated", "paper")])
def test_runtime_switch_is_smooth(first, second):
    ctl = AttitudeController(PARAMS, load_controller_config().replace(stroke_scheme=first))
    ctl.set_setpoint_rpy(0.8, 0.3, 0.0)
    R = np.eye(3)
    feet = []
    reasons = []
    for k in range(600):
        if k == 120:
            ctl.set_stroke_scheme(second)
            assert ctl.config.stroke_scheme == second
        out = ctl.step(k * DT, R, np.zeros(3))
        feet.append(out.state.foot_targets)
        reasons.append(out.state.hold_reason)
        _in_ranges(out.joint_targets)
    assert ctl.stroke.name == second
    assert any(r.startswith("switching stroke scheme") for r in reasons)
    jumps = np.linalg.norm(np.diff(np.array(feet), axis=0), axis=2).max()
    assert jumps < 0.03
    with pytest.raises(ParameterError):
        ctl.set_stroke_scheme("bogus")
    assert ctl.stroke.name == second


def test_coordinated_params_validation():
    with pytest.raises(ParameterError):
        CoordinatedParams(speed_fraction=0.0)
    with pytest.raises(ParameterError):
        CoordinatedParams(path_sample=True)
