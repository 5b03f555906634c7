"""A day in the tank's folder as the studies read it (docs/tank_day.md): the runs of a kind, their bags and records,
and what is missing, said in so many words instead of a failure deep in a study.

A study given a folder (:func:`is_folder`) reads it as a day (run folders inside, :data:`~.tank_day.PLAN_FILE`
beside them) or, when it holds bags or a :data:`~.tank_day.RUN_FILE` itself, as one run's folder. :func:`day_runs`
returns the runs a study can use (status complete or ended early, a bag with the topics it needs) and a line for
everything it left out or found missing: a planned run absent, skipped or aborted, a run's record missing (the
kind then comes from the folder's name), no bag, a topic missing from the bag.
"""
from __future__ import annotations

import dataclasses
import glob
import os
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

import yaml

from quadruped_control.control.tank_day import PLAN_FILE, RUN_FILE, parse_run_name
from quadruped_control.studies import StudyError

__all__ = ["DayRun", "bag_topics", "day_runs", "is_folder", "missing_text", "one_run", "say_missing"]


@dataclasses.dataclass
class DayRun:
    """A run's folder: its name, kind, bags (the parts of one recording, in order) and record (None: no run.yaml)."""

    name: str
    folder: str
    kind: str
    bags: List[str]
    record: Optional[Dict[str, Any]]

    @property
    def repeat(self) -> int:
        """A Table-1 run's repeat (from its record, else its folder's name; 0 for another run)."""
        if self.record and self.record.get("repeat"):
            return int(self.record["repeat"])
        return int((parse_run_name(self.name) or {}).get("repeat", 0))

    @property
    def row(self) -> str:
        """A Table-1 run's row, e.g. ``roll 30`` (from its record, else its folder's name; "" for another run)."""
        if self.record and self.record.get("row"):
            return str(self.record["row"])
        return str((parse_run_name(self.name) or {}).get("row", ""))

    @property
    def source(self) -> str:
        """The run as the studies name a recording: its parts joined by commas."""
        return ",".join(self.bags)


def is_folder(path: str) -> bool:
    return os.path.isdir(path)


def _load(path: str) -> Optional[Dict[str, Any]]:
    try:
        with open(path) as stream:
            value = yaml.safe_load(stream)
    except (OSError, yaml.YAMLError):
        return None
    return value if isinstance(value, dict) else None


def bag_topics(bags: Sequence[str]) -> Optional[set]:
    """The topics with messages in the bags; None when one cannot be read without reindexing (``.bag.active``) or at
    all."""
    from rosbags.rosbag1 import Reader

    topics: set = set()
    for path in bags:
        if path.endswith(".active"):
            return None
        try:
            with Reader(path) as reader:
                topics.update(name for name, info in reader.topics.items() if info.msgcount)
        except Exception:  # noqa: BLE001 - rosbags raises ReaderError and others for a damaged file
            return None
    return topics


def _run(folder: str) -> DayRun:
    name = os.path.basename(os.path.normpath(folder))
    record = _load(os.path.join(folder, RUN_FILE))
    parsed = parse_run_name(name)
    kind = str(record.get("kind", "")) if record else (parsed["kind"] if parsed else "")
    bags = sorted(glob.glob(os.path.join(folder, "*.bag")) + glob.glob(os.path.join(folder, "*.bag.active")))
    return DayRun(name, folder, kind, bags, record)


def _holds_a_run(folder: str) -> bool:
    return os.path.exists(os.path.join(folder, RUN_FILE)) or bool(glob.glob(os.path.join(folder, "*.bag*")))


def day_runs(path: str, kinds: Sequence[str], needs: Sequence[str] = (),
             wants: Sequence[str] = ()) -> Tuple[List[DayRun], List[str]]:
    """The runs of ``kinds`` in ``path`` (a day's folder, or one run's) a study can use, in the day's order, and a
    line for each run of those kinds left out or lacking something (module docstring). ``needs``: topics without which
    a run is left out; ``wants``: topics whose absence is said, the run kept."""
    single = _holds_a_run(path)
    if single:
        folders, plan = [path], None
    else:
        folders = sorted(f for f in glob.glob(os.path.join(path, "*")) if os.path.isdir(f) and _holds_a_run(f))
        plan = _load(os.path.join(path, PLAN_FILE))
    missing: List[str] = []
    if plan is None and not single:
        missing.append("%s: no %s: which runs were planned is unknown" % (path, PLAN_FILE))
    runs = [_run(folder) for folder in folders]
    if plan is not None:
        present = {(parse_run_name(run.name) or {}).get("planned", run.name) for run in runs}
        for entry in plan.get("runs", []):
            if entry.get("kind") in kinds and entry.get("run") not in present:
                missing.append("%s: planned, not in the folder (the day ended before it)" % entry.get("run"))
    usable = []
    for run in runs:
        if run.kind not in kinds:
            if single:
                missing.append("%s: a %s run, not %s" % (run.name, run.kind or "unknown", " or ".join(kinds)))
            continue
        status = str(run.record.get("status", "")) if run.record else ""
        why = str(run.record.get("why", "")) if run.record else ""
        if run.record is None:
            missing.append("%s: no %s (its record): kind from the folder's name; gains, configuration, code version "
                           "and legs unknown" % (run.name, RUN_FILE))
        if status in ("skipped", "aborted"):
            missing.append("%s: %s%s: left out" % (run.name, status, " (%s)" % why if why else ""))
            continue
        if not run.bags:
            missing.append("%s: no bag: left out" % run.name)
            continue
        if status == "ended early":
            missing.append("%s: ended early (%s): read as far as it goes" % (run.name, why or "no reason given"))
        topics = bag_topics(run.bags)
        if topics is None:
            missing.append("%s: a bag left open or unreadable: its topics not checked" % run.name)
        else:
            lacking = [t for t in needs if t not in topics]
            if lacking:
                missing.append("%s: the bag has no %s: left out" % (run.name, ", ".join(lacking)))
                continue
            absent = [t for t in wants if t not in topics]
            if absent:
                missing.append("%s: the bag has no %s" % (run.name, ", ".join(absent)))
        usable.append(run)
    return usable, missing


def missing_text(missing: Sequence[str]) -> List[str]:
    """The report's lines (markdown) of what the day's folder was missing; none when nothing was."""
    return ["", "Missing from the day's folder:", ""] + ["- %s" % line for line in missing] if missing else []


def say_missing(study: str, missing: Sequence[str]) -> None:
    """Each line of :func:`day_runs`' missing, on stderr, as the study's note."""
    for line in missing:
        sys.stderr.write("%s: missing: %s\n" % (study, line))


def one_run(path: str, kind: str, study: str, needs: Sequence[str] = (),
            wants: Sequence[str] = ()) -> Tuple[DayRun, List[str]]:
    """The run a one-run study reads in ``path`` (the day's last usable run of ``kind``), with the missing lines, which
    it also says (:func:`say_missing`); StudyError naming them when there is none."""
    runs, missing = day_runs(path, (kind,), needs, wants)
    if len(runs) > 1:
        missing.append("%d %s runs: reading the last, %s (%s)" % (len(runs), kind, runs[-1].name,
                                                                  ", ".join(r.name for r in runs[:-1]) + " left out"))
    say_missing(study, missing)
    if not runs:
        raise StudyError("%s: no usable %s run in %s%s" % (study, kind, path,
                                                          "".join("\n  - " + line for line in missing)))
    return runs[-1], missing
