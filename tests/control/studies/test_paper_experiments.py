"""The paper-experiments study: Table 1 data, initial attitudes, worst-axis selection, table, CLI."""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os

import numpy as np
import pytest

from quadruped_common.so3 import geodesic_angle, rpy_to_rot
from quadruped_control import simulate
from quadruped_control.sim.plants import VALIDITY_NOTE
from quadruped_control.studies import paper_experiments as pe


def test_table_has_the_papers_fifteen_cases() -> None:
    assert [pe.case_label(r) for r in pe.PAPER_TABLE][:3] == ["roll 15", "roll 30", "roll 45"]
    assert len(pe.PAPER_TABLE) == 15
    assert [r["t_rec"] for r in pe.PAPER_TABLE].count(1.0) == 3  # pitch 75, 90, coupled 60
    assert sum(r["t_s"] is None for r in pe.PAPER_TABLE) == 1  # roll 75 did not settle


@pytest.mark.parametrize("index", [0, 6, 11, 14])
def test_initial_attitude_reproduces_theta_init_and_psi_init(index: int) -> None:
    row = pe.PAPER_TABLE[index]
    setpoint = pe.setpoint_rpy_deg(row)
    rpy, tilt = pe.initial_attitude(setpoint, row["theta_init"], row["psi_init"])
    R0 = rpy_to_rot(*np.radians(rpy))
    assert math.degrees(geodesic_angle(rpy_to_rot(*np.radians(setpoint)), R0)) == pytest.approx(row["theta_init"],
                                                                                                  abs=1e-6)
    assert 0.0 <= tilt < 35.0
    # heading: the tilt is about a horizontal body axis after the yaw, so the body x axis keeps psi_init
    # to within the tilt's effect on the Euler yaw
    assert abs((rpy[2] - row["psi_init"] + 180.0) % 360.0 - 180.0) <= tilt


def test_initial_attitude_rejects_an_impossible_theta() -> None:
    with pytest.raises(ValueError):
        pe.initial_attitude((15.0, 0.0, 0.0), 179.0, 0.0)


def test_worst_axis_marks() -> None:
    metrics = {"roll": {"t_r": 5.0, "t_s": 30.0, "e_ss": 0.5, "M_p": 10.0},
               "pitch": {"t_r": 8.0, "t_s": None, "e_ss": -0.2, "M_p": 12.0},
               "yaw": {"t_r": 1.0, "t_s": 2.0, "e_ss": 0.0, "M_p": 0.0}}
    worst = pe.worst_axis_metrics(metrics, "roll+pitch")
    assert worst == {"t_r": (8.0, "P"), "t_s": (None, "P"), "e_ss": (0.5, "R"), "M_p": (12.0, "P")}
    assert pe.worst_axis_metrics(metrics, "roll")["t_s"] == (30.0, "R")


def test_study_cli_writes_the_table_json_and_figures(tmp_path) -> None:
    out = str(tmp_path / "pe")
    assert simulate.main(["--study", "paper-experiments", "--plant", "paper", "--duration", "1", "--out", out,
                          "--quiet", "--jobs", "1"]) == 0
    with open(os.path.join(out, "paper_experiments.json")) as stream:
        study = json.load(stream)
    assert study["gains"] == "experiment" and study["plant"] == "paper" and study["servo_model"] == "ideal"
    assert len(study["rows"]) == 15
    for row in study["rows"]:
        assert row["sim"]["theta_init"] == pytest.approx(row["paper"]["theta_init"], abs=1e-3)
    assert study["agreement"]["cases"] == 15
    with open(os.path.join(out, "paper_experiments.md")) as stream:
        text = stream.read()
    assert "| roll+pitch | 60 (t_rec 1.0) |" in text and "(R)" in text
    assert VALIDITY_NOTE not in text  # the paper's own model needs no warning against the robot
    assert all(os.path.exists(p) for p in study["figures"]) and len(study["figures"]) == 3


def test_the_tank_plants_table_says_the_plant_is_not_validated(tmp_path, capsys) -> None:
    """A table made on the tank plant sits beside the paper's values; it must not be read as the robot's."""
    out = str(tmp_path / "pe")
    assert simulate.main(["--study", "paper-experiments", "--duration", "1", "--engine", "batch", "--out", out,
                          "--quiet", "--jobs", "1"]) == 0
    with open(os.path.join(out, "paper_experiments.md")) as stream:
        text = stream.read()
    assert "tank plant" in text.splitlines()[0] and "Note: %s." % VALIDITY_NOTE in text
    assert VALIDITY_NOTE in capsys.readouterr().out


def test_the_slow_recovery_trials_are_the_t_rec_cases_with_the_default_recovery() -> None:
    """The paper needed t_rec = 1.0 s for pitch 75, 90 and roll+pitch 60; the checks run them at 1.5 s."""
    args = argparse.Namespace(seed=0, tank_yaml=None, robot_yaml=None)
    specs = pe.experiment_specs(args, "tank", "experiment", "rate-limited", 10.0, keep_trace=False)[0]
    checks = pe.slow_recovery_specs(specs)
    assert [k for k, _ in checks] == [10, 11, 14]
    for k, check in checks:
        assert specs[k].config_overrides == (("t_rec", 1.0),) and check.config_overrides == ()
        assert check.label == "t_rec 1.5 " + specs[k].label
        assert dataclasses.replace(check, label=specs[k].label, config_overrides=specs[k].config_overrides) == specs[k]
