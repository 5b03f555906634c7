"""A tank day's folder as the studies read it (quadruped_control/studies/day_folder.py): the runs a study can use and a
line for every one left out or lacking something; the studies given such a folder say it and stop clearly."""
import math
import os

import numpy as np
import pytest
import yaml

from quadruped_control.control import tank_day as td
from quadruped_control.studies import StudyError
from quadruped_control.studies import day_folder as df
from quadruped_control.studies import hang, identify_bags, step_test, table1_bags

pytest.importorskip("rosbags")
from tests.control.studies.test_hang import _write_imu_bag  # noqa: E402


def _day(tmp_path) -> str:
    """A day of the plan with roll 30 twice: a hang recorded with its record, the tether skipped, the step test's
    record lost (its bag only), roll 30's first repeat aborted then recorded on a second attempt without
    /controller_state, and its second repeat never reached."""
    day = tmp_path / "day"
    day.mkdir()
    plan = td.day_plan(td.DayOptions(rows=("roll 30",), repeats=2))
    (day / td.PLAN_FILE).write_text(yaml.safe_dump(td.plan_record(plan, td.DayOptions(rows=("roll 30",)))))
    t = np.arange(0.0, 30.0, 0.05)
    level = np.tile([0.0, 0.0, 0.0, 1.0], (t.size, 1))

    def run(name, status=None, bag=True, **log):
        folder = day / name
        folder.mkdir()
        if bag:
            _write_imu_bag(str(folder / "uq_0.bag"), t, level)
        if status:
            planned = next(r for r in plan if r.name == td.parse_run_name(name)["planned"])
            (folder / td.RUN_FILE).write_text(yaml.safe_dump(td.run_record(planned, status, log)))

    run("01_hang", "complete")
    run("02_tether", "skipped", bag=False, why="skipped by the operator")
    run("03_step_test")
    run("04_table1_roll_30_r1", "aborted", why="arming refused: no heartbeat")
    run("04_table1_roll_30_r1_a2", "ended early", why="ended by the operator")
    return str(day)


def test_the_runs_a_study_can_use_and_a_line_for_each_left_out_or_lacking(tmp_path) -> None:
    day = _day(tmp_path)
    runs, missing = df.day_runs(day, ("hang",), needs=("/imu/data",), wants=("/joint_states",))
    assert [run.name for run in runs] == ["01_hang"] and missing == ["01_hang: the bag has no /joint_states"]
    assert runs[0].bags == [os.path.join(day, "01_hang", "uq_0.bag")] and runs[0].record["status"] == "complete"
    runs, missing = df.day_runs(day, ("step_test", "table1"), needs=("/imu/data", "/controller_state"))
    assert runs == []
    assert missing == [
        "05_table1_roll_30_r2: planned, not in the folder (the day ended before it)",
        "03_step_test: no run.yaml (its record): kind from the folder's name; gains, configuration, code version and "
        "legs unknown",
        "03_step_test: the bag has no /controller_state: left out",
        "04_table1_roll_30_r1: aborted (arming refused: no heartbeat): left out",
        "04_table1_roll_30_r1_a2: ended early (ended by the operator): read as far as it goes",
        "04_table1_roll_30_r1_a2: the bag has no /controller_state: left out"]
    runs, missing = df.day_runs(day, ("tether",))
    assert runs == [] and missing == ["02_tether: skipped (skipped by the operator): left out"]
    one, _ = df.day_runs(os.path.join(day, "04_table1_roll_30_r1_a2"), ("table1",))
    assert [(run.row, run.repeat) for run in one] == [("roll 30", 1)]
    assert df.missing_text(["a"]) == ["", "Missing from the day's folder:", "", "- a"] and df.missing_text([]) == []


def test_a_folder_without_a_plan_says_so_and_a_run_folder_of_another_kind_is_named(tmp_path) -> None:
    folder = tmp_path / "loose"
    (folder / "01_hang").mkdir(parents=True)
    _write_imu_bag(str(folder / "01_hang" / "a.bag"), np.arange(0.0, 1.0, 0.1), np.tile([0, 0, 0, 1.0], (10, 1)))
    (folder / "09_tether").mkdir()
    runs, missing = df.day_runs(str(folder), ("hang",))
    assert [run.name for run in runs] == ["01_hang"] and missing[0].endswith("which runs were planned is unknown")
    runs, missing = df.day_runs(str(folder / "01_hang"), ("step_test",))
    assert runs == [] and missing == ["01_hang: a hang run, not step_test"]


def test_each_study_given_a_day_without_its_run_says_what_is_missing_and_stops(tmp_path, capsys) -> None:
    day = _day(tmp_path)
    out = str(tmp_path / "out")
    with pytest.raises(StudyError, match="no usable step_test run"):
        df.one_run(day, "step_test", "step_test", needs=("/imu/data", "/controller_state"))
    assert step_test.main([day, "--out", out]) == 1
    assert table1_bags.main([day, "--out", out]) == 1
    assert identify_bags.main([day, "--out", out]) == 1
    err = capsys.readouterr().err
    assert "step_test: no usable step_test run in %s\n  - 03_step_test: no run.yaml" % day in err
    assert "table1_bags: missing: 05_table1_roll_30_r2: planned, not in the folder" in err
    assert "table1_bags: no Table-1 run could be measured" in err
    assert "identify_bags: no usable step-test or Table-1 run in %s\n  - 05_table1_roll_30_r2" % day in err
    assert hang.main([os.path.join(day, "02_tether"), "--out", out]) == 1
    assert "hang: no usable hang run" in capsys.readouterr().err


def test_the_step_tests_models_run_the_gains_of_the_bag_else_of_the_runs_record() -> None:
    record = step_test.StepRecord(np.array([0.0, 1.0]), np.zeros((2, 3)), [], "r")
    record.gains = {"gains": {"k_p": 7.0, "k_i": 1.0, "t_rec": 1.0, "stroke_scheme": "paper"}, "gain_changes": [{}]}
    gains, source = step_test.record_gains(record, {"gains": {"at_start": {"k_p": 9.0}}})
    assert gains["k_p"] == 7.0 and "parameter_updates (changed 1 time(s)" in source
    record.gains = {"gains": None, "gain_changes": []}
    assert step_test.record_gains(record, {"gains": {"at_start": {"k_p": 9.0}}}) == (
        {"k_p": 9.0}, "the run's run.yaml (the bag has no parameter_updates)")
    assert step_test.record_gains(record, None)[0] is None
    overrides = dict(step_test.gains_overrides({"k_p": 7.0, "t_rec": 1.0, "stroke_scheme": "coordinated"}))
    assert overrides["gains"].k_p == 7.0 and overrides["gains"].k_i == 3.0  # the rest: the experiment set's
    assert (overrides["t_rec"], overrides["stroke_scheme"]) == (1.0, "coordinated")
    assert step_test.gains_overrides(None) == ()
    spec = step_test.step_test_spec("t.yaml", 0, (), 0.0, None, (0.0, 0.0, 0.0),
                                    config_overrides=tuple(overrides.items()))
    assert dict(spec.config_overrides)["t_rec"] == 1.0 and not math.isnan(spec.duration)


def test_table_1_of_the_day_is_the_papers() -> None:
    from quadruped_control.studies.paper_experiments import PAPER_TABLE

    assert [(s, c, p, t) for s, c, p, t in td.TABLE_1] == [
        (row["set"], row["cmd"], row["psi_init"], row["t_rec"]) for row in PAPER_TABLE]
