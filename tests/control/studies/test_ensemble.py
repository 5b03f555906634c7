"""The ensemble study (quadruped_control/studies/ensemble.py): Table 1 on every member of a fitted tank ensemble."""
from __future__ import annotations

import json
import os
import shutil

import pytest

from quadruped_common.config import config_path
from quadruped_control import simulate
from quadruped_control.sim.config_files import TANK_ENSEMBLE
from quadruped_control.sim.plants import VALIDITY_NOTE
from quadruped_control.studies import StudyError
from quadruped_control.studies import ensemble as ens
from quadruped_control.studies.runner import code_source
from quadruped_control.studies.paper_experiments import PAPER_TABLE


def _row(t_r, t_s, M_p=10.0, yaw_t_s=5.0, paper_t_s=20.0):
    side = {"t_r": t_r, "t_s": t_s, "M_p": M_p, "yaw": {"t_s": yaw_t_s}}
    paper = {"t_r": 8.0, "t_s": paper_t_s, "M_p": 25.0, "yaw": {"t_s": 12.0}}
    return {"case": "roll 15", "set": "roll", "cmd_deg": 15, "paper": paper, "sim": side,
            "settled_paper": paper_t_s is not None, "settled_sim": t_s is not None}


def test_case_spread_gives_median_and_range_over_the_members_that_have_a_value() -> None:
    members = [[_row(4.0, 10.0)], [_row(6.0, None, yaw_t_s=None)], [_row(5.0, 30.0, M_p=2.0)]]
    (entry,) = ens.case_spread(members)
    assert entry["members"] == 3 and entry["members_settled"] == 2 and entry["settled_paper"]
    assert entry["t_r"] == {"paper": 8.0, "sim": {"median": 5.0, "min": 4.0, "max": 6.0}}
    assert entry["t_s"]["sim"] == {"median": 20.0, "min": 10.0, "max": 30.0}  # the unsettled member left out
    assert entry["M_p"]["sim"] == {"median": 10.0, "min": 2.0, "max": 10.0}
    assert entry["yaw t_s"]["sim"]["median"] == 5.0 and entry["yaw t_s"]["paper"] == 12.0
    (none_settled,) = ens.case_spread([[_row(4.0, None, paper_t_s=None)]])
    assert none_settled["t_s"] == {"paper": None, "sim": None} and none_settled["members_settled"] == 0
    text = ens.format_report("F", ["a.yaml"], [{"cases": 15, "same_outcome": 14, "t_s_within_2x": 8,
                                               "t_r_within_2x": 11, "yaw_t_s_within_2x": 9, "yaw_t_s_reported": 14}],
                             [entry, none_settled], "t")
    assert "| a.yaml | 14 of 15 | 8 | 11 | 9 of 14 |" in text
    assert "| roll | 15 | 8.0 / 5.0 (4.0-6.0) | 20.0 / 20.0 (10.0-30.0) | 2 of 3 |" in text
    assert "| -- / -- | 0 of 1 (robot: not settled) |" in text and text.rstrip().endswith(VALIDITY_NOTE + ".")


def test_the_package_ensemble_is_the_default_and_its_members_are_the_shipped_files() -> None:
    assert ens.member_files(None) == [config_path(name) for name in TANK_ENSEMBLE]


def test_a_missing_empty_or_broken_ensemble_is_refused_before_any_trial(tmp_path) -> None:
    with pytest.raises(StudyError, match="no such folder"):
        ens.member_files(str(tmp_path / "missing"))
    with pytest.raises(StudyError, match="no tank.yaml files"):
        ens.member_files(str(tmp_path))
    (tmp_path / "member.yaml").write_text("tether:\n  stiffness: -1\n")
    with pytest.raises(Exception, match="member.yaml"):
        ens.member_files(str(tmp_path))


def test_study_cli_runs_table_1_on_every_member(tmp_path, capsys) -> None:
    folder = tmp_path / "fits"
    folder.mkdir()
    for name in TANK_ENSEMBLE[:2]:
        shutil.copy(config_path(name), str(folder / os.path.basename(name)))
    out = str(tmp_path / "out")
    assert simulate.main(["--study", "ensemble", "--tank-ensemble", str(folder), "--duration", "0.3",
                          "--jobs", "1", "--quiet", "--out", out]) == 0
    with open(os.path.join(out, "ensemble.json")) as stream:
        report = json.load(stream)
    assert report["members"] == ["member_00.yaml", "member_01.yaml"] and report["duration"] == 0.3
    assert len(report["rows"]) == 2 and all(len(rows) == len(PAPER_TABLE) for rows in report["rows"])
    assert [e["case"] for e in report["spread"]] == report["cases"] and len(report["counts"]) == 2
    assert all(e["members"] == 2 for e in report["spread"])
    assert report["command"][:4] == ["python", "-m", "quadruped_control.simulate", "--study"]
    assert report["code_source"] == code_source()
    printed = capsys.readouterr().out
    assert "member_00.yaml" in printed and "30 trials" in printed
    # each member's rows are its own trials: the same member twice gives the same rows, and member_00's
    twice = tmp_path / "twice"
    twice.mkdir()
    for name in ("a.yaml", "b.yaml"):
        shutil.copy(config_path(TANK_ENSEMBLE[0]), str(twice / name))
    assert simulate.main(["--study", "ensemble", "--tank-ensemble", str(twice), "--duration", "0.3",
                          "--jobs", "1", "--quiet", "--out", str(tmp_path / "out2")]) == 0
    with open(os.path.join(str(tmp_path / "out2"), "ensemble.json")) as stream:
        rows = json.load(stream)["rows"]
    assert rows[0] == rows[1] and rows[0] == report["rows"][0]


def test_the_ensemble_study_refuses_the_paper_plant_a_single_tank_and_a_stray_folder(tmp_path, capsys) -> None:
    out = str(tmp_path / "out")
    assert simulate.main(["--study", "ensemble", "--plant", "paper", "--out", out]) == 1
    assert "runs the tank plant" in capsys.readouterr().err
    assert simulate.main(["--study", "ensemble", "--tank-yaml", config_path("tank.yaml"), "--out", out]) == 1
    assert "give the folder" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # a folder of tanks only means something to the ensemble study
        simulate.main(["--study", "paper-experiments", "--tank-ensemble", str(tmp_path), "--out", out])
