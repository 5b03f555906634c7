"""One day in the tank: the runs that measure the robot for the tank model, in order, what the operator does
before each, and the record kept beside each run's bag (docs/tank_day.md). Pure Python: the tank_day node
(quadruped_control/ros/tank_day_node.py) runs the plan, the studies read the folder it leaves.

The day's folder holds :data:`PLAN_FILE` (the plan as it began) and one folder per run, named by :func:`run_name`
(``01_hang``, ``03_step_test``, ``04_table1_roll_15_r1``; a retry after an aborted attempt adds ``_a2``), with the
run's bags and its :data:`RUN_FILE` (:func:`run_record`). The runs (:func:`day_plan`):

- ``hang``: disarmed, recording only (docs/identification.md, "What a hang tells");
- ``tether``: disarmed; the tether hangs free, is bent and held, then released (the bend's fade);
- ``step_test``: armed; level for ``step_delay`` s, then :data:`~.setpoint_sequence.STEP_TEST` in the relative yaw
  reference, as launch/step_test.launch runs it;
- ``table1``: armed; each of Table 1's setpoints (:data:`TABLE_1`) held ``table1_seconds`` s, then level for
  ``return_seconds`` s, round after round (every row once, then again), so that a day cut short still has every
  row and the rounds' drift (packs, tether, water) is spread over all rows. With the relative yaw reference
  (default) a row's yaw setpoint is -psi_init: the same turn and tilt Table 1 asked, from wherever the robot
  faces, and the level hold turns it back, so its rope does not wind up over the day.
"""
from __future__ import annotations

import dataclasses
import hashlib
import os
import re
import subprocess
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

from quadruped_common.config import ParameterError, config_path
from quadruped_control.control.setpoint_sequence import STEP_TEST, SetpointHold, total_seconds

__all__ = ["CONTROLLER_FILES", "KINDS", "PLAN_FILE", "RUN_FILE", "STATUSES", "TABLE_1", "DayOptions", "Phase", "Run",
           "code_version", "config_files", "day_plan", "parse_run_name", "plan_record", "remaining", "row_label", "run_name",
           "run_record", "table1_setpoint"]

#: The kinds of run, in the day's order.
KINDS = ("hang", "tether", "step_test", "table1")
PLAN_FILE = "plan.yaml"
RUN_FILE = "run.yaml"
#: A run's end: ran to its end, ended by the operator, never began (the arming refused, the recorder failed),
#: or skipped at its prompt. Only "aborted" runs are tried again when the day is started anew.
STATUSES = ("complete", "ended early", "aborted", "skipped")

#: Table 1 of the paper (section "Experiments"): set, commanded angle (deg), the initial yaw offset psi_init the
#: controller drove to zero (deg), and t_rec (s; 1.0 where the paper shortened it, sections "Pitch Regulation" and
#: "Coupled Roll and Pitch Regulation"). quadruped_control.studies.paper_experiments.PAPER_TABLE holds the metrics.
TABLE_1: Tuple[Tuple[str, int, float, float], ...] = (
    ("roll", 15, -78.02, 1.5), ("roll", 30, -35.49, 1.5), ("roll", 45, 121.83, 1.5), ("roll", 60, 71.15, 1.5),
    ("roll", 75, 82.91, 1.5), ("roll", 90, 123.32, 1.5),
    ("pitch", 15, 1.54, 1.5), ("pitch", 30, 61.38, 1.5), ("pitch", 45, 56.76, 1.5), ("pitch", 60, -54.06, 1.5),
    ("pitch", 75, -43.40, 1.0), ("pitch", 90, 58.46, 1.0),
    ("roll+pitch", 30, -0.54, 1.5), ("roll+pitch", 45, -57.54, 1.5), ("roll+pitch", 60, -38.35, 1.0))

#: The yaw references a Table-1 row may be commanded in (docs/tank_day.md says why relative is the default).
TABLE1_YAW_REFERENCES = ("relative", "absolute")

#: A `*_yaml` parameter left empty loads this file of config/ (the loaders' defaults).
DEFAULT_FILES = {"controller_yaml": "controller.yaml", "robot_yaml": "robot.yaml", "hardware_yaml": "hardware.yaml",
                 "calibration_yaml": "servo_calibration.yaml", "vn100_yaml": "vn100.yaml",
                 "safety_yaml": "safety.yaml", "tank_yaml": "tank.yaml"}

#: The files the attitude controller loads (its ``~*_yaml`` parameters).
CONTROLLER_FILES = ("controller_yaml", "robot_yaml", "hardware_yaml", "calibration_yaml", "vn100_yaml", "safety_yaml")

