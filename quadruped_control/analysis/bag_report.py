"""Report of a recorded run from its rosbag, trial by trial: the paper's metrics, gains, figures, the stack's health.

    python -m quadruped_control.analysis.bag_report BAG [BAG ...] --out DIR [--title TITLE] [--last-trial]

Reads the bag with the pure-Python ``rosbags`` reader (no ROS installation needed: analyse the robot's
bags on any laptop). Uses:

* ``/imu/data``: measured attitude (world ENU <- base_link), converted to roll, pitch, yaw;
* ``/controller_state``: setpoint R_d, geodesic error, armed/holding;
* ``/sim/pose`` (simulation only): true attitude, reported beside the measured one;
* ``/diagnostics``: the last value of every node's figures (rates, jitter, latency, error counters);
* ``/joint_states`` (the measured servo angles) with the pair phases of ``/controller_state``: the
  strokes the robot made, power-stroke length, paw excursion and speed
  (:mod:`quadruped_control.analysis.strokes`), to set a real robot's strokes beside the simulator's;
* :data:`GAINS_TOPIC` (the controller's latched dynamic_reconfigure updates): the gains, limits and stroke
  scheme in force (:func:`gains_in_force`; "unknown" in a bag without them).

A trial is a span of armed controller steps under one setpoint: the record is split at each setpoint
change, arm and disarm (:func:`split_trials`); each trial gets its metrics, the gains in force at its start
and any change during it, and its figure ``trial_NN.png``; ``report.md`` opens with a table of them all,
``attitude.png`` shows the whole record (:func:`analyse_trials`, :func:`write_trials_report`). With
``--last-trial``, the report of one trial as before: from the last change of the setpoint (the maneuver), or
the first armed controller step, to the end of the record (:func:`analyse`, :func:`write_report`).

What the record is missing is part of the report. A bag still named ``*.bag.active`` was left open by a
recorder that was killed (or lost power): it has no index, so a copy of it is reindexed (ROS's
``rosbag`` API, the same as ``rosbag reindex``; the original is not touched) and read; the chunk the
recorder had not flushed yet is lost. The report lists each file's span, which files were reindexed, and
the missing spans: a gap of more than :data:`MAX_RECORD_GAP` between the parts of a split recording or
inside the /imu/data stream, and the end of a recording that stopped with a killed recorder. Writes
``DIR/metrics.json`` (the paper's metrics, eq. in section "Experiments", via
:func:`quadruped_control.analysis.metrics.compute_metrics`, plus gains and health figures),
``DIR/attitude.png`` and ``DIR/report.md``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.monitoring import STALE_IMU, hold_kind
from quadruped_common.robot import JOINT_NAMES, load_leg_pairs
from quadruped_common.so3 import geodesic_angle, geodesic_angles, quaternions_to_rotations, rot_to_rpy, rotations_to_rpy
from quadruped_common.tunables import TUNABLES
from quadruped_control.analysis.metrics import compute_metrics
from quadruped_control.analysis.strokes import format_spread, stroke_statistics
from quadruped_control.model.params import load_robot_params

#: Diagnostic values copied into the report (status name suffix -> keys).
HEALTH_KEYS = {
    "control loop": ("loop rate [Hz]", "period jitter p50 [ms]", "period jitter p99 [ms]",
                     "step time p50 [ms]", "step time p99 [ms]", "overruns", "hold episodes",
                     "stale-IMU hold episodes", "time held [s]", "held steps"),
    "servo output": ("command rate [Hz]", "latency p50 [ms]", "latency p99 [ms]", "latency max [ms]",
                     "clamped channels", "write errors", "watchdog tripped"),
    "servo feedback": ("rate [Hz]", "read time p50 [ms]", "read time p99 [ms]", "mux errors"),
    "imu": ("rate [Hz]", "CRC errors", "resync bytes", "disconnects"),
}


#: The attitude controller's dynamic_reconfigure updates (dynamic_reconfigure/Config, latched): the gains,
#: limits and stroke scheme in force, from the start (its gain set) and after every live change.
GAINS_TOPIC = "/attitude_controller/parameter_updates"


class BagReportError(RuntimeError):
    """The bag lacks what the report needs (named in the message)."""


#: Longer than this (s) without a message between the parts of a recording, or between /imu/data
#: samples (200 Hz), is a missing span of the record.
MAX_RECORD_GAP = 0.5


@dataclass
class BagFile:
    """One file of a recording: its span of message times (s), message count, and whether it was a
    ``.bag.active`` left by a killed recorder (read from a reindexed copy)."""

    path: str
    start: float
    end: float
    messages: int
    reindexed: bool = False


def reindexed_copy(path: str, folder: str) -> str:
    """A readable copy of the unindexed bag ``path`` (``*.bag.active``) in ``folder``, reindexed like
    ``rosbag reindex``; BagReportError if ROS's rosbag Python API is not installed or the file is no bag."""
    import shutil

    try:
        import rosbag
    except ImportError:
        raise BagReportError("%s was left open by its recorder and needs reindexing: install ROS's rosbag "
                             "(python3-rosbag) or run 'rosbag reindex' on a copy first" % path) from None
    name = os.path.basename(path)
    copy = os.path.join(folder, name[:-len(".active")] if name.endswith(".active") else name)
    shutil.copyfile(path, copy)
    try:
        with rosbag.Bag(copy, "a", allow_unindexed=True) as bag:
            for _ in bag.reindex():
                pass
    except Exception as exc:  # noqa: BLE001 - rosbag raises ROSBagException, ValueError, struct.error ...
        raise BagReportError("cannot reindex %s: %s" % (path, exc)) from None
    return copy


