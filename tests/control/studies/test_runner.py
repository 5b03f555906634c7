"""The study runner: executors (inline, processes, Dask LocalCluster), ordering, resume, failures."""
from __future__ import annotations

import dataclasses
import json
import os
from typing import Any, Dict

import numpy as np
import pytest

from quadruped_control import simulate
from quadruped_control.studies import trial
from quadruped_control.studies import StudyError, run_trials, spec_key, trial_path


@dataclasses.dataclass(frozen=True)
class Spec:
    label: str
    x: float


def square(spec: Spec) -> Dict[str, Any]:
    if spec.x < 0:
        raise ValueError("negative input")
    return {"label": spec.label, "y": np.float64(spec.x) ** 2, "trace": np.arange(3) * spec.x}


def test_inline_results_in_spec_order_and_json_round_trip(tmp_path) -> None:
    specs = [Spec("a", 1.0), Spec("b", 2.0), Spec("c", 3.0)]
    results = run_trials(square, specs, str(tmp_path), progress=False)
    assert [r["y"] for r in results] == [1.0, 4.0, 9.0]
    assert results[2]["trace"] == [0.0, 3.0, 6.0]
    for spec in specs:
        with open(trial_path(str(tmp_path), spec)) as stream:
            assert json.load(stream)["label"] == spec.label


def test_resume_skips_finished_trials_and_reruns_changed_specs(tmp_path) -> None:
    calls = []

    def counting(spec: Spec) -> Dict[str, Any]:
        calls.append(spec.label)
        return square(spec)

    specs = [Spec("a", 1.0), Spec("b", 2.0)]
    run_trials(counting, specs, str(tmp_path), progress=False)
    assert calls == ["a", "b"]
    again = run_trials(counting, specs + [Spec("b", 5.0)], str(tmp_path), progress=False)
    assert calls == ["a", "b", "b"]  # only the new (changed) spec ran
    assert [r["y"] for r in again] == [1.0, 4.0, 25.0]
    run_trials(counting, specs, str(tmp_path), progress=False, resume=False)
    assert calls == ["a", "b", "b", "a", "b"]


def test_failure_keeps_finished_trials_and_names_the_trial(tmp_path) -> None:
    with pytest.raises(StudyError, match="'bad'"):
        run_trials(square, [Spec("ok", 1.0), Spec("bad", -1.0)], str(tmp_path), progress=False)
    assert os.path.exists(trial_path(str(tmp_path), Spec("ok", 1.0)))
    assert not os.path.exists(trial_path(str(tmp_path), Spec("bad", -1.0)))


def test_bad_arguments_are_rejected(tmp_path) -> None:
    with pytest.raises(ValueError, match="jobs"):
        run_trials(square, [Spec("a", 1.0)], str(tmp_path), jobs=0)
    with pytest.raises(ValueError, match="identical"):
        run_trials(square, [Spec("a", 1.0), Spec("a", 1.0)], str(tmp_path), progress=False)


def test_spec_key_is_file_safe_and_depends_on_every_field() -> None:
    key = spec_key(Spec("roll 15 deg / (R)", 1.0))
    assert "/" not in key and " " not in key
    assert key != spec_key(Spec("roll 15 deg / (R)", 1.5))


def test_process_pool_gives_the_same_results_as_inline(tmp_path) -> None:
    specs = [Spec(str(i), float(i)) for i in range(4)]
    assert run_trials(square, specs, None, jobs=2, progress=False) == run_trials(square, specs, None, progress=False)


def test_small_simulation_study_on_a_dask_local_cluster(tmp_path) -> None:
    distributed = pytest.importorskip("distributed")
    specs = [trial.TrialSpec(label="%g deg" % a, setpoint_rpy_deg=(a, 0.0, 0.0), duration=1.0, quiet=True,
                                keep_trace=False) for a in (10.0, 20.0)]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        on_dask = run_trials(trial.run_trial, specs, str(tmp_path / "dask"), executor=client.get_executor(),
                             progress=False)
    inline = run_trials(trial.run_trial, specs, str(tmp_path / "inline"), progress=False)
    for a, b in zip(on_dask, inline):
        assert a["metrics"] == b["metrics"]


def test_cli_dask_scheduler_address(tmp_path) -> None:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        out = str(tmp_path / "study")
        assert simulate.main(["--study", "paper-sim", "--duration", "0.5", "--out", out, "--quiet",
                              "--dask-scheduler", cluster.scheduler_address]) == 2
        assert len(os.listdir(os.path.join(out, "trials"))) == 3
