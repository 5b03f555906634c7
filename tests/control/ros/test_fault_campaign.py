"""The fault campaign's bookkeeping (no graph: tests/rostest/fault_campaign.test runs one of each kind)."""
import json

import numpy as np

from quadruped_control.analysis.fault_metrics import FaultRecord, Timeline
from quadruped_control.ros import fault_campaign as fc


def _summary(**changes):
    row = {"injections": 2, "expect": "safe", "never_safe": 0, "time_to_safe_max": 0.05,
           "tracking_fraction_min": None, "recovered": 2, "time_to_recovery_median": 0.1,
           "time_to_recovery_max": 0.2, "pulses_outside": 0, "moved_unarmed": 0, "lost_before": 0,
           "lost_measured": 2, "errors": []}
    row.update(changes)
    return {"imu_link_1": row, "_errors": {"count": 0, "errors": []}}


def test_failures_name_every_missed_target():
    assert fc.failures(_summary(), 0.11) == []
    problems = fc.failures(_summary(pulses_outside=1, moved_unarmed=3, time_to_safe_max=0.2, recovered=1,
                                    lost_before=5), 0.11)
    assert len(problems) == 5 and all(p.startswith("imu_link_1: ") for p in problems)
    assert fc.failures(_summary(never_safe=1), 0.11) == ["imu_link_1: not safe in 1 injections"]
    assert fc.failures(_summary(time_to_recovery_max=6.0), 0.11) == ["imu_link_1: recovery took 6.00 s"]
    assert fc.failures(_summary(injections=0), 0.11) == ["imu_link_1: no injection ran"]
    errors = {"imu_link_1": _summary()["imu_link_1"], "_errors": {"count": 1, "errors": ["x #1: boom"]}}
    assert fc.failures(errors, 0.11) == ["x #1: boom"]


def test_a_killed_recorders_chunk_is_allowed_only_where_asked():
    summary = _summary(lost_before=40)
    assert fc.failures(summary, 0.11, lost_allowed={"imu_link_1": 30}) == []
    assert fc.failures(summary, 0.11, lost_allowed={"imu_link_1": 10}) == [
        "imu_link_1: 40 messages lost from the bag before the fault (allowed 20)"]


def test_a_recorded_graph_is_judged_again_from_disk(tmp_path):
    """run_graph keeps the timeline and the records; judge_graph (and `fault_campaign judge`) gives the
    same figures from them without running anything."""
    t = 0.01 * np.arange(600)
    widths = 1500.0 + np.cumsum(np.full((600, 12), 3.0), axis=0) % 400.0
    frozen = (t >= 2.0) & (t < 3.0)
    widths[frozen] = widths[np.searchsorted(t, 2.0) - 1]
    timeline = Timeline(t, widths, t - 0.003, widths, t, np.ones(600, bool), np.zeros(600, bool))
    np.savez_compressed(tmp_path / "timeline.npz", imu_stamps=t, state_stamps=t,
                        **{name: getattr(timeline, name) for name in Timeline.__dataclass_fields__})
    record = FaultRecord("i2c_stuck_0.1", 2.0, 3.0, "safe")
    (tmp_path / "records.json").write_text(json.dumps({"records": [record.__dict__], "errors": ["e #0: x"]}))
    results = fc.judge_graph(str(tmp_path))
    assert results[0]["kind"] == "i2c_stuck_0.1" and results[0]["time_to_safe"] == 0.0
    assert results[0]["time_to_recovery"] is not None and results[0]["lost_before"] is None  # no bag here
    assert results[1] == {"kind": "error", "error": "e #0: x"}
    assert "i2c_stuck_0.1" in fc.format_table(fc.summarise(results, ["i2c_stuck_0.1"]))


def test_a_message_in_flight_when_its_publisher_is_killed_is_the_faults_not_the_records():
    """Stamps received by the campaign, the bag missing the last IMU sample before the fault: a loss for an
    I2C fault, not for a kill of the VN-100 node, whose socket to the recorder died with it (within
    IN_FLIGHT_S of the kill); an older missing sample is a loss for every kind."""
    from quadruped_control.analysis.fault_metrics import stamp_keys
    imu = np.arange(0.0, 10.0, 0.01)
    state = np.arange(0.0, 10.0, 0.01)
    start = 10.0
    bag = [(0.0, stamp_keys(imu[:-1])), (0.0, stamp_keys(state))]  # 9.99 s missing
    assert fc._lost_before(imu, state, bag, start, since=5.0, kind="i2c_stuck_0.1") == 1
    assert fc._lost_before(imu, state, bag, start, since=5.0, kind="kill_vn100_node") == 0
    assert fc._lost_before(imu, state, bag, start, since=5.0, kind="kill_attitude_controller") == 1
    older = [(0.0, stamp_keys(np.delete(imu, 900))), (0.0, stamp_keys(state))]  # 9.00 s missing
    assert fc._lost_before(imu, state, older, start, since=5.0, kind="kill_vn100_node") == 1
    assert fc.IN_FLIGHT_S < 0.1  # within the 0.11 s safe-state limit, far inside the 5 s window