@dataclass
class BagData:
    imu_t: List[float] = field(default_factory=list)
    imu_q: List[Sequence[float]] = field(default_factory=list)
    #: the IMU's body rate (x, y, z), rad/s, one row per /imu/data sample
    imu_w: List[Sequence[float]] = field(default_factory=list)
    state_t: List[float] = field(default_factory=list)
    state_setpoint: List[Sequence[float]] = field(default_factory=list)
    state_geodesic: List[float] = field(default_factory=list)
    state_armed: List[bool] = field(default_factory=list)
    state_holding: List[bool] = field(default_factory=list)
    state_hold_reason: List[str] = field(default_factory=list)
    #: per controller step, whether each leg pair was in its power phase
    state_pair_power: List[Sequence[bool]] = field(default_factory=list)
    joint_t: List[float] = field(default_factory=list)
    #: measured joint angles in the order of JOINT_NAMES (NaN for a joint the message did not name)
    joint_q: List[Sequence[float]] = field(default_factory=list)
    #: the controller's joint targets (/servo_command joint_target, rad) in the order of JOINT_NAMES
    command_t: List[float] = field(default_factory=list)
    command_q: List[Sequence[float]] = field(default_factory=list)
    truth_t: List[float] = field(default_factory=list)
    truth_q: List[Sequence[float]] = field(default_factory=list)
    diagnostics: Dict[str, Dict[str, str]] = field(default_factory=dict)
    files: List[BagFile] = field(default_factory=list)
    #: receive time (s, the bag's) and values (name -> value) of every :data:`GAINS_TOPIC` message
    gains_t: List[float] = field(default_factory=list)
    gains: List[Dict[str, object]] = field(default_factory=list)


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def read_bags(paths: Sequence[str]) -> BagData:
    """Collect the report's topics from one or more (split) bags; ``*.bag.active`` files are read from
    reindexed copies (module docstring)."""
    import tempfile
    from pathlib import Path

    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag1 import ReaderError

    data = BagData()
    with tempfile.TemporaryDirectory(prefix="bag_report_") as folder:
        readable = [reindexed_copy(path, folder) if path.endswith(".active") else path for path in paths]
        try:
            with AnyReader([Path(p) for p in readable]) as reader:
                for path, copy, part in zip(paths, readable, reader.readers):
                    data.files.append(BagFile(path, part.start_time * 1e-9, part.end_time * 1e-9,
                                              part.message_count, copy != path))
                _read_into(data, reader)
        except (AnyReaderError, ReaderError) as exc:
            raise BagReportError("cannot read %s: %s" % (", ".join(paths), exc)) from None
    return data


