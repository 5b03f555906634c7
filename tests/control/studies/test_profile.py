"""Profile of one tank parameter: each refit holds it at its value and starts where the report's fits ended,
the folds predict their held-out groups, the report's free fit is rerun as the reference, and bad input
is refused before any trial runs."""
from __future__ import annotations

import json
import math
import os
from typing import Any, Dict, List

import pytest

from quadruped_control import simulate
from quadruped_control.studies import StudyError
from quadruped_control.studies import identify_objective as ido, identify_parameters as idp
from quadruped_control.studies import paper_experiments as pe
from quadruped_control.studies import profile as pro
from quadruped_control.studies.runner import code_source
from tests.control.studies.fake_trials import fake_summary


@pytest.fixture(scope="module")
def fake_trials():
    """Only the plumbing is under test: the identification's and the profile's CLI, Evaluator and trial runner
    run for real, each trial's simulation is :func:`~tests.control.studies.fake_trials.fake_summary`
    (test_identify_cli_tiny_run runs the same Evaluator on real trials)."""
    from quadruped_control.studies import trial

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(trial, "run_batch", lambda specs: [fake_summary(s) for s in specs])
        patch.setattr(trial, "run_trial", fake_summary)
        patch.setattr(ido, "run_batch", lambda specs: [])  # the Evaluator's compile of the batch's loops
        attitudes, real = {}, pe.initial_attitude  # a root search per Table-1 row for every Evaluator: once

        def initial_attitude(*args):
            if args not in attitudes:
                attitudes[args] = real(*args)
            return attitudes[args]

        patch.setattr(pe, "initial_attitude", initial_attitude)
        yield


@pytest.fixture(scope="module")
def tiny_report(tmp_path_factory, fake_trials) -> str:
    """An identification of three parameters on fake trials (only the plumbing is under test: fake_trials)."""
    pytest.importorskip("SALib")
    out = str(tmp_path_factory.mktemp("identify"))
    assert simulate.main(["--study", "identify", "--screen", "2", "--evaluations", "2", "--cv-evaluations", "2",
                          "--popsize", "2", "--ensemble", "1", "--duration", "0.2", "--out", out, "--quiet",
                          "--jobs", "1", "--parameters", "center_of_buoyancy_z", "net_weight", "servo_lag_scale"]) == 0
    return os.path.join(out, "identify.json")


def test_a_profile_holds_the_parameter_refits_the_others_and_predicts_every_group(tiny_report, tmp_path) -> None:
    out = str(tmp_path / "profile")
    assert pro.main([tiny_report, "--parameter", "center_of_buoyancy_z", "--values", "0.002", "-0.001", "--evaluations", "2",
                     "--cv-evaluations", "2", "--popsize", "2", "--out", out, "--quiet"]) == 0
    with open(tiny_report) as stream:
        report = json.load(stream)
    with open(os.path.join(out, "profile.json")) as stream:
        result = json.load(stream)
    assert [p["value"] for p in result["points"]] == [0.002, -0.001]  # in the command's order
    not_fitted = {n: v for n, v in report["fit"]["best"]["values"].items()
                  if n not in ("center_of_buoyancy_z", "net_weight", "servo_lag_scale")}
    for point in result["points"]:
        fits = [point["fit"]["best"]] + [fold["fit"] for fold in point["cross_validation"]]
        for fitted in fits:
            assert fitted["values"]["center_of_buoyancy_z"] == point["value"]
            for name, value in not_fitted.items():  # the report's values, untouched
                assert fitted["values"][name] == value
        for fold in point["cross_validation"]:  # the held-out prediction is of the fold's own fit
            assert fold["prediction"]["values"] == fold["fit"]["values"]
        assert [f["held_out"] for f in point["cross_validation"]] == list(ido.GROUPS)
        assert [f["prediction"]["targets"]["cases"] for f in point["cross_validation"]] == [6, 6, 3]
        assert point["held_out"] == pro.summed_targets(point["cross_validation"])
        assert point["held_out"]["cases"] == 15 and point["fit"]["best"]["targets"]["cases"] == 15
        assert point["held_out_objective"] == pytest.approx(
            sum(f["prediction"]["objective"] for f in point["cross_validation"]))
    # the report's free fit, rerun on this code, reproduces the report's figures
    free = result["free"]
    assert free["value"] == report["fit"]["best"]["values"]["center_of_buoyancy_z"]
    assert free["objective"] == pytest.approx(report["fit"]["best"]["objective"], abs=1e-9)
    assert free["held_out_objective"] == pytest.approx(free["report_held_out_objective"], abs=1e-9)
    assert result["command"][-1] == "--quiet" and len(result["report_sha256"]) == 64 and result["code"]
    assert result["code_source"] == code_source()
    with open(os.path.join(out, "profile.md")) as stream:
        text = stream.read()
    assert 0 < text.index("| -0.001 |") < text.index("| 0.002 |")  # the table by value
    assert os.path.getsize(os.path.join(out, "profile.png")) > 0


class _FakeEvaluator:
    """Stands in for identify.Evaluator: the experiments of each group, and results without trials."""

    trials = 0

    def cases(self, groups) -> List[int]:
        return [k for g in groups for k in {"roll": [0, 1], "pitch": [2, 3], "roll+pitch": [4]}[g]]

    def __call__(self, sets, cases, tag) -> List[Dict[str, Any]]:
        counts = dict.fromkeys(pro.COUNTS, 1)
        return [{"values": dict(v), "objective": 1.0, "targets": counts, "rows": [], "cases": list(cases)}
                for v in sets]


