"""quadruped_common.jit: the compile-or-plain decorators and the cache's source fingerprint."""
from __future__ import annotations

import os

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
    import numpy as np

    a, b = np.arange(5.0), np.ones(5)
    assert compiled.py_func is hypot_sum
    assert abs(compiled(a, b) - hypot_sum(a, b)) < 1e-12