def missing_spans(data: BagData, max_gap: float = MAX_RECORD_GAP) -> List[Dict[str, object]]:
    """What the record is missing: gaps of more than ``max_gap`` s between the parts of the recording or
    in the /imu/data stream, and the end of a recording whose recorder was killed. Each entry:
    ``{"from": t0, "to": t1 or None (until the end of the run), "why": text}``, message times in s."""
    spans: List[Dict[str, object]] = []
    files = sorted(data.files, key=lambda f: f.start)
    for before, after in zip(files, files[1:]):
        if after.start - before.end > max_gap:
            spans.append({"from": before.end, "to": after.start,
                          "why": "between %s and %s" % (os.path.basename(before.path), os.path.basename(after.path))})
    imu = np.unique(np.array(data.imu_t, dtype=float))
    if imu.size > 1:
        for k in np.flatnonzero(np.diff(imu) > max_gap):
            spans.append({"from": float(imu[k]), "to": float(imu[k + 1]), "why": "no /imu/data"})
    if files and files[-1].reindexed:
        spans.append({"from": files[-1].end, "to": None,
                      "why": "recorder killed: %s ends here (its unflushed last chunk is lost)"
                             % os.path.basename(files[-1].path)})
    return sorted(spans, key=lambda s: float(s["from"]))  # type: ignore[arg-type]


def _read_into(data: BagData, reader) -> None:
    """The report's messages from an open AnyReader."""
    wanted = [c for c in reader.connections if c.topic in (
        "/imu/data", "/controller_state", "/sim/pose", "/diagnostics", "/joint_states", "/servo_command", GAINS_TOPIC)]
    for connection, timestamp, raw in reader.messages(connections=wanted):
        msg = reader.deserialize(raw, connection.msgtype)
        if connection.topic == "/imu/data":
            o = msg.orientation
            data.imu_t.append(_stamp(msg))
            data.imu_q.append((o.x, o.y, o.z, o.w))
            w = msg.angular_velocity
            data.imu_w.append((w.x, w.y, w.z))
        elif connection.topic == "/controller_state":
            s = msg.setpoint
            data.state_t.append(_stamp(msg))
            data.state_setpoint.append((s.x, s.y, s.z, s.w))
            data.state_geodesic.append(msg.geodesic_error)
            data.state_armed.append(bool(msg.armed))
            data.state_holding.append(bool(msg.holding))
            data.state_hold_reason.append(str(msg.hold_reason))
            power = getattr(msg, "PHASE_POWER", 1)  # quadruped_msgs/ControllerState: PHASE_POWER=1
            data.state_pair_power.append(tuple(int(code) == power for code in getattr(msg, "pair_phase", ())))
        elif connection.topic == "/joint_states":
            angles = dict(zip(msg.name, msg.position))
            data.joint_t.append(_stamp(msg))
            data.joint_q.append([float(angles.get(name, math.nan)) for name in JOINT_NAMES])
        elif connection.topic == "/servo_command":
            targets = dict(zip(msg.name, msg.joint_target))
            data.command_t.append(_stamp(msg))
            data.command_q.append([float(targets.get(name, math.nan)) for name in JOINT_NAMES])
        elif connection.topic == GAINS_TOPIC:  # no header: the time it was recorded
            data.gains_t.append(timestamp * 1e-9)
            data.gains.append({p.name: p.value for p in (*msg.bools, *msg.ints, *msg.strs, *msg.doubles)})
        elif connection.topic == "/sim/pose":
            o = msg.pose.orientation
            data.truth_t.append(_stamp(msg))
            data.truth_q.append((o.x, o.y, o.z, o.w))
        else:
            for status in msg.status:
                data.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}


def _rotations(quaternions: Sequence[Sequence[float]]) -> np.ndarray:
    """(N, 3, 3) rotations of (x, y, z, w) quaternions, normalised first (bags hold float32-rounded ones)."""
    return quaternions_to_rotations(np.asarray(quaternions, dtype=float).reshape(-1, 4))


#: Steps a new setpoint must stay unchanged to count as the operator's (a tilt-only setpoint's R_d follows the
#: measured heading every step; only a change of its tilt is the operator's).
SETTLED_STEPS = 5


def setpoint_changes(setpoints: Sequence[Sequence[float]]) -> List[bool]:
    """Per step (quaternions x, y, z, w of R_d): did the operator's setpoint change there? Its tilt (R_d's world
    vertical in the body frame) changed, or R_d changed and then held for :data:`SETTLED_STEPS` steps."""
    q = np.asarray(setpoints, dtype=float).reshape(-1, 4)
    x, y, z, w = q.T
    tilt = np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)
    moved = np.r_[False, np.max(np.abs(np.diff(q, axis=0)), axis=1) > 1e-6]
    tilted = np.r_[False, np.max(np.abs(np.diff(tilt, axis=0)), axis=1) > 1e-6]
    settled = [not moved[i + 1:i + SETTLED_STEPS].any() and i + SETTLED_STEPS <= len(q) for i in range(len(q))]
    return [bool(tilted[i] or (moved[i] and settled[i])) for i in range(len(q))]


