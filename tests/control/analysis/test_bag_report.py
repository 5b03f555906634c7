"""Tests of the bag report on a synthetic ROS 1 bag written with rosbags (no ROS needed)."""
import json
import math
import sys
import os

import numpy as np
import pytest

from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_control.analysis.bag_report import (BagData, BagReportError, analyse, analyse_trials, attitude_rpy,
                                                  covered_by, gains_in_force, gains_text, main, missing_spans,
                                                  read_bags, setpoint_changes, sorted_unique, write_report,
                                                  write_trials_report)
from tests.repo import REPO_ROOT

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

MSG_DIR = os.path.join(REPO_ROOT, "quadruped_msgs", "msg")
STATE_TYPE = "underwater_quadruped/msg/ControllerState"


#: the type name of bags recorded before the messages became the root package's (nested package
#: quadruped_msgs): the report reads the definitions stored in the bag, so it reads those bags too
OLD_STATE_TYPE = "quadruped_msgs/msg/ControllerState"


def typestore(state_type=STATE_TYPE):
    store = get_typestore(Stores.ROS1_NOETIC)
    with open(os.path.join(MSG_DIR, "ControllerState.msg")) as f:
        store.register(get_types_from_msg(f.read(), state_type))
    return store


def write_bag(path, duration=60.0, armed=True, roll_final=math.radians(30.0), tau=3.0, state_type=STATE_TYPE,
              start=0.0, skip=None):
    """``start``: first sample at t = start (s of the run); ``skip``: (t0, t1), no message in between."""
    # A first-order roll response to a 30 deg setpoint commanded at t = 5 s, IMU at 100 Hz.
    STATE_TYPE = state_type  # noqa: N806 (the message type this bag records /controller_state as)
    store = typestore(state_type)
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Quaternion = store.types["geometry_msgs/msg/Quaternion"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    Point = store.types["geometry_msgs/msg/Point"]
    Imu = store.types["sensor_msgs/msg/Imu"]
    State = store.types[STATE_TYPE]
    DiagnosticArray = store.types["diagnostic_msgs/msg/DiagnosticArray"]
    DiagnosticStatus = store.types["diagnostic_msgs/msg/DiagnosticStatus"]
    KeyValue = store.types["diagnostic_msgs/msg/KeyValue"]
    zero3 = Vector3(x=0.0, y=0.0, z=0.0)
    cov = np.zeros(9)
    t0 = 1000.0
    with Writer(path) as writer:
        imu_c = writer.add_connection("/imu/data", Imu.__msgtype__, typestore=store)
        state_c = writer.add_connection("/controller_state", STATE_TYPE, typestore=store)
        diag_c = writer.add_connection("/diagnostics", DiagnosticArray.__msgtype__, typestore=store)
        for k in range(int(round(start * 100)), int(round((start + duration) * 100))):
            t = k * 0.01
            if skip is not None and skip[0] <= t < skip[1]:
                continue
            stamp = t0 + t
            header = Header(seq=k, stamp=Time(sec=int(stamp), nanosec=int(round((stamp % 1) * 1e9))), frame_id="")
            roll = 0.0 if t < 5.0 else roll_final * (1.0 - math.exp(-(t - 5.0) / tau))
            x, y, z, w = rot_to_quat(rpy_to_rot(roll, 0.0, 0.0))
            imu = Imu(header=header, orientation=Quaternion(x=x, y=y, z=z, w=w), orientation_covariance=cov,
                      angular_velocity=zero3, angular_velocity_covariance=cov, linear_acceleration=zero3,
                      linear_acceleration_covariance=cov)
            ns = int(stamp * 1e9)
            writer.write(imu_c, ns, store.serialize_ros1(imu, Imu.__msgtype__))
            sx, sy, sz, sw = rot_to_quat(rpy_to_rot(0.0 if t < 5.0 else roll_final, 0.0, 0.0))
            state = State(header=header, setpoint=Quaternion(x=sx, y=sy, z=sz, w=sw), attitude_error=zero3,
                          geodesic_error=abs((0.0 if t < 5.0 else roll_final) - roll), torque_command=zero3,
                          torque_saturated=zero3, integral=zero3, torque_estimated=zero3, armed=armed,
                          holding=not armed, hold_reason="", pair_phase=np.zeros(2, dtype=np.uint8),
                          pair_phase_time=np.zeros(2), foot_targets=[Point(x=0.0, y=0.0, z=0.0)] * 4)
            writer.write(state_c, ns, store.serialize_ros1(state, STATE_TYPE))
            if k % 100 == 0:
                status = DiagnosticStatus(level=0, name="pwm_node: servo output", message="ok", hardware_id="",
                                          values=[KeyValue(key="latency p99 [ms]", value="1.5"),
                                                  KeyValue(key="unrelated", value="x")])
                writer.write(diag_c, ns, store.serialize_ros1(DiagnosticArray(header=header, status=[status]),
                                                              DiagnosticArray.__msgtype__))


@pytest.mark.parametrize("state_type", [STATE_TYPE, OLD_STATE_TYPE])
def test_report_of_first_order_roll_step(tmp_path, state_type, monkeypatch):
    bag = str(tmp_path / "run.bag")
    write_bag(bag, state_type=state_type)
    metrics = analyse(read_bags([bag]))
    assert metrics["setpoint_rpy_deg"][0] == pytest.approx(30.0, abs=1e-6)
    assert metrics["theta_init_deg"] == pytest.approx(30.0, abs=0.5)
    # 10 % -> 90 % of a first-order step: tau ln 9 (the 3 s smoothing delays both crossings alike).
    assert metrics["roll"]["t_r"] == pytest.approx(3.0 * math.log(9.0), rel=0.1)
    assert metrics["settled"] is True
    assert metrics["health"] == {"pwm_node: servo output": {"latency p99 [ms]": "1.5"}}
    out = tmp_path / "report"
    assert main([bag, "--out", str(out), "--last-trial"]) == 0  # the one trial from the last setpoint change
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["settled"] is True and saved["gains"] is None
    assert (out / "attitude.png").stat().st_size > 1000
    assert "| roll |" in (out / "report.md").read_text() and "Gains: unknown." in (out / "report.md").read_text()
    if state_type != STATE_TYPE:
        return
    from quadruped_control.analysis import plotting
    monkeypatch.setattr(plotting, "plot_trials", lambda traces, path, **_: None)  # drawn in the tests below
    assert main([bag, "--out", str(tmp_path / "trials")]) == 0  # by default, trial by trial: level, then 30 deg
    trials = json.loads((tmp_path / "trials" / "metrics.json").read_text())["trials"]
    assert [round(t["setpoint_rpy_deg"][0]) for t in trials] == [0, 30] and trials[1]["metrics"]["settled"] is True


def test_never_armed_is_a_clear_error(tmp_path, capsys):
    bag = str(tmp_path / "idle.bag")
    write_bag(bag, duration=2.0, armed=False)
    with pytest.raises(BagReportError, match="never armed"):
        analyse(read_bags([bag]))
    assert main([bag, "--out", str(tmp_path / "r")]) == 1
    assert "never armed" in capsys.readouterr().err


def test_missing_bag_is_a_clear_error(tmp_path, capsys):
    assert main([str(tmp_path / "nope.bag"), "--out", str(tmp_path / "r")]) == 1


def test_health_across_runs_gives_min_median_max_of_every_figure():
    from quadruped_control.analysis.bag_report import health_across_runs

    runs = [{"ctl: control loop": {"loop rate [Hz]": "99.9", "hold episodes": "0", "hold reason": ""},
             "pwm: servo output": {"latency p99 [ms]": "3.0", "watchdog tripped": "False"}},
            {"ctl: control loop": {"loop rate [Hz]": "100.1", "hold episodes": "2"},
             "pwm: servo output": {"latency p99 [ms]": "4.5", "watchdog tripped": "True"}},
            {"ctl: control loop": {"loop rate [Hz]": "100.0", "hold episodes": "1"}}]
    summary = health_across_runs(runs)
    loop = summary["ctl: control loop"]
    assert loop["loop rate [Hz]"] == {"min": 99.9, "median": 100.0, "max": 100.1, "n": 3.0}
    assert loop["hold episodes"]["median"] == 1.0
    assert "hold reason" not in loop
    latency = summary["pwm: servo output"]["latency p99 [ms]"]
    assert latency["n"] == 2.0 and latency["median"] == 3.75
    assert summary["pwm: servo output"]["watchdog tripped"]["max"] == 1.0


def test_an_attitude_stream_comes_in_stamp_order_with_bad_samples_left_out():
    roll_30 = rot_to_quat(rpy_to_rot(math.radians(30.0), 0.0, 0.0))
    t, rpy = attitude_rpy([2.0, 1.0, 1.0, math.nan, 3.0, 4.0, 5.0],
                          [roll_30, (0.0, 0.0, 0.0, 1.02), roll_30, (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.5),
                           (math.nan, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)])
    assert t.tolist() == [1.0, 2.0, 5.0]  # a repeated stamp keeps its first sample, normalised
    np.testing.assert_allclose(rpy, [[0.0, 0.0, 0.0], [math.radians(30.0), 0.0, 0.0], [0.0, 0.0, 0.0]], atol=1e-12)


def test_sorted_unique_orders_by_stamp_keeps_a_repeated_stamps_first_sample_and_keeps_the_values_type():
    t = [3.0, 1.0, 2.0, 1.0, 0.5]
    rows = [[30.0], [10.0], [20.0], [11.0], [5.0]]
    times, listed = sorted_unique(t, rows)
    assert times.tolist() == [0.5, 1.0, 2.0, 3.0] and listed == [[5.0], [10.0], [20.0], [30.0]]
    times_a, array = sorted_unique(t, np.array(rows))
    assert isinstance(array, np.ndarray) and array.tolist() == listed and times_a.tolist() == times.tolist()
    empty_t, empty = sorted_unique([], np.empty((0, 4)))
    assert empty_t.size == 0 and empty.shape == (0, 4)


def test_a_grid_time_is_covered_inside_the_samples_span_and_not_across_a_gap():
    times = np.array([0.0, 0.1, 0.2, 1.0, 1.1])
    grid = np.array([-0.05, 0.0, 0.05, 0.2, 0.5, 1.0, 1.05, 1.1, 1.2])
    assert covered_by(times, grid, 0.15).tolist() == [False, True, True, True, False, True, True, True, False]
    assert covered_by(times, grid, 1.0).tolist() == [False] + [True] * 7 + [False]


def test_hold_episodes_say_when_and_why_in_stamp_order():
    from quadruped_control.analysis.bag_report import BagData, HoldEpisode, hold_episodes
    # Out of stamp order, as split bags may be; two episodes, the last one open at the end.
    steps = [(0.00, False, ""), (0.02, True, "IMU sample is stale (56 ms old, limit 50 ms)"),
             (0.01, True, "no IMU sample received yet"), (0.03, False, ""), (0.04, True, "IMU sample is stale (x)"),
             (0.05, True, "IMU sample is stale (y)")]
    data = BagData(state_t=[s[0] for s in steps], state_holding=[s[1] for s in steps],
                   state_hold_reason=[s[2] for s in steps])
    episodes = hold_episodes(data)
    assert episodes == [HoldEpisode(0.01, 0.02, "no IMU sample received yet"),
                        HoldEpisode(0.04, 0.05, "IMU sample is stale (x)")]
    assert [e.stale_imu for e in episodes] == [False, True]


def test_bag_reader_keeps_the_hold_reasons(tmp_path):
    bag = str(tmp_path / "never_armed.bag")
    write_bag(bag, duration=2.0, armed=False)
    data = read_bags([bag])
    assert len(data.state_hold_reason) == len(data.state_holding) == 200


# ---- what the record is missing: killed recorders, split parts, stream gaps -----------------------

def left_open_by_a_killed_recorder(path, out):
    """``out``: the ``.bag.active`` file a recorder killed while writing ``path`` leaves behind. The
    recorder (ROS's rosbag, as `rosbag record` writes) writes the file header with no index at open,
    each chunk when it fills and the index only at close: so the file as it stands before close, without
    the chunk still being filled. Returns the number of messages written."""
    import shutil

    import rosbag
    recording = out + ".recording"
    with rosbag.Bag(path) as source:
        bag = rosbag.Bag(recording, "w", chunk_threshold=64 * 1024)
        count = 0
        for topic, raw, t in source.read_messages(raw=True):
            bag.write(topic, raw, t, raw=True)
            count += 1
        shutil.copyfile(recording, out)  # the recorder dies here: no close, no index, last chunk unwritten
        bag.close()
    return count


def test_a_bag_left_open_by_a_killed_recorder_is_reindexed_and_the_missing_spans_named(tmp_path):
    pytest.importorskip("rosbag")  # ROS's API reindexes (as `rosbag reindex`)
    first, second = str(tmp_path / "uq_0.bag"), str(tmp_path / "second.bag")
    write_bag(first, duration=30.0)
    write_bag(second, start=40.0, duration=20.0)  # 30 s .. 40 s: the recorder was down
    active = str(tmp_path / "uq_1.bag.active")
    written = left_open_by_a_killed_recorder(second, active)
    with pytest.raises(BagReportError):  # rosbags alone cannot read it ...
        read_bags([str(tmp_path / "uq_1.bag.active") + "-not-there"])
    data = read_bags([first, active])  # ... the report reindexes a copy
    assert [f.reindexed for f in data.files] == [False, True]
    assert open(active, "rb").read()[:13] == b"#ROSBAG V2.0\n" and os.path.exists(active)  # original kept
    assert 0 < data.files[1].messages < written and data.files[1].end < 1000.0 + 59.99  # the last chunk is lost
    spans = missing_spans(data)
    whys = {s["why"].split(":")[0]: s for s in spans}
    assert sorted(whys) == ["between uq_0.bag and uq_1.bag.active", "no /imu/data", "recorder killed"]
    for why in ("between uq_0.bag and uq_1.bag.active", "no /imu/data"):
        assert whys[why]["from"] == pytest.approx(1029.99, abs=0.02) and whys[why]["to"] == pytest.approx(1040.0, abs=0.02)
    assert spans[-1]["why"].startswith("recorder killed") and spans[-1]["to"] is None
    metrics = analyse(data)
    assert metrics["record"]["missing_spans"] == spans
    report = open(write_report(metrics, str(tmp_path / "out"))).read()
    assert "## Record" in report and "killed recorder" in report and "recorder killed" in report


def test_without_ros_an_open_bag_is_a_clear_error(tmp_path, monkeypatch):
    bag = str(tmp_path / "run.bag")
    write_bag(bag, duration=5.0)
    active = str(tmp_path / "run.bag.active")
    with open(bag, "rb") as source, open(active, "wb") as copy:  # any unindexed file: never reaches rosbags
        copy.write(source.read(5000))
    monkeypatch.setitem(sys.modules, "rosbag", None)  # as on a laptop without ROS
    with pytest.raises(BagReportError, match="rosbag reindex"):
        read_bags([active])


def test_a_gap_in_the_imu_stream_is_a_missing_span(tmp_path):
    bag = str(tmp_path / "run.bag")
    write_bag(bag, duration=30.0, skip=(12.0, 14.0))
    spans = missing_spans(read_bags([bag]))
    assert len(spans) == 1 and spans[0]["why"] == "no /imu/data"
    assert (spans[0]["from"], spans[0]["to"]) == (pytest.approx(1011.99, abs=1e-6), pytest.approx(1014.0, abs=1e-6))
    assert missing_spans(read_bags([str(tmp_path / "run.bag")]), max_gap=5.0) == []



def test_the_report_measures_the_strokes_of_the_record(tmp_path):
    """/joint_states and the pair phases of /controller_state give the strokes' figures (analysis.strokes)."""
    from quadruped_common.robot import JOINT_NAMES
    from tests.control.analysis.test_strokes import POWER, REACH, SPEED, _record

    _, _, in_power, t, joints = _record()
    store = typestore()
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    Quaternion, Vector3 = store.types["geometry_msgs/msg/Quaternion"], store.types["geometry_msgs/msg/Vector3"]
    Point, Imu = store.types["geometry_msgs/msg/Point"], store.types["sensor_msgs/msg/Imu"]
    JointState, State = store.types["sensor_msgs/msg/JointState"], store.types[STATE_TYPE]
    zero3, cov, level = Vector3(x=0.0, y=0.0, z=0.0), np.zeros(9), Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    bag = str(tmp_path / "strokes.bag")
    with Writer(bag) as writer:
        imu_c = writer.add_connection("/imu/data", Imu.__msgtype__, typestore=store)
        state_c = writer.add_connection("/controller_state", STATE_TYPE, typestore=store)
        joint_c = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        for k, tk in enumerate(t):
            stamp = 1000.0 + tk
            ns = int(round(stamp * 1e9))
            header = Header(seq=k, stamp=Time(sec=int(stamp), nanosec=ns % 1000000000), frame_id="")
            writer.write(imu_c, ns, store.serialize_ros1(Imu(
                header=header, orientation=level, orientation_covariance=cov, angular_velocity=zero3,
                angular_velocity_covariance=cov, linear_acceleration=zero3, linear_acceleration_covariance=cov),
                Imu.__msgtype__))
            phases = np.array([State.PHASE_POWER if p else State.PHASE_RECOVERY for p in in_power[k]], dtype=np.uint8)
            writer.write(state_c, ns, store.serialize_ros1(State(
                header=header, setpoint=level, attitude_error=zero3, geodesic_error=0.0, torque_command=zero3,
                torque_saturated=zero3, integral=zero3, torque_estimated=zero3, armed=True, holding=False,
                hold_reason="", pair_phase=phases, pair_phase_time=np.zeros(2),
                foot_targets=[Point(x=0.0, y=0.0, z=0.0)] * 4), STATE_TYPE))
            # the feedback node names its joints; their order in the message need not be JOINT_NAMES'
            order = list(reversed(range(12)))
            writer.write(joint_c, ns, store.serialize_ros1(JointState(
                header=header, name=[JOINT_NAMES[i] for i in order], position=joints[k, order],
                velocity=np.zeros(0), effort=np.zeros(0)), JointState.__msgtype__))
    metrics = analyse(read_bags([bag]))
    strokes = metrics["strokes"]
    assert strokes["strokes"] == 4 and strokes["leg_strokes"] == 8 and strokes["skipped_samples"] == 0
    assert strokes["power_duration"] == pytest.approx([POWER] * 3, abs=1e-6)
    assert strokes["excursion"] == pytest.approx([REACH] * 3, abs=1e-6)
    assert strokes["peak_speed"] == pytest.approx([SPEED] * 3, rel=1e-3)
    out = tmp_path / "report"
    assert main([bag, "--out", str(out)]) == 0
    assert "4 power strokes: power phase 0.10 (0.10-0.10) s; paw excursion 3.0 (3.0-3.0) cm" in (
        out / "report.md").read_text()


# ---- trial by trial: setpoint changes, arm and disarm; the gains in force -----------------------------

EXPERIMENT = {"k_p": 10.0, "k_i": 3.0, "k_d": 0.5, "k_aw": 0.25, "tau_max": 2.0, "t_rec": 1.5, "t_pow_max": 0.5}


def write_schedule_bag(path, schedule, end, updates=()):
    """IMU and /controller_state at 100 Hz from t = 0 to ``end`` (s; stamps 1000 s on). ``schedule``: (from s,
    armed, roll setpoint deg) in time order; the roll follows the setpoint first order (tau 1 s) while armed.
    ``updates``: (s, values) recorded on the controller's parameter_updates as dynamic_reconfigure/Config."""
    from quadruped_control.analysis.bag_report import GAINS_TOPIC

    store = typestore()
    T = store.types
    zero3, cov = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0), np.zeros(9)
    Quaternion, Config = T["geometry_msgs/msg/Quaternion"], T["dynamic_reconfigure/msg/Config"]
    roll = 0.0
    with Writer(path) as writer:
        imu_c = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=store)
        state_c = writer.add_connection("/controller_state", STATE_TYPE, typestore=store)
        gains_c = writer.add_connection(GAINS_TOPIC, Config.__msgtype__, typestore=store)
        for at, values in updates:
            config = Config(bools=[], ints=[], groups=[], doubles=[T["dynamic_reconfigure/msg/DoubleParameter"](
                name=k, value=v) for k, v in values.items() if k != "stroke_scheme"],
                strs=[T["dynamic_reconfigure/msg/StrParameter"](name="stroke_scheme", value=values.get("stroke_scheme",
                                                                                                     "paper"))])
            writer.write(gains_c, int((1000.0 + at) * 1e9), store.serialize_ros1(config, Config.__msgtype__))
        for k in range(int(round(end * 100))):
            t = k * 0.01
            _, armed, setpoint = [row for row in schedule if row[0] <= t + 1e-9][-1]
            roll += (math.radians(setpoint) - roll) * 0.01 if armed else 0.0
            ns = int(round((1000.0 + t) * 1e9))
            header = T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](
                sec=ns // 1000000000, nanosec=ns % 1000000000), frame_id="")
            x, y, z, w = rot_to_quat(rpy_to_rot(roll, 0.0, 0.0))
            writer.write(imu_c, ns, store.serialize_ros1(T["sensor_msgs/msg/Imu"](
                header=header, orientation=Quaternion(x=x, y=y, z=z, w=w), orientation_covariance=cov,
                angular_velocity=zero3, angular_velocity_covariance=cov, linear_acceleration=zero3,
                linear_acceleration_covariance=cov), "sensor_msgs/msg/Imu"))
            x, y, z, w = rot_to_quat(rpy_to_rot(math.radians(setpoint), 0.0, 0.0))
            writer.write(state_c, ns, store.serialize_ros1(T[STATE_TYPE](
                header=header, setpoint=Quaternion(x=x, y=y, z=z, w=w), attitude_error=zero3,
                geodesic_error=abs(math.radians(setpoint) - roll), torque_command=zero3, torque_saturated=zero3,
                integral=zero3, torque_estimated=zero3, armed=armed, holding=False, hold_reason="",
                pair_phase=np.zeros(2, dtype=np.uint8), pair_phase_time=np.zeros(2),
                foot_targets=[T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0)] * 4), STATE_TYPE))


