"""What a fault did to the running robot: the figures of the fault campaign, from recorded time series.

Pure functions on arrays (no ROS): ``benchmarks/fault_campaign.py`` and the fault rostest record the
simulated robot's ground truth and the controller's telemetry while faults are injected
(:mod:`quadruped_control.ros.fault_campaign`), then judge each injection here. The samples are

- the **chip**: the pulse widths the fake PCA9685 really produces (``sim/servo_output``), one row of 12
  per physics step, 0 where a channel gives no pulses (servo limp);
- the **commands**: the widths pwm_node was asked for (``servo_command``);
- the **controller**: ``controller_state`` (armed, holding).

Definitions (docs/faults.md's fault table states the expectation of each kind in these words):

- *pulses outside limits*: chip rows with a channel that produces pulses (> 0) outside its joint's
  [min_us, max_us] (plus half a chip tick of quantisation).
- *leg motion while unarmed*: chip rows whose widths differ from the row before by more than half a tick
  on a channel that still produces pulses (a channel going limp is not motion), while the controller is
  unarmed: from a controller kill (plus 50 ms for the commands it sent before it died) until the next
  arm command, and wherever the controller's telemetry says it is disarmed; there, a row producing a command
  sent while armed (in flight when it disarmed) is not motion.
- *safe*: a chip row is safe when the legs are not driven by a stroke: the chip holds every width of the
  row before (the ``hold`` failsafe, or a command path that stopped), every channel is limp (``off``), or
  the controller reports that it holds. *Time to safe state*: from the injection to the first safe row
  after which every row stays safe until the fault ends or the stack tracks again by itself (0 if the
  robot was safe at once). A *stop* (an e-stop, the tether's heartbeat lost, a critical pack, a leak) is judged
  from the moment the stack must act until the operator's arm, and may not track again by itself before it;
  an e-stop's safe rows are the limp ones only.
- *tracking*: the controller reports armed and not holding, and the chip produces one of the controller's
  last three commands (each width within one tick): the command path is closed end to end. *Time to
  recovery*: from the fault's end to the first tracking row.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["FaultRecord", "InjectionResult", "Timeline", "judge_injection", "kind_summary", "landing_rows", "limp_rows",
           "lost_messages", "pulses_outside_limits", "motion_rows", "safe_rows", "stamp_keys", "tracking_rows"]


@dataclass
class Timeline:
    """The recorded samples of one run (times in seconds on one clock, increasing)."""

    chip_t: np.ndarray            # (n,)
    chip_widths: np.ndarray       # (n, 12) us, 0 = no pulses
    command_t: np.ndarray         # (m,)
    command_widths: np.ndarray    # (m, 12) us
    state_t: np.ndarray           # (k,)
    armed: np.ndarray             # (k,) bool
    holding: np.ndarray           # (k,) bool

    def __post_init__(self) -> None:
        for name in ("chip_widths", "command_widths"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim != 2:
                value = value.reshape(-1, 12)
            setattr(self, name, value)
        for name in ("chip_t", "command_t", "state_t"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=float).reshape(-1))
        self.armed = np.asarray(self.armed, dtype=bool).reshape(-1)
        self.holding = np.asarray(self.holding, dtype=bool).reshape(-1)
        if len(self.chip_t) != len(self.chip_widths) or len(self.command_t) != len(self.command_widths) \
                or not len(self.state_t) == len(self.armed) == len(self.holding):
            raise ValueError("timeline: every series needs as many times as samples")


@dataclass
class FaultRecord:
    """One injection: its kind, when it began and ended (``end`` is when the fault was over: the link back,
    the node respawned, the arm command sent after a controller restart), and what the stack must do."""

    kind: str
    start: float
    end: float
    #: "safe": the robot must reach a safe state within the limit; "track": the control path must keep
    #: tracking through the fault (it does not touch it); "stop": safe as "safe", from the moment the stack
    #: must act, and disarmed until the operator's arm at ``end``.
    expect: str
    #: Spans in which the controller is unarmed whatever its telemetry says (a killed controller, until
    #: the arm command after its restart).
    unarmed: List[Tuple[float, float]] = field(default_factory=list)
    note: str = ""
    #: The safe state must be every output off (an e-stop), not any safe state.
    limp: bool = False


@dataclass
class InjectionResult:
    kind: str
    start: float
    time_to_safe: Optional[float]       # s; None: never safe (a failure where expect == "safe")
    time_to_recovery: Optional[float]   # s after the fault's end; None: did not track again
    tracking_fraction: float            # share of the fault's rows that tracked (for expect == "track")
    pulses_outside: int
    moved_unarmed: int
    lost_before: Optional[int] = None   # messages the bag lacks in the window before the fault


def _tick_us(frequency_hz: float) -> float:
    return 1e6 / (frequency_hz * 4096.0)


def pulses_outside_limits(widths: np.ndarray, min_us: Sequence[float], max_us: Sequence[float],
                          tick_us: float) -> np.ndarray:
    """Rows (bool) with a driven channel outside its [min_us, max_us] (+- half a tick)."""
    widths = np.asarray(widths, dtype=float)
    driven = ~(widths <= 0.0)  # NaN counts as driven (and outside)
    low = np.asarray(min_us, dtype=float) - 0.5 * tick_us
    high = np.asarray(max_us, dtype=float) + 0.5 * tick_us
    bad = driven & ((widths < low) | (widths > high) | ~np.isfinite(widths))
    return bad.any(axis=1)


def motion_rows(widths: np.ndarray, tick_us: float) -> np.ndarray:
    """Rows (bool) whose driven widths moved by more than half a tick from the row before (row 0: False)."""
    widths = np.asarray(widths, dtype=float)
    moved = np.zeros(len(widths), dtype=bool)
    if len(widths) > 1:
        change = np.abs(np.diff(widths, axis=0)) > 0.5 * tick_us
        still_driven = widths[1:] > 0.0
        moved[1:] = (change & still_driven).any(axis=1)
    return moved


def _latest(times: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the latest sample at or before each time of ``at`` (-1: none yet)."""
    return np.searchsorted(times, at, side="right") - 1