def _trial_start(data: BagData) -> float:
    """Time of the last setpoint change while armed, else of the first armed step."""
    armed = [i for i, a in enumerate(data.state_armed) if a]
    if not armed:
        raise BagReportError("the controller was never armed in this bag")
    changed = setpoint_changes(data.state_setpoint)
    start = armed[0]
    for i in armed[1:]:
        if changed[i]:
            start = i
    return data.state_t[start]


@dataclass(frozen=True)
class HoldEpisode:
    """Consecutive /controller_state steps with ``holding`` set: stamps of the first and last held
    step and the reason the first one gave."""

    start: float
    end: float
    reason: str

    @property
    def stale_imu(self) -> bool:
        return hold_kind(self.reason) == STALE_IMU


def hold_episodes(data: BagData) -> List[HoldEpisode]:
    """The controller's hold episodes in stamp order (the diagnostics count them; this says when)."""
    order = np.argsort(np.array(data.state_t), kind="stable")
    episodes: List[HoldEpisode] = []
    start = None
    last = 0.0
    reason = ""
    for i in order:
        t, holding = data.state_t[i], data.state_holding[i]
        if holding and start is None:
            start, reason = t, data.state_hold_reason[i] if i < len(data.state_hold_reason) else ""
        elif not holding and start is not None:
            episodes.append(HoldEpisode(start, last, reason))
            start = None
        last = t
    if start is not None:
        episodes.append(HoldEpisode(start, last, reason))
    return episodes


def health(data: BagData) -> Dict[str, Dict[str, str]]:
    """Selected last diagnostic values per status (e.g. 'attitude_controller: control loop')."""
    result: Dict[str, Dict[str, str]] = {}
    for name, values in sorted(data.diagnostics.items()):
        for suffix, keys in HEALTH_KEYS.items():
            if name.endswith(suffix):
                result[name] = {k: values[k] for k in keys if k in values}
    return result


def health_across_runs(runs: Sequence[Dict[str, Dict[str, str]]]) -> Dict[str, Dict[str, Dict[str, float]]]:
    """min / median / max of every numeric health figure over several runs (``health()`` of each).

    Figures missing or non-numeric in a run are left out of that figure's statistics; ``n`` says how
    many runs had it.
    """
    collected: Dict[str, Dict[str, List[float]]] = {}
    for run in runs:
        for name, values in run.items():
            for key, value in values.items():
                try:
                    number = float(value)
                except (TypeError, ValueError):
                    if str(value) in ("True", "False"):
                        number = float(str(value) == "True")
                    else:
                        continue
                collected.setdefault(name, {}).setdefault(key, []).append(number)
    return {name: {key: {"min": float(np.min(v)), "median": float(np.median(v)), "max": float(np.max(v)),
                         "n": float(len(v))} for key, v in figures.items()}
            for name, figures in collected.items()}


def _check_streams(data: BagData) -> None:
    if len(data.imu_t) < 10 or len(data.state_t) < 10:
        raise BagReportError("need /imu/data and /controller_state in the bag (got %d and %d messages)"
                             % (len(data.imu_t), len(data.state_t)))


def _record(data: BagData) -> Dict:
    return {"files": [{"path": f.path, "start": f.start, "end": f.end, "messages": f.messages,
                       "reindexed": f.reindexed} for f in data.files],
            "missing_spans": missing_spans(data)}


