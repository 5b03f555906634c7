"""runner.run_trial_batches: chunks, per-trial files, resume across the two runners, errors."""
from __future__ import annotations

import dataclasses
import json
import os
from concurrent.futures import ThreadPoolExecutor

import pytest

from quadruped_control.studies.runner import StudyError, _chunks, run_trial_batches, run_trials, trial_path


@dataclasses.dataclass(frozen=True)
class Spec:
    label: str
    x: float


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
