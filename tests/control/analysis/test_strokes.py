"""Stroke figures from recorded joint angles (quadruped_control.analysis.strokes)."""
from __future__ import annotations

import numpy as np
import pytest

from quadruped_control.analysis.strokes import foot_paths, format_spread, stroke_statistics
from quadruped_control.model.kinematics import joint_angles
from quadruped_control.model.params import load_robot_params

PAIRS = ((1, 3), (2, 4))
CYCLE, POWER, RECOVERY_START, REACH, SPEED = 1.1, 0.1, 0.1, 0.03, 0.3


def _record(duration: float = 3.3, rate: float = 100.0):
    """Every paw strokes REACH m along body x at SPEED m/s in its pair's power phase (POWER s), then comes
    back over the rest of the cycle; pair 2 half a cycle later. Joint angles by the inverse kinematics."""
    robot = load_robot_params()
    t = np.arange(int(round(duration * rate))) / rate
    phase_t = t.copy()
    in_power = np.zeros((t.size, 2), dtype=bool)
    joints = np.zeros((t.size, 12))
    for p, legs in enumerate(PAIRS):
        local = np.mod(t - 0.5 * CYCLE * p + 1e-9, CYCLE)
        in_power[:, p] = (local < POWER) & (t + 1e-9 >= 0.5 * CYCLE * p)
        out = np.where(local < POWER, SPEED * local, REACH * (1.0 - (local - POWER) / (CYCLE - POWER)))
        out[t + 1e-9 < 0.5 * CYCLE * p] = 0.0
        for leg in legs:
            for k, x in enumerate(out):
                joints[k, 3 * (leg - 1):3 * leg] = joint_angles(robot.nominal_foot_body(leg) + [x, 0.0, 0.0], leg, robot)
    return robot, phase_t, in_power, t, joints


def test_the_strokes_of_a_known_record_are_measured_exactly() -> None:
    robot, phase_t, in_power, t, joints = _record()
    stats = stroke_statistics(phase_t, in_power, t, joints, robot, PAIRS)
    # pair 1 starts at 0, 1.1, 2.2 s and pair 2 at 0.55, 1.65, 2.75 s: two complete cycles each
    assert stats.strokes == 4 and stats.leg_strokes == 8 and stats.skipped_samples == 0
    assert stats.power_duration == pytest.approx((POWER,) * 3, abs=1e-9)
    assert stats.excursion == pytest.approx((REACH,) * 3, abs=1e-6)
    assert stats.peak_speed == pytest.approx((SPEED,) * 3, rel=1e-4)
    assert format_spread(stats.excursion, 100.0, 1) == "3.0 (3.0-3.0)"
    assert stats.as_dict()["strokes"] == 4


def test_paths_are_the_forward_kinematics_of_the_samples() -> None:
    robot, _, _, _, joints = _record(0.2)
    paths, good = foot_paths(joints, robot)
    assert good.all()
    for leg in (1, 2, 3, 4):
        np.testing.assert_allclose(paths[0, leg - 1], robot.nominal_foot_body(leg), atol=1e-9)


def test_corrupt_feedback_samples_are_skipped_and_counted() -> None:
    robot, phase_t, in_power, t, joints = _record()
    joints[50, 4] = np.nan               # a NaN angle (leg 2)
    joints[60, 0:2] = (3.0, -3.0)        # outside the servo ranges (theta1 -230..-50 deg)
    stats = stroke_statistics(phase_t, in_power, t, joints, robot, PAIRS)
    assert stats.skipped_samples == 2 and stats.strokes == 4
    assert stats.excursion == pytest.approx((REACH,) * 3, abs=1e-6)


def test_bad_input_is_a_clear_error_and_no_cycle_is_none() -> None:
    robot, phase_t, in_power, t, joints = _record()
    with pytest.raises(ValueError, match="increase strictly"):
        stroke_statistics(phase_t[::-1], in_power, t, joints, robot, PAIRS)
    with pytest.raises(ValueError, match="finite times"):
        stroke_statistics(np.where(phase_t > 1.0, np.nan, phase_t), in_power, t, joints, robot, PAIRS)
    with pytest.raises(ValueError, match="in_power must have shape"):
        stroke_statistics(phase_t, in_power[:, :1], t, joints, robot, PAIRS)
    with pytest.raises(ValueError, match="shape \\(samples, 12\\)"):
        stroke_statistics(phase_t, in_power, t, joints[:, :11], robot, PAIRS)
    with pytest.raises(ValueError, match="joint_t has"):
        stroke_statistics(phase_t, in_power, t[:-1], joints, robot, PAIRS)
    short = slice(0, 100)  # 1 s: no pair starts a second power phase, so no cycle is complete
    assert stroke_statistics(phase_t[short], in_power[short], t[short], joints[short], robot, PAIRS) is None
    holding = np.zeros_like(in_power)  # a record of a robot that held its pose throughout
    assert stroke_statistics(phase_t, holding, t, joints, robot, PAIRS) is None