def trial_metrics(data: BagData, start: float, end: float, setpoint: Sequence[float]) -> Dict:
    """The paper's metrics of the measured attitude in [start, end) (stamps, s) against the setpoint (x, y, z, w),
    with the share of held steps, the IMU against the true attitude (simulation), the strokes and ``_series``
    (t from start, rpy, geodesic error: the figure's); BagReportError with fewer than 10 IMU samples."""
    imu_t, imu_q = sorted_unique(data.imu_t, np.asarray(data.imu_q, dtype=float).reshape(-1, 4))
    keep = (imu_t >= start) & (imu_t < end)
    if np.count_nonzero(keep) < 10:
        raise BagReportError("fewer than 10 IMU samples in the trial (%.2f s)" % (min(end, imu_t[-1]) - start))
    t = imu_t[keep] - start
    R = _rotations(imu_q[keep])
    rpy = rotations_to_rpy(R)
    R_d = _rotations([setpoint])[0]
    geodesic = geodesic_angles(R_d, R)
    metrics = compute_metrics(t, rpy, np.array(rot_to_rpy(R_d)), geodesic)
    metrics["setpoint_rpy_deg"] = [math.degrees(a) for a in rot_to_rpy(R_d)]
    metrics["trial_start_unix"] = start
    state_t = np.array(data.state_t)
    holding = np.array(data.state_holding)[(state_t >= start) & (state_t < end)]
    metrics["holding_fraction"] = float(np.mean(holding)) if holding.size else None
    if data.truth_t:
        truth_t = np.array(data.truth_t)
        truth_R = _rotations(data.truth_q)
        # IMU vs truth: how well the measured attitude tracks the simulated one (same stamps +- 10 ms).
        idx = np.clip(np.searchsorted(truth_t, imu_t[keep]), 0, len(truth_t) - 1)
        errors = [geodesic_angle(truth_R[j], R_k) for j, R_k in zip(idx, R)]
        metrics["imu_vs_truth_deg"] = {"p50": math.degrees(float(np.percentile(errors, 50))),
                                       "max": math.degrees(float(np.max(errors)))}
    strokes = stroke_figures(data, start, end)
    metrics["strokes"] = strokes.as_dict() if strokes is not None else None
    metrics["_series"] = (t, rpy, geodesic)
    return metrics


def analyse(data: BagData) -> Dict:
    """The paper's metrics of the one trial from the last setpoint change (or the first armed step) to the end
    of the record, plus the gains in force, health figures and the record (``--last-trial``)."""
    _check_streams(data)
    start = _trial_start(data)
    metrics = trial_metrics(data, start, math.inf, data.state_setpoint[-1])
    metrics.update(gains_in_force(data, start, math.inf))
    metrics["health"] = health(data)
    metrics["record"] = _record(data)
    return metrics


@dataclass(frozen=True)
class Trial:
    """Armed controller steps under one setpoint: stamps (s) of its first step and of the step that ended it
    (the next setpoint, a disarm, or the record's last step), and the setpoint (x, y, z, w)."""

    start: float
    end: float
    setpoint: Tuple[float, ...]


def split_trials(data: BagData) -> List[Trial]:
    """The record's trials in stamp order: a new one at each armed step where the operator's setpoint changed
    (:func:`setpoint_changes`) or that follows a disarmed one; a disarmed step ends one."""
    stamps, steps = sorted_unique(data.state_t, list(zip(data.state_armed, data.state_setpoint)))
    changed = setpoint_changes([setpoint for _, setpoint in steps]) if steps else []
    trials: List[Trial] = []
    begun: Optional[Tuple[float, Sequence[float]]] = None
    for stamp, (armed, setpoint), new in zip(stamps.tolist(), steps, changed):
        if begun is not None and (not armed or new):
            trials.append(Trial(begun[0], stamp, tuple(begun[1])))
            begun = None
        if armed and begun is None:
            begun = (stamp, setpoint)
    if begun is not None:
        trials.append(Trial(begun[0], float(stamps[-1]), tuple(begun[1])))
    return trials


def gains_in_force(data: BagData, start: float, end: float) -> Dict:
    """``{"gains": name -> value in force at start, "gain_changes": [{"at": s after start, "changes": name ->
    [old, new]}, ...] before end}`` from :data:`GAINS_TOPIC`. In force at start: the last message at or before
    it, else the bag's first (a latched topic's first message is the value in force when the recorder
    subscribed: since before the record began). ``gains`` None when the bag has no such message."""
    if not data.gains:
        return {"gains": None, "gain_changes": []}
    times, values = sorted_unique(data.gains_t, data.gains)
    k = max(int(np.searchsorted(times, start, side="right")) - 1, 0)
    current, changes = values[k], []
    for t, new in zip(times[k + 1:].tolist(), values[k + 1:]):
        if t >= end:
            break
        changed = {name: [current.get(name), value] for name, value in new.items() if current.get(name) != value}
        if changed:
            changes.append({"at": t - start, "changes": changed})
        current = new
    return {"gains": values[k], "gain_changes": changes}


