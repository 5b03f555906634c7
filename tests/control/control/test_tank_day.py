"""The tank day's plan and records (quadruped_control/control/tank_day.py): the runs in order with their prompts, Table
1 in either yaw reference, the motor pack's prompts, the folders' names, what is left to do, and the record's parts."""
import subprocess

import pytest

from quadruped_common.config import ParameterError, config_path
from quadruped_control.control import tank_day as td
from quadruped_control.control.setpoint_sequence import STEP_TEST, total_seconds


def test_the_day_runs_the_hang_the_tether_the_step_test_then_table_1_round_after_round() -> None:
    plan = td.day_plan()
    assert [run.kind for run in plan[:3]] == ["hang", "tether", "step_test"]
    assert [run.armed for run in plan[:3]] == [False, False, True]
    table1 = plan[3:]
    assert len(table1) == 2 * 15 and all(run.kind == "table1" and run.armed for run in table1)
    assert [run.row for run in table1[:15]] == [run.row for run in table1[15:]]  # every row once, then again
    assert [run.repeat for run in (table1[0], table1[15])] == [1, 2]
    assert [run.name for run in plan[:4]] == ["01_hang", "02_tether", "03_step_test", "04_table1_roll_15_r1"]
    assert table1[-1].name == "33_table1_roll_pitch_60_r2"
    assert [p.name for p in plan[1].phases] == ["free", "held", "released"]
    assert plan[1].phases[0].prompt == "" and all(p.prompt for p in plan[1].phases[1:])
    step = plan[2]
    assert step.yaw_reference == "relative" and step.delay == 30.0 and step.holds == STEP_TEST
    assert plan[0].seconds == 660.0 and step.seconds == 30.0 + total_seconds(STEP_TEST)


def test_table_1_is_the_papers_turn_and_tilt_from_the_heading_at_arming_or_yaw_0_in_absolute_terms() -> None:
    relative = {run.row: run for run in td.day_plan(td.DayOptions(repeats=1))[3:]}
    assert relative["roll 45"].holds[0].rpy_deg == (45.0, 0.0, -121.83)
    assert relative["roll+pitch 60"].holds[0].rpy_deg == (60.0, 60.0, 38.35)
    assert all(run.holds[1].rpy_deg == (0.0, 0.0, 0.0) and run.yaw_reference == "relative"
               for run in relative.values())
    assert [row for row, run in relative.items() if run.t_rec is not None] == ["pitch 75", "pitch 90", "roll+pitch 60"]
    absolute = td.day_plan(td.DayOptions(repeats=1, yaw_reference="absolute", rows=("pitch 30",)))[3:]
    assert [(run.row, run.holds[0].rpy_deg, run.yaw_reference) for run in absolute] == [
        ("pitch 30", (0.0, 30.0, 0.0), "absolute")]


def test_an_armed_run_that_would_take_the_pack_past_its_minutes_asks_for_a_fresh_one_first() -> None:
    plan = td.day_plan(td.DayOptions(battery_minutes=30.0))
    asked = [run.name for run in plan if run.prompt.startswith("First a fresh motor pack")]
    assert asked[0] == "06_table1_roll_45_r1"  # step test 18.5 min + two rows of 4 min, a third would pass 30
    armed = 0.0
    for run in plan:
        if run.name in asked:
            armed = 0.0
        armed += run.seconds if run.armed else 0.0
        assert armed <= 30 * 60.0
    assert not any(run.prompt.startswith("First") for run in plan if not run.armed)


@pytest.mark.parametrize("options, what", [
    (dict(hang_seconds=0.0), "hang_seconds"), (dict(step_scale=1.5), "step_scale"), (dict(repeats=0), "repeats"),
    (dict(rows=("roll 20",)), "'roll 20' not a row"), (dict(yaw_reference="tilt"), "yaw_reference"),
    (dict(table1_seconds=float("nan")), "table1_seconds")])
def test_options_out_of_range_are_refused_by_name(options, what) -> None:
    with pytest.raises(ParameterError, match=what):
        td.DayOptions(**options)


