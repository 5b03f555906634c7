"""Run a study's trials on a ``concurrent.futures`` executor, with a progress bar and resume.

The interface is three things: a *trial function* ``fn(spec) -> dict`` (a module-level function, so it
pickles), a list of *specs* (picklable, e.g. frozen dataclasses) and an *output folder*. ::

    from quadruped_control.studies import run_trials
    results = run_trials(run_trial, specs, "out/my_study", jobs=2)                 # local processes
    results = run_trials(run_trial, specs, "out/my_study", dask_scheduler="tcp://host:8786")  # Dask

A batched trial function ``fn(specs) -> [result, ...]`` (the batched simulator runs many trials at once)
goes through :func:`run_trial_batches` instead: the trials are cut into chunks, one task each, with the
same per-trial files, resume and progress bar (:func:`run_trials` is that with chunks of one).

``results[i]`` belongs to ``specs[i]``. Each finished trial is written at once to
``<out>/trials/<key>.json`` (the key is the spec's label and a hash of all its fields, of the code that
computes a trial and of the configuration files, see :func:`spec_key`); a rerun with the same folder and
the same specs loads those files instead of running the trials again, so an interrupted study resumes
where it stopped, and a changed spec, changed code or a changed config file runs the trial afresh.
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
import functools
import hashlib
import json
import os
import re
import subprocess
import sys
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["CODE_ROOTS", "StudyError", "code_fingerprint", "code_record", "code_source", "command_line",
           "config_fingerprint", "describe_source", "run_trial_batches", "run_trials", "spec_key", "trial_path",
           "warn_uncommitted", "write_study_report"]

TrialFn = Callable[[Any], Dict[str, Any]]
#: ``fn(specs) -> [result, ...]``: many trials at once (the batched simulator), one result per spec, in order.
BatchFn = Callable[[List[Any]], List[Dict[str, Any]]]


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


#: The packages whose code computes a trial: their sources are part of every result's key.
CODE_ROOTS = ("quadruped_common", "quadruped_control/model", "quadruped_control/control", "quadruped_control/sim",
              "quadruped_control/studies")


def _tree_root() -> str:
    """The folder that holds quadruped_common/ and quadruped_control/ (this module's package's parent)."""
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _hash_files(paths: Sequence[str], root: str) -> str:
    digest = hashlib.sha256()
    for path in sorted(paths):
        digest.update(os.path.relpath(path, root).encode("utf-8") + b"\0")
        try:
            with open(path, "rb") as stream:
                digest.update(stream.read())
        except OSError as exc:  # a named file that is gone: its name and the error, not a crash
            digest.update(("unreadable: %s" % exc).encode("utf-8"))
        digest.update(b"\0")
    return digest.hexdigest()


def command_line(module: str, argv: Optional[Sequence[str]] = None) -> List[str]:
    """The command that ran a study, as given (``argv``, or the process's arguments): with
    :func:`code_fingerprint`, what a study's report records of what produced it."""
    return ["python", "-m", module] + list(sys.argv[1:] if argv is None else argv)


@functools.lru_cache(maxsize=8)
def code_fingerprint(root: Optional[str] = None) -> str:
    """sha256 of the Python sources of :data:`CODE_ROOTS` under ``root`` (default: this installation):
    any change to the model, the controller, the simulator or a study's trial code changes it. Computed
    once per process."""
    root = root or _tree_root()
    paths = []
    for top in CODE_ROOTS:
        for folder, dirs, files in os.walk(os.path.join(root, top)):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            paths += [os.path.join(folder, name) for name in files if name.endswith(".py")]
    return _hash_files(paths, root)


def _git(root: str, *arguments: str) -> Optional[str]:
    """``git -C root ARGUMENTS``' output, or None where git is missing or fails (an install space, a tarball)."""
    try:
        done = subprocess.run(["git", "-C", root] + list(arguments), stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.decode("utf-8", "replace") if done.returncode == 0 else None


@functools.lru_cache(maxsize=8)
def code_source(root: Optional[str] = None) -> Dict[str, Any]:
    """Which commit the code of :data:`CODE_ROOTS` under ``root`` (default: this installation) came from:
    ``{"commit": sha, "modified": [paths]}``, the Python sources (relative to ``root``) under
    :data:`CODE_ROOTS` that differ from that commit, untracked ones included. Both are None where ``root``
    is not the top of a git checkout (an install space, an unpacked release): then only
    :func:`code_fingerprint` says what ran.

    Why: the fingerprint hashes the sources as they are when the study starts. A study started with
    uncommitted changes records a fingerprint that no commit has, and its figures cannot be reproduced
    from the history; the reports record this beside the fingerprint and :func:`warn_uncommitted` says
    so before the study runs. Computed once per process, like the fingerprint."""
    root = os.path.realpath(root or _tree_root())
    unknown: Dict[str, Any] = {"commit": None, "modified": None}
    top = _git(root, "rev-parse", "--show-toplevel")
    # a tree inside someone else's checkout (an install space under a workspace that is a repository)
    # is not that checkout's code
    if top is None or os.path.realpath(top.strip()) != root:
        return unknown
    commit = _git(root, "rev-parse", "--verify", "HEAD")
    status = _git(root, "status", "--porcelain", "--untracked-files=all", "--", *CODE_ROOTS)
    if commit is None or status is None:
        return unknown
    # porcelain lines are "XY path" or, for a rename, "XY old -> new"; only the sources the fingerprint hashes
    paths = (line[3:].split(" -> ")[-1].strip().strip('"') for line in status.splitlines() if line.strip())
    modified = sorted(path for path in paths if path.endswith(".py"))
    return {"commit": commit.strip(), "modified": modified}


def code_record() -> Dict[str, Any]:
    """What every study's report records of the code that produced it: ``code``
    (:func:`code_fingerprint`) and ``code_source`` (:func:`code_source`)."""
    return {"code": code_fingerprint(), "code_source": code_source()}


def write_study_report(out: str, name: str, text: str, report: Dict[str, Any],
                       plot: Optional[Callable[[str], None]] = None) -> None:
    """A study's report into ``out`` as ``name``.md (``text``), ``name``.json (``report``, strict JSON) and,
    with ``plot`` (called with the path), ``name``.png; prints the text and what was written."""
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, name + ".md"), "w") as stream:
        stream.write(text)
    with open(os.path.join(out, name + ".json"), "w") as stream:
        json.dump(report, stream, indent=1, allow_nan=False)
    written = [name + ".md", name + ".json"]
    if plot is not None:
        plot(os.path.join(out, name + ".png"))
        written.append(name + ".png")
    print(text)
    print("wrote %s/{%s}" % (out, ", ".join(written)))