def analyse_trials(data: BagData) -> Dict:
    """Every trial of the record (:func:`split_trials`), each ``{"trial": n, "start_unix", "end_unix",
    "setpoint_rpy_deg", "gains", "gain_changes", "metrics"}`` (:func:`trial_metrics`; None for a trial too
    short to measure, with the reason in ``"skipped"``), plus ``record_start_unix``, health and the record."""
    _check_streams(data)
    trials = split_trials(data)
    if not trials:
        raise BagReportError("the controller was never armed in this bag")
    entries = []
    for number, trial in enumerate(trials, 1):
        entry = {"trial": number, "start_unix": trial.start, "end_unix": trial.end,
                 "setpoint_rpy_deg": [math.degrees(a) for a in rot_to_rpy(_rotations([trial.setpoint])[0])]}
        entry.update(gains_in_force(data, trial.start, trial.end))
        try:
            entry["metrics"] = trial_metrics(data, trial.start, trial.end, trial.setpoint)
        except (BagReportError, ValueError) as exc:
            entry["metrics"], entry["skipped"] = None, str(exc)
        entries.append(entry)
    return {"trials": entries, "record_start_unix": float(np.min(data.state_t)), "health": health(data),
            "record": _record(data)}


def sorted_unique(t: Sequence[float], values: Sequence) -> tuple:
    """Samples in stamp order with repeated stamps dropped: bags need not be in stamp order (split bags,
    several publishers). The values come back as an array if given one (indexed at once: a ten-minute IMU
    stream is 120,000 rows), else as a list."""
    order = np.argsort(np.array(t, dtype=float), kind="stable")
    times = np.array(t, dtype=float)[order]
    keep = np.concatenate(([True], np.diff(times) > 0)) if times.size else np.zeros(0, dtype=bool)
    kept = order[keep]
    if isinstance(values, np.ndarray):
        return times[keep], values[kept]
    return times[keep], [values[i] for i in kept.tolist()]


def attitude_rpy(times: Sequence[float], quaternions: Sequence[Sequence[float]]) -> Tuple[np.ndarray, np.ndarray]:
    """A recorded attitude stream as (times, roll-pitch-yaw in rad, Z-Y-X, REP 103), in stamp order with
    repeated stamps dropped (:func:`sorted_unique`); samples whose stamp or (x, y, z, w) quaternion is not finite,
    or whose quaternion is far from unit length (more than 0.1), are left out, and the rest normalised."""
    t = np.asarray(times, dtype=float)
    q = np.asarray(quaternions, dtype=float).reshape(-1, 4)
    norm = np.linalg.norm(np.nan_to_num(q, nan=0.0, posinf=0.0, neginf=0.0), axis=1)
    good = np.all(np.isfinite(q), axis=1) & np.isfinite(t) & (np.abs(norm - 1.0) < 0.1)
    t, kept = sorted_unique(t[good], q[good] / norm[good, None])
    return t, rotations_to_rpy(quaternions_to_rotations(kept))


def covered_by(times: np.ndarray, grid: np.ndarray, max_gap: float) -> np.ndarray:
    """Whether each time of ``grid`` lies within the span of the sorted sample ``times`` without a gap longer
    than ``max_gap`` s around it (a grid time on a sample counts as covered)."""
    after = np.clip(np.searchsorted(times, grid, side="left"), 1, times.size - 1)
    inside = (grid >= times[0]) & (grid <= times[-1])
    return inside & ((times[after] - times[after - 1] <= max_gap) | (times[after] == grid)
                     | (times[after - 1] == grid))


def stroke_figures(data: BagData, start: float, end: float = math.inf):
    """:func:`~quadruped_control.analysis.strokes.stroke_statistics` of the trial (stamps in [start, end)), with
    the package's robot.yaml and controller.yaml (leg pairs); None without joint angles, pair phases or a
    complete stroke cycle."""
    pairs = load_leg_pairs()
    phase_t, power = sorted_unique(data.state_t, data.state_pair_power)
    joint_t, joints = sorted_unique(data.joint_t, data.joint_q)
    steps = [k for k, (t, p) in enumerate(zip(phase_t, power)) if start <= t < end and len(p) == len(pairs)]
    samples = [k for k, t in enumerate(joint_t) if start <= t < end]
    if len(steps) < 2 or len(samples) < 2:
        return None
    return stroke_statistics(phase_t[steps], [power[k] for k in steps], joint_t[samples],
                             np.array([joints[k] for k in samples]), load_robot_params(), pairs)


