"""The bring-up fault study: every kind drawn, detected, named in its report; fault-free cases pass."""
from __future__ import annotations

import json

from quadruped_control.bringup.imu_check import ImuMountResult
from quadruped_control.studies import bringup_faults


def test_study_detects_every_kind_and_reports(tmp_path):
    assert bringup_faults.main(["--cases", "7", "--clean", "2", "--seed", "3", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "bringup_faults.json").read_text())
    kinds = [row["kind"] for row in report["rows"]]
    assert sorted(kinds[:7]) == sorted(bringup_faults.KINDS) and kinds[7:] == ["none", "none"]
    assert all(row["detected"] for row in report["rows"])
    slow = report["rows"][6]  # named with its speed, measured
    assert slow["kind"] == "slow_servo" and "of its rated speed" in slow["servo_findings"][0]
    assert min(report["rows"][7]["speed_fraction"].values()) > 0.9
    assert report["command"].endswith("--out %s" % tmp_path) and "code" in report
    assert "| none (fault-free) | 2 | 2 passed | 0 false alarms |" in (tmp_path / "bringup_faults.md").read_text()


def test_a_missed_fault_fails_the_study(tmp_path, monkeypatch):
    monkeypatch.setattr(bringup_faults, "check_imu_mount", lambda readings: ImuMountResult(True))  # sees nothing
    assert bringup_faults.main(["--cases", "5", "--clean", "0", "--out", str(tmp_path)]) == 1  # case 5: the IMU
    assert "imu_rotated | 1 | 0 | 1 |" in (tmp_path / "bringup_faults.md").read_text()