def describe_source(source: Dict[str, Any]) -> str:
    """:func:`code_source` in words, for a report: "commit X", "commit X with N uncommitted file(s)", or
    "not a git checkout"."""
    if not source or source.get("commit") is None:
        return "not a git checkout"
    modified = source.get("modified") or []
    return "commit %s%s" % (source["commit"][:12], " with %d uncommitted file(s): %s" % (
        len(modified), ", ".join(modified)) if modified else "")


def warn_uncommitted(stream: Any = None, root: Optional[str] = None) -> Dict[str, Any]:
    """:func:`code_source`, with a warning on ``stream`` (default stderr) when the code has uncommitted
    changes: the study's figures would then come from code that no commit holds."""
    source = code_source(root)
    if source["modified"]:
        shown = ", ".join(source["modified"][:5]) + (", ..." if len(source["modified"]) > 5 else "")
        (stream or sys.stderr).write(
            "warning: %d file(s) of the study's code differ from commit %s (%s): the results' code "
            "fingerprint names no commit; commit first so that the study can be reproduced\n"
            % (len(source["modified"]), source["commit"][:12], shown))
    return source


def config_fingerprint(spec: Any, config_folder: Optional[str] = None) -> str:
    """sha256 of the configuration a trial reads: every YAML file of the package's ``config/`` folder
    (``config_folder``, default :func:`~quadruped_common.config.config_dir`) and every file a spec field
    ending in ``_yaml`` names."""
    from quadruped_common.config import config_dir

    folder = config_folder or config_dir()
    paths = tuple(sorted(os.path.join(folder, name) for name in os.listdir(folder)
                         if name.endswith((".yaml", ".yml"))))
    named: List[str] = []
    if dataclasses.is_dataclass(spec) and not isinstance(spec, type):
        named = [os.path.abspath(value) for name, value in sorted(dataclasses.asdict(spec).items())
                 if name.endswith("_yaml") and isinstance(value, str)]
    return _hashed(paths, folder) + ":" + _hashed(tuple(named), "/")