def test_a_runs_folder_name_says_its_kind_row_repeat_and_attempt() -> None:
    assert td.run_name(16, "table1", "roll+pitch 30", 2, attempt=3) == "16_table1_roll_pitch_30_r2_a3"
    assert td.parse_run_name("16_table1_roll_pitch_30_r2_a3") == {
        "index": 16, "kind": "table1", "row": "roll+pitch 30", "repeat": 2, "attempt": 3,
        "planned": "16_table1_roll_pitch_30_r2"}
    assert td.parse_run_name("01_hang")["kind"] == "hang" and td.parse_run_name("notes") is None


def test_the_runs_left_are_those_without_an_attempt_that_began() -> None:
    plan = td.day_plan(td.DayOptions(rows=("roll 30",), repeats=1))
    done = {"01_hang": {"status": "complete"}, "02_tether": {"status": "skipped"},
            "03_step_test": {"status": "aborted"}, "03_step_test_a2": {"status": "aborted"}}
    assert [(run.name, attempt) for run, attempt in td.remaining(plan, done)] == [
        ("03_step_test", 3), ("04_table1_roll_30_r1", 1)]


def test_the_configuration_files_are_the_parameters_or_their_loaders_defaults_with_their_hashes(tmp_path) -> None:
    mine = tmp_path / "controller.yaml"
    mine.write_text("x: 1\n")
    files = td.config_files({"/attitude_controller/controller_yaml": str(mine),
                             "/attitude_controller/robot_yaml": "",
                             "/attitude_controller/gain_set": "experiment",
                             "/sim_node/plant": "paper", "/sim_node/tank_yaml": "",
                             "/x/calibration_yaml": str(tmp_path / "gone.yaml")})
    assert sorted(files) == ["/attitude_controller/controller_yaml", "/attitude_controller/robot_yaml",
                             "/x/calibration_yaml"]
    assert files["/attitude_controller/controller_yaml"]["sha256"] == (
        "d09edadd173a8bbc233d47dcafc30cc876af2fb569812f2bbe0e92a1905bbce8")
    assert files["/attitude_controller/robot_yaml"]["path"] == config_path("robot.yaml")
    assert files["/x/calibration_yaml"]["sha256"].startswith("unreadable")
    assert "/sim_node/tank_yaml" in td.config_files({"/sim_node/plant": "tank", "/sim_node/tank_yaml": ""})


def test_the_code_version_is_gits_else_the_package_xmls(tmp_path) -> None:
    def git(answer, code=0):
        return lambda *args, **kwargs: subprocess.CompletedProcess(args, code, stdout=answer)

    assert td.code_version(str(tmp_path), git("v1-3-gabc-dirty\n")) == "git v1-3-gabc-dirty"
    assert td.code_version(str(tmp_path), git("", 128)) == "unknown"
    (tmp_path / "package.xml").write_text("<package><version> 0.4.1 </version></package>")
    assert td.code_version(str(tmp_path), git("", 128)) == "package 0.4.1"


def test_a_runs_record_is_its_plan_entry_its_status_and_what_the_node_logged() -> None:
    run = td.day_plan(td.DayOptions(rows=("pitch 75",), repeats=1))[3]
    record = td.run_record(run, "complete", {"gains": {"at_start": {"k_p": 10.0, "t_rec": 1.0}},
                                             "start": {"ros_time": 12.3456789, "wall": "2026-01-01T12:00:00"}})
    assert record["run"] == "04_table1_pitch_75_r1" and record["kind"] == "table1" and record["status"] == "complete"
    assert record["row"] == "pitch 75" and record["repeat"] == 1 and record["t_rec"] == 1.0
    assert record["holds"][0] == [0.0, 75.0, 43.4, 180.0] and record["start"]["ros_time"] == 12.345679
    with pytest.raises(ValueError, match="status"):
        td.run_record(run, "done", {})
    plan = td.plan_record(td.day_plan(), td.DayOptions(), "tank 18 C")
    assert plan["notes"] == "tank 18 C" and len(plan["runs"]) == 33 and plan["options"]["repeats"] == 2
