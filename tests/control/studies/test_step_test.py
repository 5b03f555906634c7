"""The step test study (quadruped_control.studies.step_test): the protocol on a simulated truth, a recorded bag
read back to the same steps, every model asked what the record asked, and the refusals."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from quadruped_common.config import config_path
from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_control.control.setpoint_sequence import STEP_TEST
from quadruped_control.sim.config_files import TANK_ENSEMBLE
from quadruped_control.sim.simulation import ClosedLoopSimulation
from quadruped_control.studies import StudyError
from quadruped_control.studies import step_test as st

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer  # noqa: E402

from tests.control.analysis.test_bag_report import STATE_TYPE, typestore  # noqa: E402

MEMBER_00, MEMBER_05 = config_path(TANK_ENSEMBLE[0]), config_path(TANK_ENSEMBLE[5])

#: a short protocol: roll 20 deg, back 8 deg towards upright, then away again (50 s in all)
SHORT = (((20.0, 0.0, 0.0), 20.0), ((12.0, 0.0, 0.0), 15.0), ((20.0, 0.0, 0.0), 15.0))


def _simulated(sequence=SHORT, path=MEMBER_00, seed=0):
    spec = st.step_test_spec(path, seed, (), 0.05, None, (0.0, 0.0, 0.0))
    return st.run_sequence(spec, sequence, "simulated")


def test_the_studys_protocol_is_the_one_the_maneuver_node_runs() -> None:
    assert st.PROTOCOL == tuple((hold.rpy_deg, hold.seconds) for hold in STEP_TEST)


def test_a_simulated_sequence_records_each_setpoint_change_as_a_step_at_its_time() -> None:
    record = _simulated()
    assert [round(step.time, 2) for step in record.steps] == [0.0, 20.0, 35.0]
    assert record.t[0] == 0.0 and record.t[-1] == pytest.approx(50.0) and np.all(np.diff(record.t) > 0.0)
    assert [round(math.degrees(step.after[0]), 6) for step in record.steps] == [20.0, 12.0, 20.0]
    responses = record.responses()
    assert [r.towards_upright for _, r in responses] == [False, True, False]
    assert [r.duration for _, r in responses] == pytest.approx([20.0, 15.0, 15.0])
    start, first, sequence = st.record_sequence(record)
    assert first == [0.0, 0.0, 0.0] and max(abs(v) for v in start) < 1e-9
    rounded = [([round(v, 9) for v in setpoint], round(seconds, 6), state) for setpoint, seconds, state in sequence]
    assert rounded == [(list(map(float, setpoint)), seconds, "acting") for setpoint, seconds in SHORT]
    assert record.controller == [(0.0, "acting")]


def _write(path: str, record, setpoint_of, armed=True, imu: bool = True) -> None:
    """``record`` as the robot's bag would hold it: /imu/data (unless not ``imu``) and a /controller_state
    (``armed`` or not, or ``armed(t)``: holding when not) at its samples, stamped from 1000 s, with the setpoint
    ``setpoint_of(t)`` (rad)."""
    store = typestore()
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    Quaternion, Vector3 = store.types["geometry_msgs/msg/Quaternion"], store.types["geometry_msgs/msg/Vector3"]
    Point, Imu = store.types["geometry_msgs/msg/Point"], store.types["sensor_msgs/msg/Imu"]
    State = store.types[STATE_TYPE]
    zero3, cov = Vector3(x=0.0, y=0.0, z=0.0), np.zeros(9)
    with Writer(path) as writer:
        imu_c = writer.add_connection("/imu/data", Imu.__msgtype__, typestore=store)
        state_c = writer.add_connection("/controller_state", STATE_TYPE, typestore=store)
        for k, (t, rpy) in enumerate(zip(record.t, record.rpy)):
            stamp = 1000.0 + float(t)
            header = Header(seq=k, stamp=Time(sec=int(stamp), nanosec=int(round((stamp % 1) * 1e9)) % 10 ** 9),
                            frame_id="")
            x, y, z, w = rot_to_quat(rpy_to_rot(*rpy))
            sample = Imu(header=header, orientation=Quaternion(x=x, y=y, z=z, w=w), orientation_covariance=cov,
                         angular_velocity=zero3, angular_velocity_covariance=cov, linear_acceleration=zero3,
                         linear_acceleration_covariance=cov)
            ns = int(round(stamp * 1e9))
            if imu:
                writer.write(imu_c, ns, store.serialize_ros1(sample, Imu.__msgtype__))
            sx, sy, sz, sw = rot_to_quat(rpy_to_rot(*setpoint_of(float(t))))
            acting = bool(armed(float(t)) if callable(armed) else armed)
            state = State(header=header, setpoint=Quaternion(x=sx, y=sy, z=sz, w=sw), attitude_error=zero3,
                          geodesic_error=0.0, torque_command=zero3, torque_saturated=zero3, integral=zero3,
                          torque_estimated=zero3, armed=acting, holding=not acting, hold_reason="",
                          pair_phase=np.zeros(2, dtype=np.uint8), pair_phase_time=np.zeros(2),
                          foot_targets=[Point(x=0.0, y=0.0, z=0.0)] * 4)
            writer.write(state_c, ns, store.serialize_ros1(state, STATE_TYPE))


def _setpoint_of(sequence=SHORT):
    ends = np.cumsum([seconds for _, seconds in sequence])

    def setpoint(t: float):
        k = min(int(np.searchsorted(ends, t + 1e-6, side="right")), len(sequence) - 1)
        # the record's first sample is measured before the first setpoint acts: level there
        return np.radians(sequence[k][0]) if t > 0.0 else np.zeros(3)
    return setpoint


def test_a_bag_of_the_run_gives_back_its_steps_and_their_responses(tmp_path) -> None:
    record = _simulated()
    path = str(tmp_path / "run.bag")
    _write(path, record, _setpoint_of())
    read = st.record_from_bag([path], "run.bag")
    assert [round(step.time, 2) for step in read.steps] == [0.01, 20.0, 35.0]  # the bag's first setpoint: level
    assert read.t[0] == 0.0 and read.t.size == record.t.size
    np.testing.assert_allclose(read.rpy, record.rpy, atol=1e-5)  # float32 quaternions
    for (_, a), (_, b) in zip(read.responses()[1:], record.responses()[1:]):
        for key in ("settle_6", "settle_2"):
            x, y = getattr(a, key), getattr(b, key)
            assert (x is None and y is None) or x == pytest.approx(y, abs=0.02)
        assert a.overshoot_deg == pytest.approx(b.overshoot_deg, abs=1e-3)


def test_a_step_the_record_ends_on_is_left_out(tmp_path) -> None:
    record = _simulated(sequence=(((20.0, 0.0, 0.0), 5.0), ((12.0, 0.0, 0.0), 3.0)))
    path = str(tmp_path / "late.bag")
    # level at the first sample, 20 deg after it, 30 deg at the last sample (the recorder stopped then)
    _write(path, record, lambda t: np.radians([0.0 if t <= 0.0 else 20.0 if t < 7.995 else 30.0, 0.0, 0.0]))
    read = st.record_from_bag([path], "late.bag")
    assert [round(math.degrees(step.after[0]), 3) for step in read.steps] == [20.0]
    assert len(read.responses()) == 1


def test_a_stop_of_the_controller_cuts_the_step_it_falls_in_and_leaves_out_the_next(tmp_path, monkeypatch) -> None:
    record = _simulated()
    path = str(tmp_path / "held.bag")
    # the safe pose held from 25 s to 27 s: inside the second step (20 s), and 8 s before the third (35 s)
    _write(path, record, _setpoint_of(), armed=lambda t: not 25.0 <= t < 27.0)
    read = st.record_from_bag([path], "held.bag")
    assert [round(step.time, 2) for step in read.steps] == [0.01, 20.0, 35.0]
    assert [round(step.time, 2) for step in read.unread()] == [35.0]
    responses = read.responses()
    assert [round(r.duration, 2) for _, r in responses] == [19.99, 5.0]
    # the models are asked the same: the disarm included, as a hold of its own
    assert [(time, state) for time, state in read.controller] == [(0.0, "acting"), (25.0, "disarmed"),
                                                                  (27.0, "acting")]
    start, first, sequence = st.record_sequence(read)
    assert [(round(setpoint[0], 3), round(seconds, 2), state) for setpoint, seconds, state in sequence] == [
        (0.0, 0.01, "acting"), (20.0, 19.99, "acting"), (12.0, 5.0, "acting"), (12.0, 2.0, "disarmed"),
        (12.0, 8.0, "acting"), (20.0, 15.0, "acting")]
    # each model's response to the cut step is read for as long as the record's; the report names the unread step
    monkeypatch.chdir(tmp_path)
    out = str(tmp_path / "out")
    assert st.main([path, "--compare", MEMBER_00, "--out", out]) == 0
    with open(os.path.join(out, "step_test.json")) as stream:
        report = json.load(stream)
    assert [round(entry["models"][0]["response"]["duration"], 1) for entry in report["steps"]] == [20.0, 5.0]
    # none runs the settling hold's 30 s, so none is judged: neither settling says nothing
    assert [entry["judged"] for entry in report["steps"]] == [False, False] and report["counted_steps"] == 0
    assert report["agreement"] == [0]
    assert [round(step["time"], 2) for step in report["unread_steps"]] == [35.0]
    with open(os.path.join(out, "step_test.md")) as stream:
        assert "Not read: 1 step(s)" in stream.read()


def test_a_model_asked_a_disarm_stops_stroking_and_starts_again_cleared(monkeypatch) -> None:
    spec = st.step_test_spec(MEMBER_05, 0, (), 0.0, None, (0.0, 0.0, 0.0))
    sequence = (((20.0, 0.0, 0.0), 10.0, "acting"), ((20.0, 0.0, 0.0), 10.0, "disarmed"),
                ((20.0, 0.0, 0.0), 10.0, "acting"))
    disarms = []
    disarm = ClosedLoopSimulation.disarm
    monkeypatch.setattr(ClosedLoopSimulation, "disarm", lambda sim: disarms.append(sim.time) or disarm(sim))
    record = st.run_sequence(spec, sequence, "disarmed")
    # disarmed as the robot is (the servos keep their last command), not held in the safe pose
    assert disarms == [pytest.approx(10.0)]
    assert record.controller == [(0.0, "acting"), (pytest.approx(10.0), "disarmed"), (pytest.approx(20.0), "acting")]
    roll = np.degrees(record.rpy[:, 0])
    at = {seconds: int(np.searchsorted(record.t, seconds)) for seconds in (10.0, 20.0, 30.0)}
    # it turns towards 20 deg while acting, falls back towards its rest while disarmed, and turns again after
    assert roll[at[10.0]] > 5.0 and roll[at[20.0]] < roll[at[10.0]] - 2.0 and roll[at[30.0]] > roll[at[20.0]] + 2.0
    with pytest.raises(ValueError, match="controller state"):
        st.run_sequence(spec, (((20.0, 0.0, 0.0), 1.0, "asleep"),), "bad")


def test_the_hold_before_the_controller_first_acts_is_the_start_not_a_stop(tmp_path) -> None:
    record = _simulated()
    path = str(tmp_path / "start.bag")
    # held from the start to 15 s (as the start-up hold): the step at 20 s comes 5 s after it and is read
    _write(path, record, _setpoint_of(), armed=lambda t: t >= 15.0)
    read = st.record_from_bag([path], "start.bag")
    assert [round(step.time, 2) for step in read.steps] == [20.0, 35.0] and read.unread() == []
    assert [round(r.duration, 2) for _, r in read.responses()] == [15.0, 15.0]


def test_a_bag_whose_setpoint_never_changes_or_lacks_a_stream_is_refused(tmp_path) -> None:
    record = _simulated(sequence=(((0.0, 0.0, 0.0), 3.0),))
    path = str(tmp_path / "still.bag")
    _write(path, record, lambda t: np.zeros(3))
    with pytest.raises(StudyError, match="never changed while the controller was acting"):
        st.record_from_bag([path], "still.bag")
    for name, kwargs, message in (("unarmed.bag", {"armed": False}, r"acting \(armed, not holding\) /controller_state"),
                                  ("no_imu.bag", {"imu": False}, "needs /imu/data and /controller_state")):
        path = str(tmp_path / name)
        _write(path, record, _setpoint_of(), **kwargs)
        with pytest.raises(StudyError, match=message):
            st.record_from_bag([path], name)
    assert st.main([str(tmp_path / "missing.bag"), "--out", str(tmp_path / "out")]) == 1


def test_the_cli_on_a_simulated_truth_agrees_with_the_truth_and_tells_another_member_apart(tmp_path, monkeypatch,
                                                                                       capsys) -> None:
    # roll 45 held, then 12 deg back towards upright: member_00's net static torque makes its return slow
    # (15 s to the 6 deg band, docs/identification.md), member_05 returns in a few seconds
    monkeypatch.setattr(st, "PROTOCOL", (((45.0, 0.0, 0.0), 60.0), ((33.0, 0.0, 0.0), 60.0)))
    out = str(tmp_path / "out")
    assert st.main(["--simulated", MEMBER_00, "--compare", MEMBER_00, MEMBER_05, "--jobs", "2", "--out", out]) == 0
    with open(os.path.join(out, "step_test.json")) as stream:
        report = json.load(stream)
    assert report["models"] == ["member_00.yaml", "member_05.yaml"] and report["single_axis_steps"] == 2
    assert report["counted_steps"] == 2 and all(entry["judged"] for entry in report["steps"])
    assert report["command"][:3] == ["python", "-m", "quadruped_control.studies.step_test"]
    assert report["truth"] == {"tank_yaml": "member_00.yaml", "disturbance": None}
    back = report["steps"][1]
    assert back["record"]["towards_upright"] and back["record"]["settle_6"] > 8.0
    truth, other = back["models"]
    assert truth["agrees"] and other["response"]["settle_6"] < back["record"]["settle_6"] / 2.0 and not other["agrees"]
    assert report["agreement"][0] == 2 and report["agreement"][1] <= 1
    assert len(truth["series"]["t"]) == len(truth["series"]["deg"]) > 10
    assert os.path.getsize(os.path.join(out, "step_test.png")) > 0
    printed = capsys.readouterr().out
    assert "| roll 45 -> 33 (towards upright) |" in printed and "- member_05.yaml: " in printed


def test_the_cli_refuses_bad_options_before_any_trial(tmp_path, capsys) -> None:
    out = str(tmp_path / "out")
    with pytest.raises(SystemExit):
        st.main(["--out", out])  # neither a run nor --simulated
    with pytest.raises(SystemExit):
        st.main(["run.bag", "--simulated", MEMBER_00, "--out", out])
    with pytest.raises(SystemExit):
        st.main(["--simulated", MEMBER_00, "--jobs", "0", "--out", out])
    with pytest.raises(SystemExit):
        st.main(["--simulated", MEMBER_00, "--attitude-noise-deg", "nan", "--out", out])
    assert st.main(["--simulated", MEMBER_00, "--tank-disturbance", "1.0", "10.0", "--out", out]) == 1
    assert "--tank-disturbance" in capsys.readouterr().err
    assert st.main(["--simulated", MEMBER_00, "--compare", str(tmp_path), "--out", out]) == 1
    assert not os.path.exists(out)
