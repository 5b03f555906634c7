"""Calibration against the reference poses finds each servo fault, names the joint, and writes nothing;
on a robot built right it writes the servos' real zeros and maps."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from quadruped_common.robot import JOINT_NAMES
from quadruped_control.bringup import calibrate
from quadruped_control.bringup.reference import reference_poses
from quadruped_control.bringup.servo_check import (DriverBench, ServoCheck, ServoCheckSettings, model_rise_time,
                                                   rise_time, speed_fraction)
from quadruped_control.model.params import load_robot_params
from quadruped_drivers.servo_rig import PoseDriver, SimulatedServoRig
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.hardware_faults import HardwareFaults, load_hardware_faults
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray

HW, CAL, PARAMS = load_hardware_config(), load_servo_calibration(), load_robot_params()
#: a short sweep keeps the tests quick; the findings do not depend on it
QUICK = ServoCheckSettings(points=3, settle_s=0.2, samples=2)


def run(faults: HardwareFaults, seed: int = 0, indices=None, channels: bool = False, speed_deg: float = 570.0,
        speeds: bool = False):
    # the channel check reads through the file's maps: its rig's servos are the file's (as after a calibration)
    channels = channels or speeds
    scale, shift = (1.0, 0.0) if channels else (1.04, 3.0)
    rig = SimulatedServoRig(HW, CAL, seed=seed, faults=faults, slope_scale=scale, offset_shift_deg=shift,
                            speed=math.radians(speed_deg))
    if indices is None and not channels:
        return calibrate.run_on_rig(rig, HW, CAL, PARAMS, QUICK), rig
    pwm = ServoPwmOutput(rig.bus, HW, clock=rig.clock, sleep=rig.sleep)
    feedback = ServoFeedbackArray(rig.bus, HW, CAL, clock=rig.clock)
    pwm.start()
    feedback.start()
    bench = DriverBench(PoseDriver(pwm, feedback, CAL, clock=rig.clock, sleep=rig.sleep), pwm)
    check = ServoCheck(bench, PARAMS, CAL, lambda pose: rig.place(pose.joint_angles()), QUICK, log=lambda s: None)
    stance = reference_poses(PARAMS)[0]
    all_joints = tuple(range(len(JOINT_NAMES)))
    if speeds:  # after a passed channel check, as the pre-dive check runs it
        assert check.check_channels(stance, indices or all_joints).passed
        return check.check_speeds(stance, indices or all_joints), rig
    if channels:
        return check.check_channels(stance, indices or all_joints), rig
    return check.calibrate(reference_poses(PARAMS), indices), rig


def test_a_robot_built_right_passes_and_its_real_maps_are_found():
    result, rig = run(HardwareFaults())
    assert result.passed, [str(f) for f in result.findings]
    poses = [pose.joint_angles() for pose in reference_poses(PARAMS)]
    for pose in poses:  # the fitted feedback reads the real angle where the joints work
        volts = rig.built.feedback_volts(pose)
        assert np.degrees(np.abs(result.calibration.volts_to_angles(volts) - pose)).max() < 0.5
        # and the fitted command map puts the real servos where it says
        assert np.degrees(np.abs(rig.built.joint_targets(result.calibration.angles_to_pulses(pose)) - pose)).max() < 0.5
    for fitted, bought in zip(result.calibration.joints, rig.built.calibration.joints):
        assert fitted.feedback_slope == pytest.approx(bought.feedback_slope, rel=0.02)
        assert fitted.neutral_us == pytest.approx(bought.neutral_us, abs=5.0)  # 0.45 deg
        assert fitted.feedback_fitted and fitted.direction == bought.direction


@pytest.mark.parametrize("spec, kind, joints", [
    ("{reversed: [leg2_hip]}", "reversed", ["leg2_hip"]),
    ("{horn_offset_deg: {leg1_motor1: 14.4}}", "zero", ["leg1_motor1"]),
    ("{horn_offset_deg: {leg4_motor2: -5}}", "zero", ["leg4_motor2"]),
    ("{swapped_pwm: [[leg1_hip, leg3_motor2]]}", "wiring", ["leg1_hip", "leg3_motor2"]),
    ("{swapped_feedback: [[leg1_motor1, leg2_motor1]]}", "wiring", ["leg1_motor1", "leg2_motor1"]),
    ("{stuck_feedback_v: {leg4_motor2: 1.2}}", "feedback", ["leg4_motor2"]),
])
def test_each_servo_fault_is_found_and_named(spec, kind, joints):
    result, _ = run(load_hardware_faults(spec))
    assert not result.passed and result.calibration is None
    assert any(f.kind == kind and set(joints) <= set(f.joints) for f in result.findings), \
        [str(f) for f in result.findings]
    assert set(result.named()) == set(joints)  # and nothing else is blamed


def test_servos_that_lag_their_commands_are_found():
    result, _ = run(HardwareFaults(), indices=(0, 5), speed_deg=15.0)  # overloaded: 15 deg/s instead of 570
    assert {f.kind for f in result.findings} == {"tracking"} and result.calibration is None
    assert set(result.named()) == {"leg1_motor1", "leg2_hip"}
    assert "follows 0." in result.findings[0].seen


def test_a_feedback_wire_on_another_kind_of_joint_is_found_by_its_slope():
    result, _ = run(load_hardware_faults("{swapped_feedback: [[leg1_motor1, leg1_hip]]}"))
    assert {"leg1_motor1", "leg1_hip"} <= set(result.named())
    assert any(f.kind == "feedback" and f.joints == ("leg1_motor1",) for f in result.findings)


def test_the_channel_check_reads_through_the_file_and_finds_a_swap():
    result, _ = run(load_hardware_faults("{swapped_pwm: [[leg2_motor1, leg2_motor2]]}"),
                    indices=(3, 4, 5), channels=True)
    assert [f.kind for f in result.findings] == ["wiring"]
    assert set(result.findings[0].joints) == {"leg2_motor1", "leg2_motor2"}


def test_the_sweep_never_leaves_the_five_bars_safe_set_even_on_a_swapped_channel():
    from quadruped_control.model.kinematics import five_bar_problem
    result, _ = run(load_hardware_faults("{swapped_pwm: [[leg1_motor1, leg1_hip]], reversed: [leg1_motor2]}"))
    stance = reference_poses(PARAMS)[0]
    for sweep in result.sweeps.values():
        for delta in sweep.offsets:  # whatever servo the channel turns, either way
            for joint in range(2):
                q = list(stance.leg_angles)
                q[joint] += delta
                assert five_bar_problem(q[0], q[1], PARAMS.five_bar) is None


def test_cli_writes_nothing_on_a_finding_and_the_calibration_on_a_clean_rig(tmp_path, capsys):
    out = str(tmp_path / "cal.yaml")
    assert calibrate.main(["--fake", "--faults", "{reversed: [leg3_hip]}", "--out", out, "--settle", "0.2"]) == 1
    err = capsys.readouterr().err
    assert "FOUND leg3_hip: it turns against its command" in err and "nothing written" in err
    assert not os.path.exists(out)
    assert calibrate.main(["--fake", "--out", out, "--settle", "0.2"]) == 0
    assert load_servo_calibration(out).joints[0].feedback_fitted


def test_cli_refuses_faults_without_the_fake_rig_and_bad_faults(capsys):
    with pytest.raises(SystemExit):
        calibrate.main(["--faults", "{reversed: [leg3_hip]}"])
    assert calibrate.main(["--fake", "--faults", "{reversed: [leg9_hip]}"]) == 2
    assert "configuration error" in capsys.readouterr().err


def test_noise_alone_never_makes_a_finding():
    for seed in range(3):
        result, _ = run(HardwareFaults(), seed=seed + 10)
        assert result.passed, [str(f) for f in result.findings]
    assert np.isfinite(result.sweeps["leg1_hip"].angles).all()


def test_a_servo_slower_than_its_rating_is_found_by_its_step_and_healthy_ones_are_not():
    result, rig = run(load_hardware_faults("{servo_speed_scale: {leg2_motor1: 0.5, leg3_hip: 0.8}}"), speeds=True)
    assert result.named() == ["leg2_motor1"] and result.findings[0].kind == "slow"  # 0.8 is above the 0.7 limit
    assert "turns at 0.50 of its rated speed" in result.findings[0].seen
    assert result.speeds["leg3_hip"] == pytest.approx(0.8, abs=0.05)
    healthy = [v for k, v in result.speeds.items() if k not in ("leg2_motor1", "leg3_hip")]
    assert min(healthy) > 0.9  # the rig's servos are pure rate limiters: a little faster than the lagged model
    assert np.allclose(rig.angles, reference_poses(PARAMS)[0].joint_angles(), atol=math.radians(1.0))  # at stance


def test_a_servo_that_never_finishes_its_step_is_a_finding():
    result, _ = run(load_hardware_faults("{servo_speed_scale: {leg1_hip: 0.1}}"), indices=(2,), speeds=True)
    assert result.named() == ["leg1_hip"] and "did not turn 80 % of a 60 deg step" in result.findings[0].seen
    assert result.speeds["leg1_hip"] == 0.0


def test_rise_time_interpolates_the_crossings_and_says_when_it_cannot_time():
    times = np.arange(0.0, 0.2, 0.01)
    ramp = np.clip((times - 0.02) / 0.1, 0.0, 1.0) * 2.0 + 1.0  # 1 -> 3 rad from 0.02 s to 0.12 s
    assert rise_time(times, ramp, 1.0, 3.0) == pytest.approx(0.06)
    assert rise_time(times, 4.0 - ramp, 3.0, 1.0) == pytest.approx(0.06)  # the other way
    assert rise_time(times, np.minimum(ramp, 2.5), 1.0, 3.0) == math.inf  # stopped at 75 %
    assert math.isnan(rise_time(times[5:], ramp[5:], 1.0, 3.0))  # already past 20 % at the first reading
    assert math.isnan(rise_time(times, ramp, 1.0, 1.0)) and math.isnan(rise_time(times[:0], ramp[:0], 1.0, 3.0))


@pytest.mark.parametrize("fraction", [0.1, 0.5, 0.7, 1.0, 2.0])
def test_the_speed_fraction_inverts_the_servo_model(fraction):
    span, rated, lag = math.radians(60.0), PARAMS.servo_no_load_speed, 0.03
    rise = model_rise_time(span, fraction * rated, lag)
    assert speed_fraction(rise, span, rated, lag) == pytest.approx(fraction, rel=1e-6)
    # a pure rate limiter: 60 % of the span at the speed
    assert model_rise_time(span, rated, 0.0) == pytest.approx(0.6 * span / rated, rel=1e-6)
    assert speed_fraction(math.inf, span, rated, lag) == 0.0 and math.isnan(speed_fraction(math.nan, span, rated, lag))
    assert speed_fraction(0.001, span, rated, lag) == 10.0  # faster than the lag alone allows: capped


@pytest.mark.parametrize("bad", [{"min_speed_fraction": 0.0}, {"min_speed_fraction": float("nan")},
                                 {"min_speed_fraction": 1.5}, {"speed_steps": 0}, {"speed_record_s": -1.0},
                                 {"speed_step_deg": 400.0}, {"time_constant": float("inf")}])
def test_speed_check_settings_out_of_range_are_refused_by_name(bad):
    from quadruped_common.config import ParameterError
    with pytest.raises(ParameterError, match=list(bad)[0]):
        ServoCheckSettings(**bad)