_NAME = re.compile(r"^(\d+)_(hang|tether|step_test|table1)(?:_(roll|pitch|roll_pitch)_(\d+)_r(\d+))?(?:_a(\d+))?$")


def row_label(set_name: str, cmd: int) -> str:
    """Table 1's name of a row, e.g. ``roll+pitch 30``."""
    return "%s %d" % (set_name, cmd)


def table1_setpoint(set_name: str, cmd: float, psi_init: float, yaw_reference: str) -> Tuple[float, float, float]:
    """The row's setpoint (roll, pitch, yaw, deg) in ``yaw_reference``: roll and pitch as Table 1 (against gravity
    in every reference); yaw 0 (absolute: east, as the paper) or -psi_init (relative: the paper's turn)."""
    roll = float(cmd) if set_name in ("roll", "roll+pitch") else 0.0
    pitch = float(cmd) if set_name in ("pitch", "roll+pitch") else 0.0
    return roll, pitch, (-float(psi_init) + 0.0 if yaw_reference == "relative" else 0.0)


@dataclasses.dataclass(frozen=True)
class Phase:
    """A stretch of a disarmed run: the operator's task first (empty: none, it follows at once), then recorded
    ``seconds``."""

    name: str
    prompt: str
    seconds: float


@dataclasses.dataclass(frozen=True)
class Run:
    """One run of the day: its folder ``name``, kind, the operator's task before it (``prompt``), and either the
    phases of a disarmed run or, armed, the setpoints held in turn (``holds``, in ``yaw_reference``) after ``delay``
    s level. ``row``, ``repeat``, ``psi_init`` and ``t_rec``: a Table-1 run's (``t_rec`` None: the gains' own)."""

    name: str
    kind: str
    prompt: str
    armed: bool
    phases: Tuple[Phase, ...] = ()
    holds: Tuple[SetpointHold, ...] = ()
    delay: float = 0.0
    yaw_reference: str = ""
    row: str = ""
    repeat: int = 0
    psi_init: Optional[float] = None
    t_rec: Optional[float] = None

    @property
    def seconds(self) -> float:
        """How long it records once begun, the operator's tasks apart."""
        return self.delay + total_seconds(self.holds) + sum(phase.seconds for phase in self.phases)


@dataclasses.dataclass(frozen=True)
class DayOptions:
    """The day's durations (s), Table 1's rows (labels; empty: all fifteen), repeats and yaw reference, the step test's
    scale (each hold times it) and the motor pack's armed minutes between the prompts for a fresh one."""

    hang_seconds: float = 660.0
    tether_still_seconds: float = 30.0
    tether_hold_seconds: float = 120.0
    tether_release_seconds: float = 180.0
    step_delay: float = 30.0
    step_scale: float = 1.0
    table1_seconds: float = 180.0
    return_seconds: float = 60.0
    repeats: int = 2
    rows: Tuple[str, ...] = ()
    yaw_reference: str = "relative"
    battery_minutes: float = 30.0

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.type == "float" and not (isinstance(value, (int, float)) and 0.0 < value < float("inf")):
                raise ParameterError("tank day: %s must be a positive number, got %r" % (field.name, value))
        if not 0.0 < self.step_scale <= 1.0:
            raise ParameterError("tank day: step_scale must lie in (0, 1], got %r" % (self.step_scale,))
        if not 1 <= self.repeats <= 5:
            raise ParameterError("tank day: repeats must be 1 to 5, got %r" % (self.repeats,))
        if self.yaw_reference not in TABLE1_YAW_REFERENCES:
            raise ParameterError("tank day: yaw_reference must be one of %s, got %r"
                                 % (", ".join(TABLE1_YAW_REFERENCES), self.yaw_reference))
        known = [row_label(s, c) for s, c, _, _ in TABLE_1]
        unknown = [row for row in self.rows if row not in known]
        if unknown:
            raise ParameterError("tank day: %s not a row of Table 1 (%s)" % (", ".join(map(repr, unknown)),
                                                                            ", ".join(known)))


def run_name(index: int, kind: str, row: str = "", repeat: int = 0, attempt: int = 1) -> str:
    """The folder of a run: ``NN_kind``, a Table-1 run's row and repeat after it, ``_aN`` from the second attempt."""
    name = "%02d_%s" % (index, kind)
    if row:
        set_name, cmd = row.split()
        name += "_%s_%s_r%d" % (set_name.replace("+", "_"), cmd, repeat)
    return name + ("_a%d" % attempt if attempt > 1 else "")