def test_a_tilt_only_setpoint_following_the_heading_is_one_setpoint():
    """In tilt mode R_d's yaw follows the measured heading every step: only a change of its tilt, or a setpoint
    that then holds (absolute, relative), is the operator's."""
    def q(roll, pitch, yaw):
        return rot_to_quat(rpy_to_rot(math.radians(roll), math.radians(pitch), math.radians(yaw)))
    tilt = [q(20.0, 0.0, 0.1 * k) for k in range(30)]                        # yaw drifts, the tilt holds
    tilt += [q(20.0, 10.0, 3.0 + 0.1 * k) for k in range(30)]                # the operator changes the tilt
    held = [q(0.0, 0.0, 0.0)] * 10 + [q(0.0, 0.0, 45.0)] * 10 + [q(0.0, 0.0, 50.0)] * 2 + [q(0.0, 0.0, 0.0)] * 10
    assert [i for i, new in enumerate(setpoint_changes(tilt)) if new] == [30]
    assert [i for i, new in enumerate(setpoint_changes(held)) if new] == [10, 22]  # a 2-step blip is not one


def test_five_setpoints_are_five_trials_each_with_its_gains_and_a_live_change_shows(tmp_path, monkeypatch):
    from quadruped_control.analysis import plotting
    drawn = {}  # figure file -> the trials' setpoints (roll, deg) it shows (drawing takes a second each: not here)
    monkeypatch.setattr(plotting, "plot_trials", lambda traces, path, **_: drawn.setdefault(
        os.path.basename(path), [round(math.degrees(trace.setpoint[0])) for trace in traces]))
    bag = str(tmp_path / "five.bag")
    schedule = [(8.0 * i, True, roll) for i, roll in enumerate((10.0, 20.0, 30.0, 20.0, 0.0))]
    # the latched value reaches the recorder just after the first step; K_p is raised live in trial 2
    updates = [(0.3, EXPERIMENT), (12.0, dict(EXPERIMENT, k_p=20.0)),
               (30.0, dict(EXPERIMENT, k_p=20.0, stroke_scheme="coordinated"))]
    write_schedule_bag(bag, schedule, 40.0, updates)
    out = tmp_path / "report"
    assert main([bag, "--out", str(out), "--title", "Five steps"]) == 0
    trials = json.loads((out / "metrics.json").read_text())["trials"]
    assert [t["trial"] for t in trials] == [1, 2, 3, 4, 5]
    assert [round(t["setpoint_rpy_deg"][0], 6) for t in trials] == [10.0, 20.0, 30.0, 20.0, 0.0]
    assert [round(t["end_unix"] - t["start_unix"], 6) for t in trials] == [8.0, 8.0, 8.0, 8.0, 7.99]
    assert [t["gains"]["k_p"] for t in trials] == [10.0, 10.0, 20.0, 20.0, 20.0]
    assert all(t["gains"]["k_i"] == 3.0 and t["metrics"]["theta_init_deg"] > 0.0 for t in trials[:4])
    assert trials[1]["gain_changes"] == [{"at": pytest.approx(4.0), "changes": {"k_p": [10.0, 20.0]}}]
    assert trials[3]["gain_changes"][0]["changes"] == {"stroke_scheme": ["paper", "coordinated"]}
    assert trials[4]["gains"]["stroke_scheme"] == "coordinated" and trials[4]["gain_changes"] == []
    report = (out / "report.md").read_text()
    assert report.count("\n| %d | " % 3) == 1 and "| 5 | 32.0 | 8.0 | 0.0, 0.0, 0.0 | k_p 20, k_i 3," in report
    assert "Gains: k_p 10, k_i 3, k_d 0.5, k_aw 0.25, tau_max 2, t_rec 1.5, t_pow_max 0.5, stroke_scheme paper; " \
           "changed during the trial: k_p 10.0 -> 20.0 at 4.0 s." in report
    assert drawn == dict({"trial_%02d.png" % n: [roll] for n, roll in enumerate((10, 20, 30, 20, 0), 1)},
                         **{"attitude.png": [10, 20, 30, 20, 0]})