def _report() -> Dict[str, Any]:
    values = {"center_of_buoyancy_z": -0.003, "net_weight": 2.0, "servo_lag_scale": 5.0, "hook_z": 0.07}
    folds = [{"held_out": g, "fit": {"values": dict(values, net_weight=1.0 + i)}} for i, g in enumerate(ido.GROUPS)]
    return {"study": "identify", "identified": ["center_of_buoyancy_z", "net_weight", "servo_lag_scale"], "seed": 7,
            "duration": 160.0, "servo_model": "rate-limited", "fit": {"best": {"values": values}},
            "cross_validation": folds}


def test_each_refit_starts_from_the_reports_fit_of_the_same_experiments(monkeypatch) -> None:
    calls = []

    def fake_fit(evaluate, names, fixed, start, budget, popsize, seed, cases, tag, sigma):
        calls.append(dict(names=list(names), fixed=dict(fixed), start=dict(start), budget=budget, seed=seed,
                          cases=list(cases), sigma=sigma))
        return [{"values": dict(start), "objective": 2.0, "targets": {}, "rows": []}]

    monkeypatch.setattr(pro, "fit", fake_fit)
    report = _report()
    point = pro.profile_point(_FakeEvaluator(), report, "center_of_buoyancy_z", 0.001, 30, 20, 4, 0.1)
    full, *folds = calls
    assert full["names"] == ["net_weight", "servo_lag_scale"]  # the held parameter is not fitted
    assert full["start"] == dict(report["fit"]["best"]["values"], center_of_buoyancy_z=0.001) == full["fixed"]
    assert (full["budget"], full["seed"], full["sigma"], full["cases"]) == (30, 7, 0.1, [0, 1, 2, 3, 4])
    for call, fold in zip(folds, report["cross_validation"]):
        assert call["start"] == dict(fold["fit"]["values"], center_of_buoyancy_z=0.001)
        assert (call["budget"], call["seed"]) == (20, 8)
        held = _FakeEvaluator().cases([fold["held_out"]])
        assert call["cases"] == [k for k in range(5) if k not in held]  # trained without the held-out group
    assert point["held_out"]["cases"] == 3 and point["held_out_objective"] == 3.0


def test_a_profile_that_leaves_one_parameter_to_fit_is_refused_by_name() -> None:
    report = dict(_report(), identified=["center_of_buoyancy_z", "net_weight"])
    with pytest.raises(StudyError, match="holding center_of_buoyancy_z leaves net_weight to fit; CMA-ES fits two or more"):
        pro.profile_point(_FakeEvaluator(), report, "center_of_buoyancy_z", 0.0, 2, 2, 2, 0.1)


@pytest.mark.parametrize("value", [0.005, -0.0041, math.nan, math.inf])
def test_values_outside_the_bounds_are_refused(value) -> None:
    with pytest.raises(StudyError, match=r"center_of_buoyancy_z = .* lies outside its bounds -0.004 .. 0.004"):
        pro.check_values("center_of_buoyancy_z", [0.0, value])


def test_bad_command_lines_and_reports_fail_before_any_trial(tmp_path, capsys, tiny_report) -> None:
    for argv in (["--parameter", "wake_speed", "--values", "0"], ["--parameter", "center_of_buoyancy_z", "--values", "0",
                                                                  "--sigma", "0"],
                 ["--parameter", "center_of_buoyancy_z", "--values", "0", "--evaluations", "0"], ["--parameter", "center_of_buoyancy_z"]):
        with pytest.raises(SystemExit):
            pro.main([tiny_report, "--out", str(tmp_path / "x")] + argv)
    assert pro.main([tiny_report, "--parameter", "center_of_buoyancy_z", "--values", "0.01", "--out", str(tmp_path / "y")]) == 1
    assert "center_of_buoyancy_z = 0.01 lies outside its bounds" in capsys.readouterr().err
    assert not os.path.exists(str(tmp_path / "y"))  # refused before anything ran
    missing = str(tmp_path / "none.json")
    assert pro.main([missing, "--parameter", "center_of_buoyancy_z", "--values", "0"]) == 1
    assert "cannot read the identification report" in capsys.readouterr().err
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"study": "paper-experiments"}))
    assert pro.main([str(other), "--parameter", "center_of_buoyancy_z", "--values", "0"]) == 1
    assert "is not an identification report" in capsys.readouterr().err
    partial = tmp_path / "partial.json"
    partial.write_text(json.dumps({"study": "identify", "identified": [], "fit": {}, "cross_validation": [],
                                   "seed": 0, "duration": 1.0}))
    assert pro.main([str(partial), "--parameter", "center_of_buoyancy_z", "--values", "0"]) == 1
    assert "has no 'servo_model'" in capsys.readouterr().err


def test_a_tank_yaml_other_than_the_identifications_is_refused_by_the_keys_that_differ(tiny_report, tmp_path,
                                                                                      capsys) -> None:
    from quadruped_common.config import config_path

    with open(config_path("tank.yaml")) as stream:
        text = idp.update_tank_yaml(stream.read(), {"center_of_buoyancy_z": 0.003, "net_weight": 2.5}, "another trim")
    other = tmp_path / "other_tank.yaml"
    other.write_text(text)
    assert pro.main([tiny_report, "--parameter", "servo_lag_scale", "--values", "2", "--tank-yaml", str(other),
                     "--out", str(tmp_path / "z")]) == 1
    err = capsys.readouterr().err
    assert "is not the tank yaml the identification started from (center_of_buoyancy_z, net_weight differ" in err
    assert not os.path.exists(str(tmp_path / "z"))
    broken = tmp_path / "broken.yaml"
    broken.write_text("tank: [1, 2\n")
    with pytest.raises(StudyError, match="cannot load the tank parameters"):
        pro.check_base({"nominal": {}}, str(broken))