def _state_at(timeline: Timeline, at: np.ndarray, max_age: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(fresh, armed, holding) of the controller's latest telemetry at each time (fresh: within max_age)."""
    index = _latest(timeline.state_t, at)
    valid = index >= 0
    safe_index = np.where(valid, index, 0)
    if len(timeline.state_t) == 0:
        false = np.zeros(len(at), dtype=bool)
        return false, false, false
    fresh = valid & (at - timeline.state_t[safe_index] <= max_age)
    return fresh, valid & timeline.armed[safe_index], valid & timeline.holding[safe_index]


def safe_rows(timeline: Timeline, tick_us: float, state_max_age: float = 0.05) -> np.ndarray:
    """Chip rows (bool) on which the legs are not driven by a stroke (module docstring)."""
    widths = timeline.chip_widths
    held = np.ones(len(widths), dtype=bool)
    if len(widths) > 1:
        held[1:] = (np.abs(np.diff(widths, axis=0)) <= 0.5 * tick_us).all(axis=1)
    limp = (widths <= 0.0).all(axis=1)
    fresh, armed, holding = _state_at(timeline, timeline.chip_t, state_max_age)
    controller_safe = fresh & (holding | ~armed)
    return held | limp | controller_safe


def limp_rows(timeline: Timeline) -> np.ndarray:
    """Chip rows (bool) with every output off (the servos limp)."""
    return (timeline.chip_widths <= 0.0).all(axis=1)


def tracking_rows(timeline: Timeline, tick_us: float, state_max_age: float = 0.05) -> np.ndarray:
    """Chip rows (bool) on which the robot tracks: the controller armed and stroking, and the chip producing
    one of its last three commands (module docstring)."""
    fresh, armed, holding = _state_at(timeline, timeline.chip_t, state_max_age)
    ok = fresh & armed & ~holding
    matched = np.zeros(len(timeline.chip_t), dtype=bool)
    if len(timeline.command_t):
        last = _latest(timeline.command_t, timeline.chip_t)
        for back in range(3):
            index = last - back
            valid = index >= 0
            commands = timeline.command_widths[np.where(valid, index, 0)]
            close = (np.abs(commands - timeline.chip_widths) <= tick_us).all(axis=1)
            matched |= valid & close
    return ok & matched


def landing_rows(timeline: Timeline, tick_us: float) -> np.ndarray:
    """Chip rows (bool) that produce one of the last three commands stamped before the controller's latest armed
    telemetry: a command sent while armed landing after the disarm (in flight on a loaded host), not motion."""
    if len(timeline.command_t) == 0 or len(timeline.state_t) == 0:
        return np.zeros(len(timeline.chip_t), dtype=bool)
    armed_t = np.where(timeline.armed, timeline.state_t, -np.inf)
    last_armed = np.maximum.accumulate(armed_t)[np.maximum(_latest(timeline.state_t, timeline.chip_t), 0)]
    last = _latest(timeline.command_t, last_armed)
    landing = np.zeros(len(timeline.chip_t), dtype=bool)
    for back in range(3):
        index = last - back
        valid = index >= 0
        commands = timeline.command_widths[np.where(valid, index, 0)]
        landing |= valid & (np.abs(commands - timeline.chip_widths) <= tick_us).all(axis=1)
    return landing


def _in_spans(t: np.ndarray, spans: Sequence[Tuple[float, float]]) -> np.ndarray:
    inside = np.zeros(len(t), dtype=bool)
    for low, high in spans:
        inside |= (t >= low) & (t <= high)
    return inside


def judge_injection(timeline: Timeline, fault: FaultRecord, min_us: Sequence[float], max_us: Sequence[float],
                    pwm_frequency_hz: float, settle_window: float = 5.0,
                    state_max_age: float = 0.05) -> InjectionResult:
    """The figures of one injection from ``fault.start`` to ``fault.end + settle_window`` (module docstring)."""
    tick = _tick_us(pwm_frequency_hz)
    t = timeline.chip_t
    window = (t >= fault.start) & (t <= fault.end + settle_window)
    outside = int(pulses_outside_limits(timeline.chip_widths, min_us, max_us, tick)[window].sum())

    fresh, armed, _holding = _state_at(timeline, t, state_max_age)
    disarmed = fresh & ~armed
    unarmed = _in_spans(t, fault.unarmed) | (disarmed & ~landing_rows(timeline, tick))
    moved = int((motion_rows(timeline.chip_widths, tick) & unarmed & window).sum())

    safe = limp_rows(timeline) if fault.limp else safe_rows(timeline, tick, state_max_age)
    tracking = tracking_rows(timeline, tick, state_max_age)
    during = (t >= fault.start) & (t <= fault.end)
    time_to_safe: Optional[float] = None
    rows = np.flatnonzero(during)
    first_safe = rows[safe[rows]][:1]
    if len(first_safe):
        # Safe until the fault ends, or until the stack tracks again by itself (a respawned driver can
        # close the command path before the campaign sees it registered).
        resumed = rows[(rows > first_safe[0]) & tracking[rows]][:1] if fault.expect != "stop" else rows[:0]
        judged = rows[rows < resumed[0]] if len(resumed) else rows
        unsafe = judged[~safe[judged]]
        if len(unsafe) == 0:
            time_to_safe = 0.0
        elif unsafe[-1] != judged[-1]:
            time_to_safe = max(0.0, float(t[unsafe[-1] + 1] - fault.start))

    after = np.flatnonzero((t >= fault.end) & (t <= fault.end + settle_window) & tracking)
    time_to_recovery = float(t[after[0]] - fault.end) if len(after) else None
    fraction = float(tracking[during].mean()) if during.any() else 0.0
    return InjectionResult(fault.kind, fault.start, time_to_safe, time_to_recovery, fraction, outside, moved)


def stamp_keys(stamps: Sequence[float]) -> set:
    """Message stamps (s) as integer microseconds, for :func:`lost_messages` (build once per bag)."""
    return set(np.round(np.asarray(stamps, dtype=float) * 1e6).astype(np.int64).tolist())


def lost_messages(received: Sequence[float], recorded: set, start: float, end: float) -> int:
    """Messages stamped in [start, end) that a subscriber received but the bag does not hold, matched by
    stamp (``recorded``: the bag's :func:`stamp_keys`)."""
    received = np.asarray(received, dtype=float)
    got = stamp_keys(received[(received >= start) & (received < end)])
    return len(got - recorded)


def kind_summary(results: Sequence[InjectionResult], expect: str) -> Dict[str, object]:
    """Per fault kind: injections, time to safe state (max), time to recovery (median / max), pulses
    outside limits, legs moved while unarmed, messages lost before the fault, and the failures."""
    n = len(results)
    safe = [r.time_to_safe for r in results]
    recovery = [r.time_to_recovery for r in results]
    lost = [r.lost_before for r in results if r.lost_before is not None]
    done = [x for x in recovery if x is not None]
    return {
        "injections": n,
        "expect": expect,
        "never_safe": sum(1 for x in safe if x is None) if expect != "track" else 0,
        "time_to_safe_max": max((x for x in safe if x is not None), default=None) if expect != "track" else None,
        "tracking_fraction_min": min((r.tracking_fraction for r in results), default=None)
        if expect == "track" else None,
        "recovered": len(done),
        "time_to_recovery_median": float(np.median(done)) if done else None,
        "time_to_recovery_max": max(done) if done else None,
        "pulses_outside": sum(r.pulses_outside for r in results),
        "moved_unarmed": sum(r.moved_unarmed for r in results),
        "lost_before": sum(lost) if lost else None,  # None: no bag was compared
        "lost_measured": len(lost),
    }
