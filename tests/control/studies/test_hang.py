"""What a hang tells (quadruped_control/studies/hang.py): a recorded or simulated hang fitted, and the models
set beside it."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from quadruped_common.config import config_path
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.tank import TankModel
from quadruped_control.sim.plants.tank_params import load_tank_params
from quadruped_control.sim.simulation import nominal_joint_angles
from quadruped_control.studies import StudyError
from quadruped_control.studies import hang as study

ROBOT = load_robot_params()


def _quaternions(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    return np.array([rot_to_quat(rpy_to_rot(r, p, 0.3)) for r, p in zip(roll, pitch)])


def test_the_imu_attitude_goes_on_a_grid_with_bad_samples_and_gaps_left_out() -> None:
    t = 50.0 + 0.02 * np.arange(600)
    roll, pitch = 0.1 * np.sin(0.5 * (t - 50.0)), 0.05 * np.cos(0.3 * (t - 50.0))
    q = _quaternions(roll, pitch)
    q[10] = math.nan  # not finite
    q[20] *= 3.0  # far from unit length
    order = np.r_[np.arange(300, 600), np.arange(0, 250)]  # out of order, and 1 s missing (250-299)
    record = study.record_from_bag(t[order], q[order], 0.1, 0.5, "synthetic")
    assert record.dt == 0.1 and record.t[0] == 0.0 and record.t[-1] == pytest.approx(11.9, abs=1e-9)
    expected_roll = 0.1 * np.sin(0.5 * record.t)
    good = record.valid
    assert np.abs(record.roll[good] - expected_roll[good]).max() < 1e-3  # linear between 50 Hz samples
    assert np.abs(record.pitch[good] - 0.05 * np.cos(0.3 * record.t[good])).max() < 1e-3
    gap = (record.t > 4.95) & (record.t < 6.0)
    assert not record.valid[gap].any() and record.valid[~gap].all()
    with pytest.raises(StudyError, match="fewer than two usable"):
        study.record_from_bag([1.0, 2.0], [[math.nan] * 4, [0.0, 0.0, 0.0, 2.0]], 0.1, 0.5, "bad")
    with pytest.raises(StudyError, match="fewer than 100 valid samples"):
        record.after(5.0)


def test_a_record_that_did_not_hang_still_is_refused() -> None:
    t = 0.1 * np.arange(2000)
    still = study.HangRecord(t, 0.01 * np.sin(t), np.full(t.size, 0.2), np.ones(t.size, dtype=bool), 0.1, "s")
    mean = study.check_hanging(still)
    assert mean["pitch"] == pytest.approx(0.2) and abs(mean["roll"]) < 1e-3
    tumbled = study.HangRecord(t, np.linspace(0.0, 2.0, t.size), still.pitch, still.valid, 0.1, "t")
    with pytest.raises(StudyError, match="roll left its mean by 57 deg"):
        study.check_hanging(tumbled)


def test_a_models_stiffness_at_the_hanging_attitude_is_its_restoring_torques_slope() -> None:
    tank = load_tank_params()
    sides = study.compare_tank(ROBOT, tank, 0.0, 0.0)
    model, q = TankModel(ROBOT, tank), nominal_joint_angles(ROBOT)
    at = math.radians(5.0)
    slope = -float(model.restoring_torque(rpy_to_rot(at, 0.0, 0.0), q)[0]) / at
    assert sides["roll"]["stiffness"] == pytest.approx(slope, rel=0.02)  # nearly linear over 5 deg
    assert sides["roll"]["stiffness"] > 0.1 and sides["pitch"]["stiffness"] > 0.1  # the a priori tank restores
    member_00 = study.compare_tank(ROBOT, load_tank_params(config_path("tank_ensemble/member_00.yaml")), 0.0, 0.0)
    assert member_00["roll"]["stiffness"] < 0.0  # it pushes away from level (docs/identification.md)
    roll_inertia, pitch_inertia = study.tilt_inertia(ROBOT, tank)
    assert 0.0 < roll_inertia < pitch_inertia  # the body is longer than it is wide


def test_verdicts_place_a_stiffness_against_the_interval() -> None:
    assert study._verdict(0.5, (0.2, 1.0)) == "inside"
    assert study._verdict(0.1, (0.2, 1.0)) == "softer"
    assert study._verdict(-0.1, (0.2, 1.0)) == "pushes away (k < 0)"
    assert study._verdict(2.0, (0.2, 1.0)) == "stiffer"
    assert study._verdict(2.0, None).startswith("not judged")


def test_the_legs_pose_through_a_hang_is_each_joints_median_after_the_skip() -> None:
    q0 = nominal_joint_angles(ROBOT).reshape(12)
    t = np.array([3.0, 0.0, 1.0, 2.0, 4.0])
    rows = np.tile(q0, (5, 1))
    rows[1] += 1.0  # the first sample, before the skip: left out
    rows[2, 5] = math.nan  # one joint unread once: the others' median
    rows[[0, 2, 3, 4], 2] += [0.1, 0.2, 0.2, 0.3]
    legs = study.recorded_legs(t, rows, 0.5, ROBOT)
    expected = q0.copy()
    expected[2] += 0.2
    np.testing.assert_allclose(legs, expected.reshape(4, 3))
    rows[[0, 3], 4] = 50.0  # outside its servo range: not a reading
    np.testing.assert_allclose(study.recorded_legs(t, rows, 0.5, ROBOT), expected.reshape(4, 3))
    rows[:, 7] = math.nan
    assert study.recorded_legs(t, rows, 0.5, ROBOT) is None  # a joint never read: the pose is not known
    assert study.recorded_legs([], np.empty((0, 12)), 0.5, ROBOT) is None


def test_legs_away_from_the_nominal_pose_move_a_models_hanging_moment() -> None:
    tank = load_tank_params()
    q0 = nominal_joint_angles(ROBOT)
    same = study.legs_effect(ROBOT, tank, 0.0, 0.0, q0)
    assert all(same[name]["moment"] == 0.0 and same[name]["tilt"] == 0.0 for name in ("roll", "pitch"))
    moved = q0.copy()
    moved[0, 2] += math.radians(10.0)  # leg 1's hip: its paw swings sideways
    effect = study.legs_effect(ROBOT, tank, 0.0, 0.0, moved)
    stiffness = study.compare_tank(ROBOT, tank, 0.0, 0.0)["roll"]["stiffness"]
    assert effect["roll"]["moment"] != 0.0
    assert effect["roll"]["tilt"] == pytest.approx(effect["roll"]["moment"] / stiffness)


def _write_imu_bag(path: str, t: np.ndarray, quaternions: np.ndarray, legs: np.ndarray = None) -> None:
    pytest.importorskip("rosbags")
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    Quaternion, Vector3 = store.types["geometry_msgs/msg/Quaternion"], store.types["geometry_msgs/msg/Vector3"]
    Imu, JointState = store.types["sensor_msgs/msg/Imu"], store.types["sensor_msgs/msg/JointState"]
    cov, zero = np.zeros(9), Vector3(x=0.0, y=0.0, z=0.0)
    with Writer(path) as writer:
        connection = writer.add_connection("/imu/data", Imu.__msgtype__, typestore=store)
        joints = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        for k, (tk, (x, y, z, w)) in enumerate(zip(t, quaternions)):
            ns = 1_000_000_000_000 + int(round(tk * 1e9))
            header = Header(seq=k, stamp=Time(sec=ns // 1000000000, nanosec=ns % 1000000000), frame_id="imu_link")
            if legs is not None and k % 5 == 0:  # the joint feedback at a fifth of the IMU's rate
                writer.write(joints, ns, store.serialize_ros1(JointState(
                    header=header, name=list(JOINT_NAMES), position=legs.reshape(12), velocity=np.zeros(12),
                    effort=np.zeros(0)), JointState.__msgtype__))
            writer.write(connection, ns, store.serialize_ros1(Imu(
                header=header, orientation=Quaternion(x=x, y=y, z=z, w=w), orientation_covariance=cov,
                angular_velocity=zero, angular_velocity_covariance=cov, linear_acceleration=zero,
                linear_acceleration_covariance=cov), Imu.__msgtype__))


def test_a_simulated_hang_is_fitted_and_the_same_hang_recorded_in_a_bag_fits_the_same(tmp_path, capsys,
                                                                                       monkeypatch) -> None:
    # The same simulated hang and the same fit of the same record, asked for again below (the bag's
    # attitude is the study's simulated record; the second bag run differs only in the legs), are each
    # computed once: both are deterministic functions of their arguments.
    records, fits = {}, {}
    real_record, real_fit = study.simulated_record, study.fit_axis

    def simulated_record(truth_yaml, disturbance, duration, seed, noise_deg, dt, robot_yaml):
        key = (truth_yaml, tuple(disturbance), duration, seed, noise_deg, dt, robot_yaml)
        if key not in records:
            records[key] = real_record(truth_yaml, disturbance, duration, seed, noise_deg, dt, robot_yaml)
        return records[key]

    # The fit's own accuracy is tests/control/analysis/test_hang.py's; here 300 evaluations reach the same
    # optimum (to 1e-6 on this record) in a third of the time. The bag's attitude round-trips through
    # quaternions, so records equal to 1e-9 rad share a fit.
    def fit_axis(y, dt, inertia, valid=None, tether=False):
        key = (np.round(np.asarray(y, dtype=float), 9).tobytes(), dt, inertia,
               None if valid is None else np.asarray(valid, dtype=bool).tobytes(), tether)
        if key not in fits:
            fits[key] = real_fit(y, dt, inertia, valid, max_evaluations=300, tether=tether)
        return fits[key]

    monkeypatch.setattr(study, "simulated_record", simulated_record)
    monkeypatch.setattr(study, "fit_axis", fit_axis)
    out = str(tmp_path / "sim")
    common = ["--skip", "10", "--compare", config_path("tank_ensemble/member_00.yaml")]
    assert study.main(["--simulated", config_path("tank.yaml"), "--tank-disturbance", "0.005", "10",
                       "--duration", "250", "--seed", "2", "--model-hangs", "--out", out] + common) == 0
    with open(os.path.join(out, "hang.json")) as stream:
        report = json.load(stream)
    assert os.path.isfile(os.path.join(out, "hang.png")) and os.path.isfile(os.path.join(out, "hang.md"))
    assert report["truth"]["torque_std"] == 0.005 and report["seconds"] == pytest.approx(240.0, abs=0.11)
    assert [entry["tank_yaml"] for entry in report["comparison"]] == ["tank.yaml", "member_00.yaml"]
    for axis in ("roll", "pitch"):
        fit = report["fits"][axis]["values"]
        # four minutes of a tank pushing with 5 mN m: the push and the stiffness within a factor 1.5 of the truth's
        assert 0.005 / 1.5 < fit["torque_std"] < 0.005 * 1.5, axis
        assert report["truth"]["stiffness"][axis] / 1.5 < fit["stiffness"] < report["truth"]["stiffness"][axis] * 1.5
        assert report["comparison"][1][axis]["verdict"] == "pushes away (k < 0)"
    # --model-hangs: each model hung as the robot was and read by the same fit. The truth's own hang (another
    # draw) reads the stiffness the record did, rope's swing included; member_00 pushes away and tumbles.
    own, tumbled = report["comparison"][0]["own_hang"], report["comparison"][1]["own_hang"]
    assert own["hangs"] and tumbled["hangs"] is False and "it did not hang still" in tumbled["why"]
    for axis in ("roll", "pitch"):
        assert own[axis]["stiffness"] == pytest.approx(report["fits"][axis]["values"]["stiffness"], rel=0.15)
    printed = capsys.readouterr().out
    assert "disturbance:" in printed and "Truth (--simulated tank.yaml)" in printed
    assert "The legs' pose is not known" in printed
    assert "Each model hung in the simulator with the fitted push (--model-hangs; trial seed 3)" in printed
    # the same attitude written to a bag at 50 Hz and read back gives the same fit
    record = study.simulated_record(config_path("tank.yaml"), (0.005, 10.0), 250.0, 2, 0.05, 0.1, None)
    t = np.arange(0.0, record.t[-1] + 1e-9, 0.02)
    quaternions = _quaternions(np.interp(t, record.t, record.roll), np.interp(t, record.t, record.pitch))
    bag = str(tmp_path / "hang.bag")
    legs = nominal_joint_angles(ROBOT)
    legs[0, 2] += math.radians(4.0)  # leg 1's hip 4 deg off the nominal pose through the hang
    _write_imu_bag(bag, t, quaternions, legs)
    assert study.main([bag, "--out", str(tmp_path / "bag")] + common) == 0
    with open(os.path.join(str(tmp_path / "bag"), "hang.json")) as stream:
        from_bag = json.load(stream)
    assert "truth" not in from_bag and from_bag["source"] == bag
    # the legs' pose is read and what it moves in each model reported; the simulated hang has no joint feedback
    assert from_bag["legs"]["from_nominal_deg"] == pytest.approx(4.0)
    assert all(entry["legs_as_recorded"]["roll"]["moment"] != 0.0 for entry in from_bag["comparison"])
    assert "stood up to 4.0 deg from the nominal pose" in capsys.readouterr().out
    assert report["legs"] is None and all("legs_as_recorded" not in entry for entry in report["comparison"])
    # a pose a model's legs cannot take is said, and the study goes on
    def unreachable(*_args):
        raise ValueError("the five-bar cannot close")
    monkeypatch.setattr(study, "legs_effect", unreachable)
    assert study.main([bag, "--out", str(tmp_path / "bag2")] + common) == 0
    assert "a pose the models' legs cannot take (the five-bar cannot close)" in capsys.readouterr().out
    for axis in ("roll", "pitch"):
        assert from_bag["fits"][axis]["values"]["stiffness"] == pytest.approx(
            report["fits"][axis]["values"]["stiffness"], rel=0.05)
        assert from_bag["mean_deg"][axis] == pytest.approx(report["mean_deg"][axis], abs=0.01)


def test_the_cli_refuses_what_it_cannot_fit(tmp_path, capsys) -> None:
    out = ["--out", str(tmp_path / "out")]
    with pytest.raises(SystemExit):
        study.main(out)  # neither a run nor --simulated
    with pytest.raises(SystemExit):
        study.main(["--simulated", config_path("tank.yaml")] + out)  # a still tank does not move it
    with pytest.raises(SystemExit):
        study.main(["x.bag", "--tank-disturbance", "0.001", "10"] + out)
    with pytest.raises(SystemExit):
        study.main(["x.bag", "--grid", "nan"] + out)
    assert study.main([str(tmp_path / "missing.bag")] + out) == 1
    assert "no such bag" in capsys.readouterr().err
    assert study.main(["--simulated", config_path("tank.yaml"), "--tank-disturbance", "1.0", "10"] + out) == 1
    assert "'disturbance_torque_std' = 1 is outside [0, 0.4]" in capsys.readouterr().err
    assert study.main(["--simulated", config_path("tank.yaml"), "--tank-disturbance", "0.001", "10",
                       "--grid", "0.015"] + out) == 1
    assert "multiple of the plant's 0.01 s step" in capsys.readouterr().err


def test_tether_asks_the_fit_for_the_tethers_branch(tmp_path, monkeypatch, capsys) -> None:
    asked = []

    def quick_fit(y, dt, inertia, valid=None, tether=False):
        asked.append(tether)
        return study_fit(y, dt, inertia, valid, max_evaluations=150, tether=tether)

    study_fit = study.fit_axis
    monkeypatch.setattr(study, "fit_axis", quick_fit)
    out = str(tmp_path / "out")
    assert study.main(["--simulated", config_path("tank.yaml"), "--tank-disturbance", "0.005", "10", "--duration",
                       "40", "--skip", "5", "--tether", "--compare", "--out", out]) == 0
    assert asked == [True, True]
    with open(os.path.join(out, "hang.json")) as stream:
        report = json.load(stream)
    assert report["tether"] and set(report["fits"]["roll"]["values"]) >= {"relaxing_stiffness", "relaxation_time"}
    assert [entry["tank_yaml"] for entry in report["comparison"]] == ["tank.yaml"]  # --compare with nothing
    assert report["comparison"][0]["roll"]["relaxing_stiffness"] == 0.0
    assert "The tether's relaxing bend (--tether" in capsys.readouterr().out