def _fmt(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return "%.2f" % value
    return str(value)


def gains_text(gains: Optional[Dict[str, object]]) -> str:
    """The tunables of :func:`gains_in_force` in one line, in the order of the reconfigure GUI; 'unknown' for None."""
    if gains is None:
        return "unknown"
    order = [t.name for t in TUNABLES]
    names = [n for n in order if n in gains] + sorted(n for n in gains if n not in order)
    return ", ".join("%s %s" % (n, "%.4g" % gains[n] if isinstance(gains[n], float) else gains[n]) for n in names)


def _gains_line(entry: Dict) -> str:
    """'Gains: ...' of a trial's :func:`gains_in_force`, with every change during the trial."""
    changes = "; ".join("%s at %.1f s" % (", ".join("%s %s -> %s" % (name, old, new)
                                                     for name, (old, new) in c["changes"].items()), c["at"])
                        for c in entry["gain_changes"])
    return "Gains: %s%s." % (gains_text(entry["gains"]), "; changed during the trial: " + changes if changes else "")


def _summary_cells(m: Optional[Dict]) -> str:
    """theta_init, geodesic t_s, final error, settled, held % of a trial's metrics (dashes without)."""
    if m is None:
        return " | ".join("-" * 5)
    held = 100.0 * m["holding_fraction"] if m["holding_fraction"] is not None else None
    return " | ".join(("%.1f" % m["theta_init_deg"], _fmt(m["geodesic"]["t_s"]),
                       "%.1f" % m["geodesic"]["final_smoothed_deg"], _fmt(m["settled"]), _fmt(held)))


def _trial_lines(metrics: Dict) -> List[str]:
    """The per-axis table, IMU against truth and strokes of one trial's metrics."""
    lines = ["| axis | t_r [s] | t_s [s] | e_ss [deg] | M_p [%] |", "|---|---|---|---|---|"]
    for axis in ("roll", "pitch", "yaw"):
        m = metrics[axis]
        lines.append("| %s | %s | %s | %s | %s |" % (axis, _fmt(m["t_r"]), _fmt(m["t_s"]), _fmt(m["e_ss"]),
                                                    _fmt(m["M_p"])))
    if "imu_vs_truth_deg" in metrics:
        lines += ["", "Measured (VN-100 path) vs simulated attitude: p50 %.3f deg, max %.3f deg."
                  % (metrics["imu_vs_truth_deg"]["p50"], metrics["imu_vs_truth_deg"]["max"])]
    strokes = metrics.get("strokes")
    if strokes:
        lines += ["", "Strokes (measured joint angles): %d power strokes: power phase %s s; paw excursion %s cm; "
                  "peak paw speed %s m/s (median (p10-p90) over %d leg strokes); corrupt joint samples skipped: %d."
                  % (strokes["strokes"], format_spread(strokes["power_duration"]),
                     format_spread(strokes["excursion"], 100.0, 1), format_spread(strokes["peak_speed"]),
                     strokes["leg_strokes"], strokes["skipped_samples"])]
    else:
        lines += ["", "Strokes: no complete stroke cycle with joint angles in the record (/joint_states and the "
                  "pair phases of /controller_state)."]
    return lines


def _record_lines(record: Dict, start: float, origin: str, health_figures: Dict) -> List[str]:
    """The record's files and missing spans (times from ``start``, which is ``origin``) and the last diagnostics."""
    lines = ["", "## Record", "", "Times from %s." % origin, ""]
    for f in record["files"]:
        lines.append("- %s: %.1f s to %.1f s, %d messages%s" % (
            os.path.basename(f["path"]), f["start"] - start, f["end"] - start, f["messages"],
            " (left open by a killed recorder: read from a reindexed copy)" if f["reindexed"] else ""))
    spans = record["missing_spans"]
    lines.append("- missing: none" if not spans else "- missing: " + "; ".join(
        "%.2f s to %s (%s)" % (s["from"] - start, "the end" if s["to"] is None else "%.2f s" % (s["to"] - start),
                               s["why"]) for s in spans))
    lines += ["", "## Stack health (last diagnostics in the bag)", ""]
    for name, values in health_figures.items():
        lines.append("- **%s**: %s" % (name, ", ".join("%s %s" % kv for kv in values.items())))
    return lines


def _write(out_dir: str, result: Dict, lines: List[str]) -> str:
    with open(os.path.join(out_dir, "metrics.json"), "w") as f:
        json.dump(result, f, indent=2, sort_keys=True)
    path = os.path.join(out_dir, "report.md")
    with open(path, "w") as f:
        f.write("\n".join(lines + [""]))
    return path


def write_report(metrics: Dict, out_dir: str, title: str = "Simulated maneuver") -> str:
    """Write metrics.json, attitude.png and report.md of :func:`analyse` into ``out_dir``; returns the report path."""
    from quadruped_control.analysis.plotting import plot_attitude

    os.makedirs(out_dir, exist_ok=True)
    t, rpy, geodesic = metrics.pop("_series")
    setpoint = np.radians(metrics["setpoint_rpy_deg"])
    plot_attitude(t, rpy, setpoint, geodesic, os.path.join(out_dir, "attitude.png"), title=title)
    lines = ["# %s" % title, "",
             "Setpoint roll/pitch/yaw: %s deg; initial geodesic error %.1f deg; settled: %s."
             % (", ".join("%.1f" % v for v in metrics["setpoint_rpy_deg"]), metrics["theta_init_deg"],
                _fmt(metrics["settled"])), "",
             _gains_line(metrics), ""]
    lines += _trial_lines(metrics)
    lines += _record_lines(metrics["record"], metrics["trial_start_unix"], "the trial's start", metrics["health"])
    lines += ["", "![attitude](attitude.png)"]
    return _write(out_dir, metrics, lines)


def write_trials_report(result: Dict, out_dir: str, title: str = "Recorded run") -> str:
    """Write report.md (a table of every trial of :func:`analyse_trials`, then each trial: its gains, metrics and
    figure trial_NN.png), attitude.png (the whole record, a colour per trial) and metrics.json into
    ``out_dir``; returns the report path. Times are from the record's first controller step."""
    from quadruped_control.analysis.plotting import Trace, plot_attitude, plot_trials

    os.makedirs(out_dir, exist_ok=True)
    origin = result["record_start_unix"]
    traces, sections = [], []
    rows = ["| trial | from [s] | for [s] | setpoint r, p, y [deg] | gains | theta_init [deg] | t_s [s] | "
            "final error [deg] | settled | held [%] |", "|---|---|---|---|---|---|---|---|---|---|"]
    for trial in result["trials"]:
        n, m = trial["trial"], trial["metrics"]
        setpoint = ", ".join("%.1f" % (round(v, 1) + 0.0) for v in trial["setpoint_rpy_deg"])  # no -0.0
        gains = gains_text(trial["gains"]) + (" (changed)" if trial["gain_changes"] else "")
        rows.append("| %d | %.1f | %.1f | %s | %s | %s |" % (n, trial["start_unix"] - origin, trial["end_unix"]
                                                            - trial["start_unix"], setpoint, gains, _summary_cells(m)))
        sections += ["", "## Trial %d: setpoint %s deg, from %.1f s" % (n, setpoint, trial["start_unix"] - origin), "",
                     _gains_line(trial), ""]
        if m is None:
            sections.append("Not measured: %s." % trial["skipped"])
            continue
        t, rpy, geodesic = m.pop("_series")
        setpoint_rad = np.radians(trial["setpoint_rpy_deg"])
        figure = "trial_%02d.png" % n
        plot_attitude(t, rpy, setpoint_rad, geodesic, os.path.join(out_dir, figure), title="%s, trial %d" % (title, n))
        traces.append(Trace(t + trial["start_unix"] - origin, rpy, setpoint_rad, geodesic, "trial %d" % n))
        sections += ["Initial geodesic error %.1f deg; settled: %s." % (m["theta_init_deg"], _fmt(m["settled"])), ""]
        sections += _trial_lines(m) + ["", "![trial %d](%s)" % (n, figure)]
    if traces:
        plot_trials(traces, os.path.join(out_dir, "attitude.png"), title=title)
    lines = ["# %s" % title, "", "%d trials: armed, one setpoint each (the record split at each setpoint change, arm "
             "and disarm); times from the first controller step; gains from %s, the values in force at the trial's "
             "start." % (len(result["trials"]), GAINS_TOPIC), ""]
    lines += rows + (["", "![attitude](attitude.png)"] if traces else []) + sections
    lines += _record_lines(result["record"], origin, "the first controller step", result["health"])
    return _write(out_dir, result, lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("bags", nargs="+", help="bag file(s) of one run (split parts together)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--title", default="Recorded maneuver")
    parser.add_argument("--last-trial", action="store_true",
                        help="one trial only, from the last setpoint change to the end (the report before trials)")
    args = parser.parse_args(argv)
    try:
        data = read_bags(args.bags)
        result = analyse(data) if args.last_trial else analyse_trials(data)
    except (BagReportError, OSError) as exc:
        print("bag_report: %s" % exc, file=sys.stderr)
        return 1
    path = (write_report if args.last_trial else write_trials_report)(result, args.out, args.title)
    with open(path) as f:
        print(f.read())
    return 0


if __name__ == "__main__":
    sys.exit(main())
