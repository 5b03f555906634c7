"""Identification from recorded runs: a bag becomes a record on the plant's grid (corrupt samples skipped,
gaps marked), the joint filter removes noise without delay, the fit recovers the parameters of a
simulated run, and bad input is refused."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from quadruped_common import jit
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import geodesic_angles, rot_to_quat, rot_z
from quadruped_control.analysis.bag_report import BagData
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants import load_tank_params
from quadruped_control.sim.replay import Record
from quadruped_control.studies import StudyError
from quadruped_control.studies import identify_bags as ib
from quadruped_control.studies.runner import code_source
from quadruped_control.studies.identify_parameters import nominal_values, update_tank_yaml
from tests.repo import REPO_ROOT

TANK = "config/tank_identified.yaml"
COMMAND_TYPE = "underwater_quadruped/msg/ServoCommand"
ROBOT = load_robot_params(None)

#: The fits below run thousands of replays; uncompiled (the Jetson's Python 3.8 venv has no numba: the robot
#: never runs a study) each takes over the 600 s test timeout on a loaded 2-core machine. The main run
#: compiles them, and tests/control/sim/test_batch.py checks the compiled loops against their plain Python.
needs_compiled_loops = pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed: the replay fits "
                                                                     "run uncompiled, past the test timeout")


def _stance() -> np.ndarray:
    """The twelve joint angles of the nominal stance: inside every servo range, and the five-bar closes."""
    from quadruped_control.control.strokes.paper import StrokeCycle

    return np.array(StrokeCycle(ROBOT).nominal_joints, dtype=float).reshape(12)


def _bag_data(imu_rate: float = 200.0, joint_rate: float = 50.0, duration: float = 2.0) -> BagData:
    """A yaw turn at 0.3 rad/s and joints moving as slow sines about the stance, on their own clocks."""
    data = BagData()
    stance = _stance()
    for k in range(int(duration * imu_rate) + 1):
        t = 100.0 + k / imu_rate
        data.imu_t.append(t)
        data.imu_q.append(tuple(rot_to_quat(rot_z(0.3 * (t - 100.0)))))
        data.imu_w.append((0.0, 0.0, 0.3))
    for k in range(int(duration * joint_rate) + 1):
        t = 100.003 + k / joint_rate
        data.joint_t.append(t)
        data.joint_q.append(list(stance + 0.05 * math.sin(2.0 * (t - 100.0))))
    return data


def test_a_bag_becomes_a_record_on_the_plants_grid() -> None:
    data = _bag_data()
    record, skipped = ib.record_from_bag(data, ROBOT, source="synthetic")
    assert skipped == 0 and record.dt == 0.01 and record.valid.all()
    assert record.t[0] == 0.0 and record.duration == pytest.approx(1.99, abs=1e-9)  # the span both cover
    start = 100.003
    expected = np.array([rot_z(0.3 * (start - 100.0 + tk)) for tk in record.t])
    assert geodesic_angles(expected, record.rotation).max() < 1e-9  # slerp of a steady turn is exact
    np.testing.assert_allclose(record.omega[:, 2], 0.3)
    stance = _stance().reshape(4, 3)
    exact = stance[None] + 0.05 * np.sin(2.0 * (start - 100.0 + record.t))[:, None, None]
    assert np.abs(record.joints - exact).max() < 2e-4  # linear between 50 Hz samples of a slow sine


def test_corrupt_joint_samples_are_skipped_and_gaps_marked_invalid() -> None:
    data = _bag_data()
    data.joint_q[20] = [math.nan] * 12
    data.joint_q[30] = [10.0] * 12  # outside every servo range
    record, skipped = ib.record_from_bag(data, ROBOT)
    assert skipped == 2
    assert record.valid.all()  # one missing 20 ms sample is no gap of 0.1 s
    del data.imu_t[100:160], data.imu_q[100:160], data.imu_w[100:160]  # 0.3 s without /imu/data
    record, _ = ib.record_from_bag(data, ROBOT)
    gap = (record.t > 0.5 - 0.003) & (record.t < 0.8 - 0.003)
    assert not record.valid[gap][1:-1].any() and record.valid[~gap].all()


def test_commands_are_held_to_the_next_and_missing_where_stale() -> None:
    data = _bag_data()
    record, _ = ib.record_from_bag(data, ROBOT)
    assert record.commands is None  # no /servo_command in this record
    stance = _stance()
    data.command_t = [100.1 + 0.05 * k for k in range(20)] + [101.5 + 0.05 * k for k in range(10)]
    data.command_q = [list(stance + 0.01 * k) for k in range(30)]
    record, _ = ib.record_from_bag(data, ROBOT)
    commands = record.commands.reshape(-1, 12)
    t = record.t + 0.003  # the grid's times on the bag's clock, less 100 s
    before = t < 0.1 - 1e-9
    assert np.isnan(commands[before]).all()
    k = np.searchsorted(t, 0.32)  # after the command stamped at 0.30 s (k = 4), before 0.35 s
    np.testing.assert_array_equal(commands[k], stance + 0.04)
    stale = (t > 1.05 + 0.1 + 1e-9) & (t < 1.5 - 1e-9)  # the last of the first burst, 1.05 s, is 0.1 s old
    assert np.isnan(commands[stale]).all() and np.isfinite(commands[(t >= 1.5) & (t < 1.9)]).all()


@needs_compiled_loops
def test_the_servo_fit_recovers_the_lag_and_says_what_it_cannot_pin_down() -> None:
    """The sixth set's servos (lag 6.185 x 30 ms, no dead band) in a 20 s run: the lag comes back to a step
    of its grid and the dead band to 0; the rate limit hardly binds at that lag (a stroke's error stays
    below w_max T), so the speed's profile is flat over most of its bounds, and the report says so."""
    record = ib.simulated_record(TANK, (45.0, 0.0, 0.0), (0.0, 0.0, 60.0), 20.0)
    objective = ib.ServoObjective(ib.load_servo_params(), [record], 500, 500, 10)
    assert objective.window_count == 3
    best = ib.fit_servos(objective)
    assert best["servo_lag_scale"] == pytest.approx(6.185, abs=0.1)
    speed_low, speed_high = best["within_1_percent"]["servo_speed_scale"]
    assert speed_low <= 0.6 and speed_high == 1.0  # 40 % of the range and more, the truth (1) in it
    low, high = best["within_1_percent"]["servo_lag_scale"]
    assert 6.185 - 0.2 <= low <= high <= 6.185 + 0.2  # pinned to a step or two of its 0.1 grid
    assert best["servo_dead_band"] == 0.0 and best["within_1_percent"]["servo_dead_band"] == [0.0, 0.0]
    assert best["objective"] < 0.01 < objective.ideal_deg()