def _hashed(paths: Tuple[str, ...], root: str) -> str:
    """:func:`_hash_files`, remembered while no file's size or modification time changes (a study keys
    thousands of specs on the same few files)."""
    signature = []
    for path in paths:
        try:
            stat = os.stat(path)
            signature.append((path, stat.st_size, stat.st_mtime_ns))
        except OSError:
            signature.append((path, -1, -1))
    return _hash_signed(tuple(signature), root)


@functools.lru_cache(maxsize=256)
def _hash_signed(signature: Tuple[Tuple[str, int, int], ...], root: str) -> str:
    return _hash_files([path for path, _, _ in signature], root)


def spec_key(spec: Any, code: Optional[str] = None, config: Optional[str] = None) -> str:
    """File name stem of a spec's result: its ``label`` (made file-safe) and a hash of all its fields
    (dataclasses: ``dataclasses.asdict``; other objects: ``repr``), of the code that computes it
    (:func:`code_fingerprint`) and of the configuration it reads (:func:`config_fingerprint`).

    A result computed by other code or from other configuration files therefore has another key and is
    never reused: after a change the trial runs again (the older file stays in the folder, unused, and
    :func:`run_trials` says how many there are). ``code`` and ``config`` replace the fingerprints (tests).
    """
    if dataclasses.is_dataclass(spec) and not isinstance(spec, type):
        text = json.dumps(_jsonable(dataclasses.asdict(spec)), sort_keys=True)
    else:
        text = repr(spec)
    code = code_fingerprint() if code is None else code
    config = config_fingerprint(spec) if config is None else config
    digest = hashlib.sha1("\n".join((text, code, config)).encode("utf-8")).hexdigest()[:12]
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
    return run_trial_batches(_EachTrial(fn), specs, out_dir, batch_size=1, jobs=jobs, dask_scheduler=dask_scheduler,
                             executor=executor, resume=resume, progress=progress, desc=desc)


class _EachTrial:
    """A trial function as a batched one (one spec per call): :func:`run_trials` is
    :func:`run_trial_batches` with batches of one. A class, not a closure, so that it pickles."""

    def __init__(self, fn: TrialFn) -> None:
        self.fn = fn

    def __call__(self, specs: List[Any]) -> List[Dict[str, Any]]:
        return [self.fn(spec) for spec in specs]


#: folders whose unused result files were already reported by this process (a study that runs the
#: runner many times, such as the identification's generations, says it once)
_REPORTED: set = set()


def _report_stale(out_dir: str, paths: Sequence[Optional[str]], show: bool) -> int:
    """Count (and, if ``show``, say in one line, once per folder and process) the result files of
    ``out_dir`` that belong to none of this call's keys: results of other specs (also an earlier stage of
    the same study), or of these specs computed by other code or configuration."""
    folder = os.path.join(out_dir, "trials")
    current = {os.path.basename(p) for p in paths if p}
    stale = [name for name in os.listdir(folder) if name.endswith(".json") and name not in current]
    if stale and show and folder not in _REPORTED:
        _REPORTED.add(folder)
        sys.stderr.write("study: %d result file(s) in %s belong to other trials, code or configuration; "
                         "they are not reused\n" % (len(stale), folder))
    return len(stale)


