"""The ensemble study (quadruped_control/studies/ensemble.py): Table 1 on every member of a fitted tank ensemble."""
from __future__ import annotations

import json
import os
import shutil

import pytest

from quadruped_common.config import ParameterError, config_path
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


def test_case_spread_gives_median_and_range_over_the_runs_that_have_a_value() -> None:
    runs = [[_row(4.0, 10.0)], [_row(6.0, None, yaw_t_s=None)], [_row(5.0, 30.0, M_p=2.0)]]
    (entry,) = ens.case_spread(runs)
    assert entry["runs"] == 3 and entry["runs_settled"] == 2 and entry["settled_paper"]
    assert entry["t_r"] == {"paper": 8.0, "sim": {"median": 5.0, "min": 4.0, "max": 6.0}}
    assert entry["t_s"]["sim"] == {"median": 20.0, "min": 10.0, "max": 30.0}  # the unsettled run left out
    assert entry["M_p"]["sim"] == {"median": 10.0, "min": 2.0, "max": 10.0}
    assert entry["yaw t_s"]["sim"]["median"] == 5.0 and entry["yaw t_s"]["paper"] == 12.0
    (none_settled,) = ens.case_spread([[_row(4.0, None, paper_t_s=None)]])
    assert none_settled["t_s"] == {"paper": None, "sim": None} and none_settled["runs_settled"] == 0
    counts = {"cases": 15, "same_outcome": 14, "t_s_within_2x": 8, "t_r_within_2x": 11, "yaw_t_s_within_2x": 9,
              "yaw_t_s_reported": 14}
    text = ens.format_report("F", ["a.yaml"], [[counts]], [entry, none_settled], "t")
    assert "| a.yaml | 14 of 15 | 8 | 11 | 9 of 14 |" in text
    assert "| roll | 15 | 8.0 / 5.0 (4.0-6.0) | 20.0 / 20.0 (10.0-30.0) | 2 of 3 |" in text
    assert "| -- / -- | 0 of 1 (robot: not settled) |" in text and text.rstrip().endswith(VALIDITY_NOTE + ".")
    assert "Coverage" not in text  # only when given


def test_coverage_asks_whether_the_robot_lies_inside_the_runs_range() -> None:
    inside = [[_row(4.0, 10.0, M_p=20.0)], [_row(9.0, 30.0, M_p=30.0)]]  # robot: t_r 8, t_s 20, M_p 25, yaw 12
    cover = ens.coverage(inside)
    assert {label: (c["covered"], c["of"]) for label, c in cover.items()} == {
        "t_r": (1, 1), "t_s": (1, 1), "M_p": (1, 1), "yaw t_s": (0, 1)}  # both runs' yaw t_s 5 < 12
    assert cover["yaw t_s"]["outside"] == ["roll 15"] and cover["t_r"]["outside"] == []
    # a settling time is judged by the runs that settle: one run that settles at 10 s does not cover 20 s
    assert ens.coverage([[_row(4.0, 10.0)], [_row(4.0, None)]])["t_s"]["covered"] == 0
    # a robot that did not settle is covered by a run that does not settle, whatever the others' times
    unsettled = [[_row(4.0, 10.0, paper_t_s=None)], [_row(4.0, None, paper_t_s=None)]]
    assert ens.coverage(unsettled)["t_s"] == {"covered": 1, "of": 1, "outside": []}
    assert ens.coverage(unsettled[:1])["t_s"]["covered"] == 0
    # a value Table 1 does not give is not judged
    unreported = _row(4.0, 10.0)
    unreported["paper"]["yaw"]["t_s"] = None
    assert ens.coverage([[unreported]])["yaw t_s"] == {"covered": 0, "of": 0, "outside": []}


def test_a_members_counts_over_its_draws_are_reported_as_median_and_range() -> None:
    draws = [{"cases": 15, "same_outcome": 14, "t_s_within_2x": t_s, "t_r_within_2x": 11, "yaw_t_s_within_2x": 9,
              "yaw_t_s_reported": 14} for t_s in (6, 9, 8)]
    spread = ens.count_spread(draws)
    assert spread["t_s_within_2x"] == {"median": 8, "min": 6, "max": 9}
    assert spread["same_outcome"] == {"median": 14, "min": 14, "max": 14}
    entry = ens.case_spread([[_row(4.0, 10.0)]] * 3)
    cover = {"runs": ens.coverage([[_row(4.0, 10.0)]] * 3), "members": [ens.coverage([[_row(4.0, 10.0)]] * 3)]}
    text = ens.format_report("F", ["a.yaml"], [draws], entry, "t", cover)
    assert "| a.yaml | 14 of 15 | 8 (6-9) | 11 | 9 of 14 |" in text
    assert "runs (1 members x 3 draws)" in text and "(N - 1) / (N + 1) = 50 % of the experiments." in text
    assert "| a.yaml, its 3 draws | 0 of 1 | 0 of 1 | 0 of 1 | 0 of 1 |" in text
    assert "Outside the range of all runs: t_r: roll 15; t_s: roll 15; M_p: roll 15; yaw t_s: roll 15." in text


