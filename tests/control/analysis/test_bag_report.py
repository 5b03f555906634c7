"""Tests of the bag report on a synthetic ROS 1 bag written with rosbags (no ROS needed)."""
import json
import math
import os

import numpy as np
import pytest

from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_control.analysis.bag_report import BagReportError, analyse, main, read_bags
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


def write_bag(path, duration=60.0, armed=True, roll_final=math.radians(30.0), tau=3.0, state_type=STATE_TYPE):
    """A first-order roll response to a 30 deg setpoint commanded at t = 5 s, IMU at 100 Hz."""
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
        for k in range(int(duration * 100)):
            t = k * 0.01
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
def test_report_of_first_order_roll_step(tmp_path, state_type):
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
    assert main([bag, "--out", str(out)]) == 0
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["settled"] is True
    assert (out / "attitude.png").stat().st_size > 1000
    assert "| roll |" in (out / "report.md").read_text()


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