def parse_run_name(name: str) -> Optional[Dict[str, Any]]:
    """What a run's folder name says (:func:`run_name`): index, kind, row, repeat, attempt, and ``planned`` (the
    name without its attempt); None for another name."""
    match = _NAME.match(name)
    if not match:
        return None
    index, kind, set_name, cmd, repeat, attempt = match.groups()
    row = row_label(set_name.replace("_", "+"), int(cmd)) if set_name else ""
    return {"index": int(index), "kind": kind, "row": row, "repeat": int(repeat or 0), "attempt": int(attempt or 1),
            "planned": run_name(int(index), kind, row, int(repeat or 0))}


def _time(seconds: float) -> str:
    return "%.0f min" % (seconds / 60.0) if seconds >= 120.0 else "%.0f s" % seconds


def _pack(armed_minutes: float) -> str:
    return ("First a fresh motor pack (about %.0f min armed on this one). " % armed_minutes) if armed_minutes else ""


def day_plan(options: DayOptions = DayOptions()) -> Tuple[Run, ...]:
    """The day's runs in order (module docstring), each with its operator's prompt; an armed run whose minutes would
    take the motor pack past ``battery_minutes`` asks for a fresh pack first."""
    o = options
    runs: List[Run] = [
        Run(run_name(1, "hang"), "hang", "Unpowered hang, %s: servo outputs off, legs set to the nominal pose by "
            "hand, the robot hanging still on its rope, hands and tether off it. Next records it, disarmed."
            % _time(o.hang_seconds), False, (Phase("hang", "", o.hang_seconds),)),
        Run(run_name(2, "tether"), "tether", "Tether bend: hook the spring balance on the tether a few cm above the "
            "gland, slack. Next records %s of the free hang first." % _time(o.tether_still_seconds), False,
            (Phase("free", "", o.tether_still_seconds),
             Phase("held", "Pull the tether sideways until the robot tilts about 10 deg and hold it there; next as "
                   "the pull begins, then note the balance's reading now and at the end (tank_day/note).",
                   o.tether_hold_seconds),
             Phase("released", "Let go of the tether; next as you let go. The fade is recorded for %s."
                   % _time(o.tether_release_seconds), o.tether_release_seconds)))]
    step = tuple(SetpointHold(hold.rpy_deg, hold.seconds * o.step_scale) for hold in STEP_TEST)
    runs.append(Run(run_name(3, "step_test"), "step_test", "Step test, %s armed: servo outputs on, a charged "
                    "motor pack, the robot hanging still. Next arms; level %s, then the steps."
                    % (_time(o.step_delay + total_seconds(step)), _time(o.step_delay)), True, holds=step,
                    delay=o.step_delay, yaw_reference="relative"))
    rows = [row for row in TABLE_1 if not o.rows or row_label(row[0], row[1]) in o.rows]
    index = 4
    for repeat in range(1, o.repeats + 1):
        for set_name, cmd, psi_init, t_rec in rows:
            label = row_label(set_name, cmd)
            holds = (SetpointHold(table1_setpoint(set_name, cmd, psi_init, o.yaw_reference), o.table1_seconds),
                     SetpointHold((0.0, 0.0, 0.0), o.return_seconds))
            runs.append(Run(run_name(index, "table1", label, repeat), "table1", "Table 1 %s, repeat %d of %d: %s, "
                            "then level %s, armed%s. The robot hanging still; next arms."
                            % (label, repeat, o.repeats, _time(o.table1_seconds), _time(o.return_seconds),
                               ", t_rec %.1f s" % t_rec if t_rec != 1.5 else ""), True, holds=holds,
                            yaw_reference=o.yaw_reference, row=label, repeat=repeat, psi_init=psi_init,
                            t_rec=t_rec if t_rec != 1.5 else None))
            index += 1
    paced: List[Run] = []
    armed = 0.0  # seconds on the current pack; the step test starts on a charged one
    for run in runs:
        if run.armed and armed and armed + run.seconds > 60.0 * o.battery_minutes:
            run = dataclasses.replace(run, prompt=_pack(armed / 60.0) + run.prompt)
            armed = 0.0
        armed += run.seconds if run.armed else 0.0
        paced.append(run)
    return tuple(paced)


def remaining(plan: Sequence[Run], records: Mapping[str, Mapping[str, Any]]) -> List[Tuple[Run, int]]:
    """The runs still to do, with their attempt number, given the folders' records already there (folder name ->
    :func:`run_record`): a run is done when an attempt of it ended other than "aborted"."""
    attempts: Dict[str, List[Tuple[int, str]]] = {}
    for folder, record in records.items():
        parsed = parse_run_name(folder)
        if parsed is not None:
            attempts.setdefault(parsed["planned"], []).append((parsed["attempt"], str(record.get("status", ""))))
    todo = []
    for run in plan:
        tried = attempts.get(run.name, [])
        if not any(status != "aborted" for _, status in tried):
            todo.append((run, 1 + max([attempt for attempt, _ in tried], default=0)))
    return todo