def test_draws_of_a_still_tank_and_a_disturbance_out_of_bounds_are_refused_before_any_trial() -> None:
    members = ens.member_files(None)[:2]
    with pytest.raises(StudyError, match=r"--draws 3: member_00.yaml is a still tank"):
        ens.member_tanks(members, (), 3)
    with pytest.raises(StudyError, match="--draws must be at least 1"):
        ens.member_tanks(members, (), 0)
    with pytest.raises(StudyError, match=r"--tank-disturbance: .*disturbance_torque_std. = 1 is outside \[0, 0.4\]"):
        ens.member_tanks(members, ens.disturbance_overrides((1.0, 10.0)), 2)
    with pytest.raises(StudyError, match="--tank-disturbance: .*disturbance_correlation_time. must be finite"):
        ens.member_tanks(members, ens.disturbance_overrides((0.002, float("nan"))), 2)
    tanks = ens.member_tanks(members, ens.disturbance_overrides((0.002, 5.0)), 3)
    assert all(t.disturbed and t.disturbance_torque_std == 0.002 and t.disturbance_correlation_time == 5.0
               for t in tanks)
    assert ens.member_tanks(members, (), 1)[0] == ens.member_tanks(members, (), 1)[0]  # one draw of a still tank


def test_the_package_ensemble_is_the_default_and_its_members_are_the_shipped_files() -> None:
    assert ens.member_files(None) == [config_path(name) for name in TANK_ENSEMBLE]


def test_tank_files_take_files_and_folders_each_once_in_the_order_given() -> None:
    folder = config_path("tank_ensemble")
    members = ens.member_files(folder)
    assert ens.tank_files([members[3], folder]) == [members[3]] + [m for m in members if m != members[3]]
    assert ens.tank_files([config_path("tank.yaml"), config_path("tank.yaml")]) == [config_path("tank.yaml")]


def test_a_missing_empty_or_broken_ensemble_is_refused_before_any_trial(tmp_path) -> None:
    with pytest.raises(StudyError, match="no such folder"):
        ens.member_files(str(tmp_path / "missing"))
    with pytest.raises(StudyError, match="no tank.yaml files"):
        ens.member_files(str(tmp_path))
    (tmp_path / "member.yaml").write_text("tether:\n  tether_stiffness: -1\n")
    members = ens.member_files(str(tmp_path))
    with pytest.raises(ParameterError, match="member.yaml"):
        ens.member_tanks(members, (), 1)


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
    assert report["draws"] == 1 and report["seeds"] == [0] and report["tank_overrides"] == []
    assert len(report["rows"]) == 2 and all(len(rows) == 1 and len(rows[0]) == len(PAPER_TABLE)
                                            for rows in report["rows"])
    assert [e["case"] for e in report["spread"]] == report["cases"] and len(report["counts"]) == 2
    assert all(e["runs"] == 2 for e in report["spread"]) and set(report["coverage"]["runs"]) == {
        "t_r", "t_s", "M_p", "yaw t_s"}
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
    for option in (["--tank-ensemble", str(tmp_path)], ["--draws", "2"], ["--tank-disturbance", "0.001", "10"]):
        with pytest.raises(SystemExit):  # a folder of tanks and its draws only mean something to the ensemble study
            simulate.main(["--study", "paper-experiments", "--out", out] + option)


def test_study_cli_runs_each_member_in_several_draws_of_a_disturbed_tank(tmp_path, capsys) -> None:
    folder = tmp_path / "fits"
    folder.mkdir()
    shutil.copy(config_path(TANK_ENSEMBLE[0]), str(folder / "member_00.yaml"))
    still, out = str(tmp_path / "still"), str(tmp_path / "out")
    common = ["--study", "ensemble", "--tank-ensemble", str(folder), "--duration", "3", "--jobs", "1", "--quiet"]
    assert simulate.main(common + ["--out", still]) == 0
    assert simulate.main(common + ["--draws", "2", "--seed", "4", "--tank-disturbance", "0.02", "10",
                                   "--out", out]) == 0
    with open(os.path.join(out, "ensemble.json")) as stream:
        report = json.load(stream)
    with open(os.path.join(still, "ensemble.json")) as stream:
        still_rows = json.load(stream)["rows"][0][0]
    assert report["draws"] == 2 and report["seeds"] == [4, 5]
    assert report["tank_overrides"] == [["disturbance_torque_std", 0.02], ["disturbance_correlation_time", 10.0]]
    (draws,) = report["rows"]
    assert len(draws) == 2 and len(report["counts"][0]) == 2 and all(e["runs"] == 2 for e in report["spread"])
    # each draw is pushed by its own disturbance: the draws differ from each other and from the still tank
    assert draws[0] != draws[1] and still_rows not in draws
    assert len(report["coverage"]["members"]) == 1
    printed = capsys.readouterr().out
    assert "2 draws (trial seeds 4-5)" in printed and "a disturbance of 0.02 N m" in printed and "30 trials" in printed
    assert simulate.main(common + ["--draws", "2", "--out", out]) == 1  # the shipped member is a still tank
    assert "is a still tank" in capsys.readouterr().err