@needs_compiled_loops
def test_the_servo_fit_measures_a_dead_band_from_the_commands_and_the_feedback(tmp_path) -> None:
    """The same run with the servos' dead band at 0.007 rad (0.4 deg), the feedback's noise at 0.05 deg:
    the dead band comes back to a step of its 0.002 rad grid and the lag to a step of its own, the fit's
    error to the noise; the same servos without the dead band miss by several times more."""
    with open(os.path.join(REPO_ROOT, TANK)) as stream:
        text = stream.read()
    assert "  servo_dead_band: 0.0 " in text
    truth = tmp_path / "banded.yaml"
    truth.write_text(text.replace("  servo_dead_band: 0.0 ", "  servo_dead_band: 0.007 ", 1))
    record = ib.simulated_record(str(truth), (45.0, 0.0, 0.0), (0.0, 0.0, 60.0), 20.0, joint_noise_deg=0.05)
    objective = ib.ServoObjective(ib.load_servo_params(), [record], 500, 500, 10)
    best = ib.fit_servos(objective)
    assert best["servo_dead_band"] == pytest.approx(0.007, abs=0.002)
    assert best["servo_lag_scale"] == pytest.approx(6.185, abs=0.2)
    low, high = best["within_1_percent"]["servo_dead_band"]
    assert 0.005 <= low <= high <= 0.009  # the first grid's points next to the truth
    assert best["objective"] < 0.06  # the feedback's noise, 0.05 deg
    without = objective([best["servo_speed_scale"]], [best["servo_lag_scale"]], [0.0])[0]
    assert without > 4.0 * best["objective"]


def test_a_bag_without_a_stream_or_an_overlap_is_refused() -> None:
    data = _bag_data()
    data.joint_t, data.joint_q = [], []
    with pytest.raises(StudyError, match="no /joint_states"):
        ib.record_from_bag(data, ROBOT, source="x.bag")
    data = _bag_data()
    data.joint_t = [t + 10.0 for t in data.joint_t]
    with pytest.raises(StudyError, match="do not overlap"):
        ib.record_from_bag(data, ROBOT)