def test_arm_and_disarm_split_trials_a_blip_is_not_measured_and_gains_are_unknown_without_updates(tmp_path):
    bag = str(tmp_path / "arm.bag")
    schedule = [(0.0, False, 0.0), (2.0, True, 15.0), (10.0, False, 15.0), (12.0, True, 15.0), (20.0, False, 15.0),
                (21.0, True, 15.0), (21.04, False, 15.0)]
    write_schedule_bag(bag, schedule, 23.0)
    result = analyse_trials(read_bags([bag]))
    spans = [(round(t["start_unix"] - 1000.0, 6), round(t["end_unix"] - 1000.0, 6)) for t in result["trials"]]
    assert spans == [(2.0, 10.0), (12.0, 20.0), (21.0, 21.04)]
    assert [t["gains"] for t in result["trials"]] == [None] * 3
    assert result["trials"][1]["metrics"]["theta_init_deg"] < result["trials"][0]["metrics"]["theta_init_deg"]
    assert result["trials"][2]["metrics"] is None and "fewer than 10 IMU samples" in result["trials"][2]["skipped"]
    report = open(write_trials_report(result, str(tmp_path / "out"))).read()
    assert "3 trials" in report and "Gains: unknown." in report and "Not measured: fewer than 10" in report
    assert "| 3 | 21.0 | 0.0 | 15.0, 0.0, 0.0 | unknown | - | - | - | - | - |" in report


def test_the_gains_in_force_are_the_last_update_at_or_before_the_start_else_the_first_recorded():
    data = BagData(gains_t=[5.0, 1.0, 9.0], gains=[{"k_p": 2.0}, {"k_p": 1.0}, {"k_p": 3.0}])
    assert gains_in_force(data, 0.0, 0.5) == {"gains": {"k_p": 1.0}, "gain_changes": []}
    assert gains_in_force(data, 5.0, 20.0) == {"gains": {"k_p": 2.0}, "gain_changes": [
        {"at": 4.0, "changes": {"k_p": [2.0, 3.0]}}]}
    assert gains_in_force(data, 0.0, 9.0)["gain_changes"] == [{"at": 5.0, "changes": {"k_p": [1.0, 2.0]}}]
    assert gains_in_force(BagData(), 0.0, 1.0) == {"gains": None, "gain_changes": []}
    assert gains_text(None) == "unknown" and gains_text({"x": "a", "k_i": 0.5, "k_p": 1.0}) == "k_p 1, k_i 0.5, x a"