def _chunks(todo: Sequence[int], batch_size: int, workers: int) -> List[List[int]]:
    """``todo`` in consecutive chunks of at most ``batch_size``, and at least ``workers`` chunks when
    there are that many trials (so every worker gets one), as even as possible."""
    if not todo:
        return []
    count = max(-(-len(todo) // batch_size), min(workers, len(todo)))
    size = -(-len(todo) // count)
    return [list(todo[i:i + size]) for i in range(0, len(todo), size)]


def run_trial_batches(fn: BatchFn, specs: Sequence[Any], out_dir: Optional[str], batch_size: int = 1500,
                      jobs: int = 1, dask_scheduler: Optional[str] = None, executor: Optional[Executor] = None,
                      resume: bool = True, progress: bool = True, desc: str = "") -> List[Dict[str, Any]]:
    """:func:`run_trials` for a batched trial function ``fn(specs) -> results``: the trials still to run
    are cut into chunks of at most ``batch_size`` (and at least one per worker), each chunk is one task
    on the executor, and every trial of a finished chunk is written to its own file at once. Resume,
    result files, errors and the progress bar (counted in trials) are those of :func:`run_trials`, so a
    study may switch between the two and keep its finished trials."""
    if jobs < 1 or batch_size < 1:
        raise ValueError("jobs and batch_size must be at least 1, got %r and %r" % (jobs, batch_size))
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
            _report_stale(out_dir, paths, progress)
    todo = [i for i, r in enumerate(results) if r is None]
    workers = 1 if (executor is None and dask_scheduler is None and jobs == 1) else max(jobs, 2)
    chunks = _chunks(todo, batch_size, workers)

    def finish(i: int, result: Dict[str, Any]) -> None:
        if paths[i] is not None:
            _write_atomic(paths[i], result)  # type: ignore[arg-type]
            results[i] = _load(paths[i])  # type: ignore[arg-type]
        else:
            results[i] = json.loads(json.dumps(_jsonable(result), allow_nan=True))

    def finish_chunk(chunk: List[int], chunk_results: List[Dict[str, Any]]) -> None:
        if len(chunk_results) != len(chunk):
            raise StudyError("a batch of %d trials returned %d results" % (len(chunk), len(chunk_results)))
        for i, result in zip(chunk, chunk_results):
            finish(i, result)

    def failed(chunk: List[int]) -> str:
        first, last = (getattr(specs[i], "label", i) for i in (chunk[0], chunk[-1]))
        return "trial %r failed" % (first,) if len(chunk) == 1 else "batch %r .. %r failed" % (first, last)

    with _progress(len(specs), len(specs) - len(todo), desc, progress) as bar:
        with _executor(jobs, dask_scheduler, len(chunks)) as pool:
            pool = executor if executor is not None else pool
            if pool is None:
                for chunk in chunks:
                    try:
                        finish_chunk(chunk, fn([specs[i] for i in chunk]))
                    except Exception as exc:
                        raise StudyError("%s: %s" % (failed(chunk), exc)) from exc
                    bar.update(len(chunk))
            else:
                futures: Dict[Future, List[int]] = {pool.submit(fn, [specs[i] for i in chunk]): chunk
                                                    for chunk in chunks}
                try:
                    for future in as_completed(futures):
                        chunk = futures[future]
                        try:
                            finish_chunk(chunk, future.result())
                        except Exception as exc:
                            raise StudyError("%s: %s" % (failed(chunk), exc)) from exc
                        bar.update(len(chunk))
                finally:
                    for future in futures:
                        future.cancel()
    return results  # type: ignore[return-value]