def test_the_joint_filter_removes_noise_without_delay() -> None:
    t = np.arange(1001) * 0.01
    slow = 0.2 * np.sin(2.0 * math.pi * 0.5 * t)
    noise = np.random.default_rng(1).normal(0.0, math.radians(0.3), size=(1001, 4, 3))
    valid = np.ones(1001, dtype=bool)
    valid[500:505] = False
    valid[3:8] = False  # leaves samples 0-2: too short to filter
    record = Record(t=t, rotation=np.tile(np.eye(3), (1001, 1, 1)), omega=np.zeros((1001, 3)),
                    joints=slow[:, None, None] + noise, valid=valid, dt=0.01)
    record.joints[~valid] = 1e3  # invalid samples must not leak into their neighbours
    out = ib.smoothed(record, 10.0)
    inner = np.r_[30:480, 525:980]
    residual = out.joints[inner] - slow[inner, None, None]
    # the replay differentiates the joints: their rate's noise is what matters, and most of it is gone
    assert np.std(np.diff(residual, axis=0)) < 0.15 * np.std(np.diff(noise, axis=0))
    assert np.std(residual) < 0.5 * np.std(noise)
    assert abs(np.mean(residual)) < 1e-3  # and the 0.5 Hz motion passes without delay or loss
    assert not out.valid[:8].any() and out.valid[8:500].all() and out.valid[505:].all()
    assert ib.smoothed(record, 0.0) is record
    with pytest.raises(StudyError, match="cutoff"):
        ib.smoothed(record, 50.0)


