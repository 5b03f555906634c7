"""The study runner: executors (inline, processes, Dask LocalCluster), ordering, resume, failures, batched
trial functions, and the key that covers code and configuration."""
from __future__ import annotations

import dataclasses
import json
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Dict

import numpy as np
import pytest

from quadruped_control import simulate
from quadruped_control.studies import trial
from quadruped_control.studies import StudyError, run_trials, spec_key, trial_path
from quadruped_control.studies import runner
from quadruped_control.studies.runner import _chunks, run_trial_batches


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


# ---- batched trial functions (run_trial_batches) ------------------------------------------------

CALLS = []


def square_one(spec):
    return {"label": spec.label, "y": spec.x * spec.x}


def square_many(specs):
    CALLS.append(len(specs))
    return [square_one(spec) for spec in specs]


def broken_many(specs):
    if any(spec.x == 3.0 for spec in specs):
        raise RuntimeError("diverged")
    return [square_one(spec) for spec in specs]


def test_chunks_cover_everything_in_order_with_one_chunk_per_worker_at_least():
    assert _chunks([], 10, 2) == []
    assert _chunks(list(range(7)), 10, 1) == [list(range(7))]
    assert _chunks(list(range(7)), 10, 2) == [[0, 1, 2, 3], [4, 5, 6]]
    chunks = _chunks(list(range(25)), 10, 2)
    assert [i for c in chunks for i in c] == list(range(25)) and max(map(len, chunks)) <= 10 and len(chunks) == 3


def test_batches_write_one_file_per_trial_and_resume_with_the_per_trial_runner(tmp_path):
    specs = [Spec("t%d" % i, float(i)) for i in range(9)]
    CALLS.clear()
    out = str(tmp_path)
    results = run_trial_batches(square_many, specs, out, batch_size=4, progress=False)
    assert [r["y"] for r in results] == [float(i * i) for i in range(9)]
    assert sorted(CALLS) == [1, 4, 4] or sorted(CALLS) == [3, 3, 3]
    for spec in specs:
        with open(trial_path(out, spec)) as stream:
            assert json.load(stream)["label"] == spec.label
    # the per-trial runner resumes from the batch's files: nothing runs again
    os.remove(trial_path(out, specs[4]))
    again = run_trials(square_one, specs, out, progress=False)
    assert again == results
    CALLS.clear()
    assert run_trial_batches(square_many, specs, out, batch_size=4, progress=False) == results
    assert CALLS == []


def test_batches_on_an_executor_and_a_failing_batch_keeps_the_finished_ones(tmp_path):
    specs = [Spec("t%d" % i, float(i)) for i in range(6)]
    with ThreadPoolExecutor(2) as pool:
        results = run_trial_batches(square_many, specs, None, batch_size=2, executor=pool, progress=False)
    assert [r["y"] for r in results] == [float(i * i) for i in range(6)]
    with pytest.raises(StudyError, match="diverged"):
        run_trial_batches(broken_many, specs, str(tmp_path), batch_size=2, progress=False)
    kept = [os.path.exists(trial_path(str(tmp_path), spec)) for spec in specs]
    assert kept[:2] == [True, True] and kept[2:4] == [False, False]


def test_batches_refuse_bad_arguments():
    with pytest.raises(ValueError):
        run_trial_batches(square_many, [], None, batch_size=0)
    with pytest.raises(ValueError):
        run_trial_batches(square_many, [], None, jobs=0)


# ---- the key covers the code and the configuration ------------------------------------------------

def test_code_fingerprint_changes_with_any_source_file(tmp_path) -> None:
    for top in runner.CODE_ROOTS:
        os.makedirs(tmp_path / top, exist_ok=True)
        (tmp_path / top / "m.py").write_text("x = 1\n")
    (tmp_path / "quadruped_control" / "ros").mkdir()
    (tmp_path / "quadruped_control" / "ros" / "node.py").write_text("y = 1\n")
    fingerprint = runner.code_fingerprint.__wrapped__  # uncached
    first = fingerprint(str(tmp_path))
    (tmp_path / "quadruped_control" / "ros" / "node.py").write_text("y = 2\n")
    assert fingerprint(str(tmp_path)) == first  # the ROS glue computes no trial
    (tmp_path / "quadruped_control" / "model" / "m.py").write_text("x = 2\n")
    assert fingerprint(str(tmp_path)) != first
    assert len(runner.code_fingerprint()) == 64 and runner.code_fingerprint() == runner.code_fingerprint()


