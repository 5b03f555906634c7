"""Run a study's trials on a ``concurrent.futures`` executor, with a progress bar and resume.

The interface is three things: a *trial function* ``fn(spec) -> dict`` (a module-level function, so it
pickles), a list of *specs* (picklable, e.g. frozen dataclasses) and an *output folder*. ::

    from quadruped_control.studies import run_trials
    results = run_trials(run_trial, specs, "out/my_study", jobs=2)                 # local processes
    results = run_trials(run_trial, specs, "out/my_study", dask_scheduler="tcp://host:8786")  # Dask

``results[i]`` belongs to ``specs[i]``. Each finished trial is written at once to
``<out>/trials/<key>.json`` (the key is the spec's label and a hash of all its fields, see
:func:`spec_key`); a rerun with the same folder and the same specs loads those files instead of running
the trials again, so an interrupted study resumes where it stopped and a changed spec is run afresh.
Results are JSON (numpy arrays become lists); every result, fresh or resumed, is returned as read back
from its file, so a resumed study and a fresh one see the same values.

Executors: ``jobs == 1`` runs in this process (no executor); ``jobs > 1`` a
:class:`~concurrent.futures.ProcessPoolExecutor`; ``dask_scheduler`` an existing Dask cluster through
``distributed.Client(address).get_executor()``; or pass any ``concurrent.futures.Executor`` as
``executor`` (the tests use a Dask ``LocalCluster``). The progress bar (tqdm, on stderr) shows finished
trials, the rate and the ETA.
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import re
import sys
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence

import numpy as np

__all__ = ["StudyError", "run_trials", "spec_key", "trial_path"]

TrialFn = Callable[[Any], Dict[str, Any]]


class StudyError(RuntimeError):
    """A trial failed; the trials finished before it are kept in the output folder."""


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def spec_key(spec: Any) -> str:
    """File name stem of a spec's result: its ``label`` (made file-safe) and a hash of all its fields
    (dataclasses: ``dataclasses.asdict``; other objects: ``repr``)."""
    if dataclasses.is_dataclass(spec) and not isinstance(spec, type):
        text = json.dumps(_jsonable(dataclasses.asdict(spec)), sort_keys=True)
    else:
        text = repr(spec)
    digest = hashlib.sha1(text.encode("utf-8")).hexdigest()[:12]
    label = str(getattr(spec, "label", "") or "trial")
    slug = re.sub(r"[^A-Za-z0-9_.+-]+", "_", label).strip("_")[:60] or "trial"
    return "%s-%s" % (slug, digest)


def trial_path(out_dir: str, spec: Any) -> str:
    """Where the result of ``spec`` is stored under the study folder ``out_dir``."""
    return os.path.join(out_dir, "trials", spec_key(spec) + ".json")


def _write_atomic(path: str, result: Dict[str, Any]) -> None:
    tmp = "%s.tmp%d" % (path, os.getpid())
    with open(tmp, "w") as stream:
        json.dump(_jsonable(result), stream, allow_nan=True)
    os.replace(tmp, path)


def _load(path: str) -> Optional[Dict[str, Any]]:
    try:
        with open(path) as stream:
            return json.load(stream)
    except (OSError, ValueError):
        return None  # missing or half-written (killed mid-write is impossible with os.replace, but be safe)


@contextlib.contextmanager
def _executor(jobs: int, dask_scheduler: Optional[str], n: int) -> Iterator[Optional[Executor]]:
    if dask_scheduler:
        try:
            from distributed import Client
        except ImportError as exc:  # pragma: no cover - distributed is in requirements.txt
            raise StudyError("--dask-scheduler needs the 'distributed' package: %s" % exc)
        client = Client(dask_scheduler)
        try:
            yield client.get_executor()
        finally:
            client.close()
    elif jobs > 1 and n > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, n)) as pool:
            yield pool
    else:
        yield None


def _progress(total: int, initial: int, desc: str, show: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=desc or "trials", unit="trial", disable=not show,
                file=sys.stderr, dynamic_ncols=True, smoothing=0.1)


def run_trials(fn: TrialFn, specs: Sequence[Any], out_dir: Optional[str], jobs: int = 1,
               dask_scheduler: Optional[str] = None, executor: Optional[Executor] = None,
               resume: bool = True, progress: bool = True, desc: str = "") -> List[Dict[str, Any]]:
    """Run ``fn(spec)`` for every spec; return the results in the order of ``specs``.

    ``out_dir`` None keeps nothing on disk (no resume). ``resume=False`` runs every trial again (and
    overwrites its file). A trial that raises stops the study with :class:`StudyError` after the running
    trials are cancelled; the finished ones stay on disk for the next run.
    """
    if jobs < 1:
        raise ValueError("jobs must be at least 1, got %r" % (jobs,))
    paths: List[Optional[str]] = [None] * len(specs)
    results: List[Optional[Dict[str, Any]]] = [None] * len(specs)
    if out_dir is not None:
        os.makedirs(os.path.join(out_dir, "trials"), exist_ok=True)
        paths = [trial_path(out_dir, spec) for spec in specs]
        if len(set(paths)) != len(paths):
            raise ValueError("two specs of the study are identical (same key); give them distinct labels")
        if resume:
            for i, path in enumerate(paths):
                results[i] = _load(path)  # type: ignore[arg-type]
    todo = [i for i, r in enumerate(results) if r is None]

    def finish(i: int, result: Dict[str, Any]) -> None:
        if paths[i] is not None:
            _write_atomic(paths[i], result)  # type: ignore[arg-type]
            results[i] = _load(paths[i])  # type: ignore[arg-type]
        else:
            results[i] = json.loads(json.dumps(_jsonable(result), allow_nan=True))

    with _progress(len(specs), len(specs) - len(todo), desc, progress) as bar:
        with _executor(jobs, dask_scheduler, len(todo)) as pool:
            pool = executor if executor is not None else pool
            if pool is None:
                for i in todo:
                    try:
                        finish(i, fn(specs[i]))
                    except Exception as exc:
                        raise StudyError("trial %r failed: %s" % (getattr(specs[i], "label", i), exc)) from exc
                    bar.update(1)
            else:
                futures: Dict[Future, int] = {pool.submit(fn, specs[i]): i for i in todo}
                try:
                    for future in as_completed(futures):
                        i = futures[future]
                        try:
                            finish(i, future.result())
                        except Exception as exc:
                            raise StudyError("trial %r failed: %s"
                                             % (getattr(specs[i], "label", i), exc)) from exc
                        bar.update(1)
                finally:
                    for future in futures:
                        future.cancel()
    return results  # type: ignore[return-value]