def _write_bag(path: str, record: Record) -> None:
    rosbags = pytest.importorskip("rosbags")  # noqa: F841
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    with open(os.path.join(REPO_ROOT, "quadruped_msgs", "msg", "ServoCommand.msg")) as stream:
        store.register(get_types_from_msg(stream.read(), COMMAND_TYPE))
    Command = store.types[COMMAND_TYPE]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    Quaternion, Vector3 = store.types["geometry_msgs/msg/Quaternion"], store.types["geometry_msgs/msg/Vector3"]
    Imu, JointState = store.types["sensor_msgs/msg/Imu"], store.types["sensor_msgs/msg/JointState"]
    cov = np.zeros(9)
    with Writer(path) as writer:
        imu_c = writer.add_connection("/imu/data", Imu.__msgtype__, typestore=store)
        joint_c = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        command_c = writer.add_connection("/servo_command", COMMAND_TYPE, typestore=store)
        for k, tk in enumerate(record.t):
            ns = 1_000_000_000_000 + int(round(tk * 1e9))
            header = Header(seq=k, stamp=Time(sec=ns // 1000000000, nanosec=ns % 1000000000), frame_id="")
            x, y, z, w = rot_to_quat(record.rotation[k])
            wx, wy, wz = record.omega[k]
            writer.write(imu_c, ns, store.serialize_ros1(Imu(
                header=header, orientation=Quaternion(x=x, y=y, z=z, w=w), orientation_covariance=cov,
                angular_velocity=Vector3(x=wx, y=wy, z=wz), angular_velocity_covariance=cov,
                linear_acceleration=Vector3(x=0.0, y=0.0, z=0.0), linear_acceleration_covariance=cov),
                Imu.__msgtype__))
            writer.write(joint_c, ns, store.serialize_ros1(JointState(
                header=header, name=list(JOINT_NAMES), position=record.joints[k].reshape(12),
                velocity=np.zeros(0), effort=np.zeros(0)), JointState.__msgtype__))
            if np.all(np.isfinite(record.commands[k])):
                writer.write(command_c, ns, store.serialize_ros1(Command(
                    header=header, name=list(JOINT_NAMES), pulse_width_us=np.full(12, 1500.0),
                    joint_target=record.commands[k].reshape(12)), COMMAND_TYPE))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A 12 s roll manoeuvre simulated on the sixth identified set, noise-free, and its bag."""
    record = ib.simulated_record(TANK, (45.0, 0.0, 0.0), (0.0, 0.0, 60.0), 12.0)
    path = str(tmp_path_factory.mktemp("bags") / "run.bag")
    _write_bag(path, record)
    return record, path


def test_a_bag_reads_back_as_the_run_it_recorded(run) -> None:
    record, path = run
    read, skipped = ib.read_run(path, ROBOT, max_gap=0.1)
    assert skipped == 0 and read.valid.all() and read.t.size == record.t.size
    assert geodesic_angles(record.rotation, read.rotation).max() < 1e-6
    np.testing.assert_allclose(read.joints, record.joints, atol=1e-9)
    np.testing.assert_allclose(read.omega, record.omega, atol=1e-9)
    # the commands, each held to the next; the run's last sample has none, and the bag holds none for it
    np.testing.assert_array_equal(read.commands[:-1], record.commands[:-1])


@needs_compiled_loops
def test_the_fit_recovers_what_a_simulated_run_was_made_with(tmp_path) -> None:
    """The base is the truth with the centre of buoyancy and the roll/pitch damping moved away; a 25 s run
    with the IMU's and the feedback's noise pins both down again."""
    pytest.importorskip("cma")
    truth = nominal_values(load_tank_params(TANK))
    with open(TANK) as stream:
        base = update_tank_yaml(stream.read(), {"center_of_buoyancy_z": 0.0, "appendage_damping_linear_xy": 0.05,
                                                "appendage_damping_linear_z": truth["appendage_damping_linear_z"]}, "moved")
    base_yaml = str(tmp_path / "base.yaml")
    with open(base_yaml, "w") as stream:
        stream.write(base)
    out = str(tmp_path / "out")
    assert ib.main(["--simulated", TANK, "--tank-yaml", base_yaml, "--rpy", "45", "0", "0", "--hold-out-rpy", "0",
                    "30", "0", "--duration", "25", "--window", "5", "--stride", "2.5", "--parameters", "center_of_buoyancy_z",
                    "appendage_damping_linear_xy", "--evaluations", "96", "--popsize", "8", "--out", out]) == 0
    with open(os.path.join(out, "identify_bags.json")) as stream:
        report = json.load(stream)
    assert report["fitted"]["center_of_buoyancy_z"] == pytest.approx(truth["center_of_buoyancy_z"], abs=1e-4)  # 0.1 mm of its 8 mm range
    assert report["fitted"]["appendage_damping_linear_xy"] == pytest.approx(truth["appendage_damping_linear_xy"], abs=0.05)
    for side in ("training", "held_out"):
        s = report[side]
        assert s["windows"] == 7  # from 5 s (after the default lead-in) to 20 s
        assert s["fitted"] < 1.5 * s["truth"] and s["fitted"] < 0.2 * s["base"] and s["fitted"] < 0.2 * s["still"]
    assert report["truth"]["values"]["center_of_buoyancy_z"] == truth["center_of_buoyancy_z"]
    assert report["code_source"] == code_source()
    fitted = load_tank_params(os.path.join(out, "tank_fitted.yaml"))
    assert fitted.center_of_buoyancy[2] == pytest.approx(report["fitted"]["center_of_buoyancy_z"], abs=1e-12)
    for name in ("identify_bags.md", "identify_bags.png"):
        assert os.path.getsize(os.path.join(out, name)) > 0
    # the same command gives the same fit
    again = str(tmp_path / "again")
    assert ib.main(report["command"][3:-2] + ["--out", again]) == 0
    with open(os.path.join(again, "identify_bags.json")) as stream:
        assert json.load(stream)["fitted"] == report["fitted"]


def test_a_recorded_run_is_fitted_end_to_end(run, tmp_path) -> None:
    pytest.importorskip("cma")
    _, path = run
    out = str(tmp_path / "out")
    assert ib.main([path, "--hold-out", path, "--tank-yaml", TANK, "--parameters", "center_of_buoyancy_z", "net_weight",
                    "--window", "4", "--stride", "4", "--lead-in", "0", "--evaluations", "8", "--popsize", "4",
                    "--out", out]) == 0
    with open(os.path.join(out, "identify_bags.json")) as stream:
        report = json.load(stream)
    assert report["training"]["windows"] == report["held_out"]["windows"] == 3  # at 0, 4 and 8 s
    assert report["training"]["runs"][0]["source"] == path and report["skipped_joint_samples"] == [0, 0]
    # the base competes with the search's sets: the fit is never worse than its start
    assert report["evaluations"] >= 9 and report["fit_objective"] <= report["training"]["base"]
    servos = report["servos"]  # the bag holds /servo_command: the servos' half runs too
    assert servos["training"]["windows"] == 3  # the bag holds each command until the next: the last too
    assert servos["fitted"]["servo_lag_scale"] == pytest.approx(6.185, abs=0.1)
    assert servos["training"]["fitted"] < 0.1 * servos["training"]["ideal"]
    fitted = load_tank_params(os.path.join(out, "tank_fitted.yaml"))
    assert fitted.servo_lag_scale == servos["fitted"]["servo_lag_scale"]


@pytest.mark.parametrize("argv, message", [
    (["--parameters", "center_of_buoyancy_z", "servo_lag_scale"], "servo model"),
    (["--parameters", "center_of_buoyancy_z", "gravity"], "unknown parameter"),
    (["--parameters", "center_of_buoyancy_z"], "two or more"),
    (["--parameters", "center_of_buoyancy_z", "center_of_buoyancy_z"], "named twice"),
    (["missing.bag"], "no such bag"),
    (["--simulated", TANK], "--rpy"),
    ([], "at least one recorded run"),
])
def test_bad_input_is_refused(argv, message, capsys, tmp_path) -> None:
    assert ib.main(argv + ["--out", str(tmp_path)]) == 1
    assert message in capsys.readouterr().err


def test_runs_shorter_than_a_window_are_refused(capsys, tmp_path) -> None:
    assert ib.main(["--simulated", TANK, "--rpy", "45", "0", "0", "--duration", "2", "--window", "5", "--parameters",
                    "center_of_buoyancy_z", "net_weight", "--out", str(tmp_path)]) == 1
    assert "no window of 5.00 s" in capsys.readouterr().err


def test_a_broken_tank_yaml_is_named(capsys, tmp_path) -> None:
    broken = tmp_path / "tank.yaml"
    broken.write_text("effects: [\n")
    assert ib.main(["--simulated", TANK, "--rpy", "45", "0", "0", "--tank-yaml", str(broken), "--parameters",
                    "center_of_buoyancy_z", "net_weight", "--out", str(tmp_path / "out")]) == 1
    assert str(broken) in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--simulated", TANK, "run.bag"], ["run.bag", "--rpy", "1", "2", "3"],
                                  ["--window", "0"], ["--stride", "nan"], ["--sigma", "0.9"], ["--every", "0"],
                                  ["--joint-noise-deg", "-1"],
                                  ["--lead-in", "-1"], ["--lead-in", "nan"], ["--window", "0.05", "--every", "10"]])
def test_bad_options_are_refused(argv) -> None:
    with pytest.raises(SystemExit):
        ib.main(argv)


def test_the_imus_heading_is_no_parameter_of_the_replay():
    """The replay takes the recorded attitude as the true one: the residual field at the IMU is refused."""
    from quadruped_control.studies.identify_bags import PLANT_PARAMETERS, SENSOR_PARAMETERS, _check_parameters

    assert not set(SENSOR_PARAMETERS) & set(PLANT_PARAMETERS)
    with pytest.raises(StudyError, match="IMU's heading"):
        _check_parameters(["center_of_buoyancy_z", "imu_field_residual_z"])


def test_a_simulated_bag_records_the_heading_the_imu_reports(tmp_path) -> None:
    """With a residual field at the truth's IMU the simulated bag holds what the VN-100 would publish: the
    attitude the controller saw (the batch's reported rpy, BatchResult.rpy, of the run started where the IMU
    reports the initial attitude), not the plant's true one, which differs from it in heading."""
    from quadruped_common.so3 import rotations_to_rpy, rpy_to_rot
    from quadruped_control.sim.batch import BatchSimulation, BatchTrial
    from quadruped_control.studies.trial import TrialSpec, trial_setup

    with open(os.path.join(REPO_ROOT, TANK)) as stream:
        text = stream.read()
    assert "\nimu:" not in text  # the identified set's IMU reports the true heading
    truth = tmp_path / "magnetic.yaml"
    truth.write_text(text + "\nimu:\n  imu_field_residual: [0.1, -0.3, 0.4]\n")
    record = ib.simulated_record(str(truth), (30.0, 0.0, 0.0), (0.0, 0.0, 60.0), 2.0)
    spec = TrialSpec(label="x", setpoint_rpy_deg=(30.0, 0.0, 0.0), initial_rpy_deg=(0.0, 0.0, 60.0), duration=2.0,
                     gains="experiment", servo_model="rate-limited", plant="tank", tank_yaml=str(truth))
    setup = trial_setup(spec)
    trial = BatchTrial(config=setup.config, setpoint=rpy_to_rot(math.radians(30.0), 0.0, 0.0),
                       initial=setup.initial_R, servo_model="rate-limited", servo_params=setup.servo_params,
                       tank=setup.model.tank)
    result = BatchSimulation(setup.robot, [trial]).run(2.0, record_states=201)
    np.testing.assert_allclose(rotations_to_rpy(record.rotation), result.rpy[0], atol=1e-12)
    np.testing.assert_allclose(result.rpy[0, 0], [0.0, 0.0, math.radians(60.0)], atol=1e-12)
    true_heading = rotations_to_rpy(result.states["rotation"][0])[:, 2]
    assert np.abs(true_heading - result.rpy[0, :, 2]).min() > math.radians(1.0)