def test_a_changed_config_file_or_code_runs_the_trial_again_and_says_so(tmp_path, monkeypatch, capsys) -> None:
    config = tmp_path / "config"
    config.mkdir()
    (config / "robot.yaml").write_text("mass: 4.9\n")
    original = runner.config_fingerprint
    monkeypatch.setattr(runner, "config_fingerprint", lambda spec: original(spec, str(config)))
    calls = []

    def counted(spec):
        calls.append(spec.label)
        return square(spec)

    specs = [Spec("a", 1.0), Spec("b", 2.0)]
    out = str(tmp_path / "out")
    run_trials(counted, specs, out, progress=False)
    run_trials(counted, specs, out, progress=False)
    assert calls == ["a", "b"]  # unchanged: resumed
    (config / "robot.yaml").write_text("mass: 5.1\n")
    run_trials(counted, specs, out, progress=True)
    assert calls == ["a", "b", "a", "b"]
    assert "2 result file(s)" in capsys.readouterr().err
    monkeypatch.setattr(runner, "code_fingerprint", lambda: "other code")
    run_trials(counted, specs[:1], out, progress=False)
    assert calls[-1] == "a" and len(calls) == 5


def test_a_file_named_by_a_spec_is_part_of_its_key(tmp_path) -> None:
    @dataclasses.dataclass(frozen=True)
    class FileSpec:
        label: str
        tank_yaml: str

    path = tmp_path / "tank.yaml"
    path.write_text("rope_length: 0.5\n")
    spec = FileSpec("t", str(path))
    first = spec_key(spec)
    assert spec_key(spec) == first
    path.write_text("rope_length: 0.6\n")
    os.utime(path, ns=(1, 1))  # a new size or time: the remembered hash is not used
    assert spec_key(spec) != first


def test_unused_result_files_are_reported_once_per_folder(tmp_path, capsys):
    from quadruped_control.studies import runner

    folder = tmp_path / "trials"
    folder.mkdir()
    (folder / "old.json").write_text("{}")
    assert runner._report_stale(str(tmp_path), [], True) == 1
    assert runner._report_stale(str(tmp_path), [], True) == 1  # counted again, said once
    assert capsys.readouterr().err.count("not reused") == 1


def _git(repo, *arguments: str) -> None:
    import subprocess
    subprocess.run(["git", "-C", str(repo), "-c", "user.name=test", "-c", "user.email=test@example.com"]
                   + list(arguments), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_code_source_names_the_commit_and_every_source_that_differs_from_it(tmp_path, capsys) -> None:
    source = runner.code_source.__wrapped__  # uncached
    for top in runner.CODE_ROOTS:
        os.makedirs(tmp_path / top, exist_ok=True)
        (tmp_path / top / "m.py").write_text("x = 1\n")
    (tmp_path / "README.md").write_text("read me\n")
    # not a checkout (an install space): nothing is known but the fingerprint
    assert source(str(tmp_path)) == {"commit": None, "modified": None}
    assert runner.describe_source(source(str(tmp_path))) == "not a git checkout"
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", "-A")
    _git(tmp_path, "commit", "-q", "-m", "first")
    clean = source(str(tmp_path))
    assert len(clean["commit"]) == 40 and clean["modified"] == []
    assert runner.describe_source(clean) == "commit %s" % clean["commit"][:12]
    # what the fingerprint hashes, changed or new, is named; other files are not
    (tmp_path / "quadruped_control" / "model" / "m.py").write_text("x = 2\n")
    (tmp_path / "quadruped_control" / "sim" / "new.py").write_text("y = 1\n")
    (tmp_path / "README.md").write_text("changed\n")
    (tmp_path / "quadruped_control" / "sim" / "notes.txt").write_text("not code\n")
    dirty = source(str(tmp_path))
    assert dirty == {"commit": clean["commit"],
                     "modified": ["quadruped_control/model/m.py", "quadruped_control/sim/new.py"]}
    assert runner.describe_source(dirty).endswith(
        "with 2 uncommitted file(s): quadruped_control/model/m.py, quadruped_control/sim/new.py")
    # a tree inside another checkout's folder is not that checkout's code
    inner = tmp_path / "install" / "lib"
    for top in runner.CODE_ROOTS:
        os.makedirs(inner / top, exist_ok=True)
    assert source(str(inner)) == {"commit": None, "modified": None}


def test_warn_uncommitted_says_so_only_for_a_dirty_tree(tmp_path, monkeypatch, capsys) -> None:
    import io
    monkeypatch.setattr(runner, "code_source", lambda root=None: {"commit": "a" * 40, "modified": []})
    stream = io.StringIO()
    assert runner.warn_uncommitted(stream)["modified"] == [] and stream.getvalue() == ""
    modified = ["quadruped_control/sim/m%d.py" % i for i in range(7)]
    monkeypatch.setattr(runner, "code_source", lambda root=None: {"commit": "b" * 40, "modified": modified})
    runner.warn_uncommitted(stream)
    text = stream.getvalue()
    assert text.startswith("warning: 7 file(s) of the study's code differ from commit bbbbbbbbbbbb")
    assert "m4.py, ..." in text and "m5.py" not in text and "commit first" in text
    # a study run from the command line warns before any trial runs
    assert simulate.main(["--study", "paper-sim", "--duration", "0.05", "--jobs", "1", "--quiet",
                          "--out", str(tmp_path / "s")]) in (0, 2)
    assert "warning: 7 file(s) of the study's code differ" in capsys.readouterr().err