def _sha256(path: str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 16), b""):
            digest.update(block)
    return digest.hexdigest()


def config_files(params: Mapping[str, Any]) -> Dict[str, Dict[str, str]]:
    """The configuration files the stack loaded, from its parameters (full name -> value): each ``*_yaml``
    parameter's file, or for an empty one the file of config/ its loader takes (:data:`DEFAULT_FILES`), with its
    sha256 (or why it cannot be read). A ``tank_yaml`` beside a ``plant`` other than tank loads nothing: left out."""
    files = {}
    for name in sorted(params):
        key = name.rsplit("/", 1)[-1]
        if not key.endswith("_yaml") or not isinstance(params[name], str):
            continue
        if key == "tank_yaml" and str(params.get(name[:-len(key)] + "plant", "tank")) != "tank":
            continue
        path = params[name] or (config_path(DEFAULT_FILES[key]) if key in DEFAULT_FILES else "")
        if not path:
            continue
        try:
            files[name] = {"path": path, "sha256": _sha256(path)}
        except OSError as exc:
            files[name] = {"path": path, "sha256": "unreadable: %s" % (exc.strerror or exc)}
    return files


def code_version(package_dir: str, run: Callable[..., Any] = subprocess.run) -> str:
    """``git describe --always --dirty --tags`` of the package's checkout, else the version of its package.xml
    (an install space), else "unknown"."""
    try:
        out = run(["git", "-C", package_dir, "describe", "--always", "--dirty", "--tags"], stdout=subprocess.PIPE,
                  stderr=subprocess.DEVNULL, universal_newlines=True, timeout=10)
        if out.returncode == 0 and out.stdout.strip():
            return "git %s" % out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        with open(os.path.join(package_dir, "package.xml"), encoding="utf-8") as stream:
            match = re.search(r"<version>\s*([^<\s]+)\s*</version>", stream.read())
        if match:
            return "package %s" % match.group(1)
    except OSError:
        pass
    return "unknown"


def _round(value: Any) -> Any:
    """Plain YAML types, floats to 6 decimals."""
    if isinstance(value, float):
        return round(value, 6)
    if isinstance(value, Mapping):
        return {str(k): _round(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_round(v) for v in value]
    return value


def _run_entry(run: Run) -> Dict[str, Any]:
    entry: Dict[str, Any] = {"run": run.name, "kind": run.kind, "armed": run.armed, "seconds": run.seconds,
                             "prompt": run.prompt}
    if run.phases:
        entry["phases"] = [{"name": p.name, "seconds": p.seconds, "prompt": p.prompt} for p in run.phases]
    if run.holds:
        entry.update(delay=run.delay, yaw_reference=run.yaw_reference,
                     holds=[list(h.rpy_deg) + [h.seconds] for h in run.holds])
    if run.kind == "table1":
        entry.update(row=run.row, repeat=run.repeat, paper_psi_init_deg=run.psi_init, t_rec=run.t_rec)
    return entry


def plan_record(plan: Sequence[Run], options: DayOptions, notes: str = "") -> Dict[str, Any]:
    """The day's :data:`PLAN_FILE`: its options and runs, as the day began."""
    return _round({"options": dataclasses.asdict(options), "notes": notes, "runs": [_run_entry(r) for r in plan]})


def run_record(run: Run, status: str, log: Mapping[str, Any]) -> Dict[str, Any]:
    """A run's :data:`RUN_FILE`: the planned run (:func:`plan_record`'s entry) with ``status`` (:data:`STATUSES`) and
    what the node logged, passed through as given: ``why`` (an end other than complete), ``start`` and ``end``
    (``{"ros_time": s, "wall": ISO 8601}``), ``attempt``, ``gains`` (``{"at_start", "at_arming", "at_end"}``: the
    controller's parameter_updates values), ``config`` (:func:`config_files`), ``code`` (:func:`code_version`),
    ``legs_rad`` (``{"at_start", "at_end"}``: joint name -> angle of the last /joint_states), ``events`` and ``notes``
    (``{"at": s from the start, ...}``) and the day's ``day_notes``."""
    if status not in STATUSES:
        raise ValueError("a run's status is one of %s, got %r" % (", ".join(STATUSES), status))
    record = _run_entry(run)
    record["status"] = status
    record.update(log)
    return _round(record)
