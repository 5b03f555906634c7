"""quadruped_common.jit: the compile-or-plain decorators and the cache's source fingerprint."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from quadruped_common import jit


def test_the_fingerprint_follows_every_source_file_and_nothing_else(tmp_path):
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "a.py").write_text("x = 1\n")
    (package / "notes.txt").write_text("not code\n")
    first = jit.source_fingerprint(("pkg",), root=str(tmp_path))
    assert jit.source_fingerprint(("pkg",), root=str(tmp_path)) == first
    (package / "notes.txt").write_text("still not code\n")
    assert jit.source_fingerprint(("pkg",), root=str(tmp_path)) == first
    (package / "a.py").write_text("x = 2\n")
    changed = jit.source_fingerprint(("pkg",), root=str(tmp_path))
    assert changed != first
    (package / "sub").mkdir()
    (package / "sub" / "b.py").write_text("")
    assert jit.source_fingerprint(("pkg",), root=str(tmp_path)) != changed


def test_the_cache_folder_is_named_by_the_kernel_sources(monkeypatch, tmp_path):
    monkeypatch.setenv("UQ_JIT_CACHE", str(tmp_path))
    assert jit._cache_dir() == os.path.join(str(tmp_path), jit.source_fingerprint())


def test_jitable_functions_stay_plain_python_for_python_callers():
    def twice(x):
        return 2.0 * x

    assert jit.jitable(twice) is twice


def test_a_kernel_keeps_its_plain_function_and_computes_the_same():
    def hypot_sum(a, b):
        total = 0.0
        for i in range(a.shape[0]):
            total += (a[i] * a[i] + b[i] * b[i]) ** 0.5
        return total

    compiled = jit.kernel(hypot_sum)
    a, b = np.arange(5.0), np.ones(5)
    assert compiled.py_func is hypot_sum
    assert abs(compiled(a, b) - hypot_sum(a, b)) < 1e-12


def test_a_trial_step_fails_its_trial_alone_in_plain_python_and_compiled():
    """Plain Python raises on 1 / 0 where compiled code (numpy's error model) gives inf: either way the
    step reports the trial failed, and the loop goes on with the next one."""
    def inverse(x, out, i):
        out[i] = 1.0 / x
        return math.isfinite(out[i])

    step = jit.trial_step(inverse)

    def loop(xs, out, good):
        for i in range(xs.shape[0]):
            good[i] = step(xs[i], out, i)

    xs = np.array([2.0, 0.0, 4.0])
    for run in (loop, jit.kernel(loop)):
        out, good = np.zeros(3), np.zeros(3, dtype=bool)
        run(xs, out, good)
        assert good.tolist() == [True, False, True]
        assert out[0] == 0.5 and out[2] == 0.25
    with pytest.raises(ZeroDivisionError):
        inverse(0.0, np.zeros(1), 0)  # the function itself is unchanged
