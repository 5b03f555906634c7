"""A witness of machine-level stalls, independent of the ROS stack.

The timing benchmark (benchmarks/bench_sim_graph.sh) needs to tell two causes of a stale-IMU hold
apart: the stack starved the simulated robot (a defect of the stack or of the simulation), or the
whole machine stopped running threads (a virtual machine whose host deschedules its vCPUs, firmware,
a non-preemptible kernel section). A probe thread that sleeps ``period`` at the highest real-time
priority and does nothing else wakes late only in the second case: it shares no lock, interpreter or
socket with the stack. Each late wake-up beyond ``threshold`` is a :class:`Stall`.

Times are wall-clock (``time.time``), the clock of the ROS stamps in real-time mode, so stalls and the
controller's hold episodes can be compared directly.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator, List, Sequence


@dataclass(frozen=True)
class Stall:
    """The probe could not run from ``start`` to ``end`` (s, wall clock) beyond its own sleep."""

    start: float
    end: float

    @property
    def duration(self) -> float:
        return self.end - self.start


def watch(period: float = 0.002, threshold: float = 0.010, keep_running: Callable[[], bool] = lambda: True,
          monotonic: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time,
          sleep: Callable[[float], None] = time.sleep) -> Iterator[Stall]:
    """Sleep ``period`` again and again; yield a :class:`Stall` whenever one sleep lasted more than
    ``period + threshold`` (the time beyond ``period`` is the stall)."""
    last = monotonic()
    while keep_running():
        sleep(period)
        now = monotonic()
        late = now - last - period
        if late > threshold:
            end = wall()
            yield Stall(end - late, end)
        last = now


def format_stall(stall: Stall) -> str:
    return "%.6f,%.6f" % (stall.start, stall.end)


def read_stalls(lines: Iterable[str]) -> List[Stall]:
    """Stalls from the probe's CSV lines (``start,end``; ``#`` lines are comments)."""
    stalls = []
    for line in lines:
        line = line.strip()
        if line and not line.startswith("#"):
            start, end = (float(v) for v in line.split(","))
            stalls.append(Stall(start, end))
    return stalls


def stalled_time(stalls: Sequence[Stall], start: float, end: float) -> float:
    """Seconds of ``[start, end]`` in which the machine was stalled (the union of the stalls in it).

    For a stale-IMU hold decided at ``end``, ``end - start`` is the stale limit plus one control
    period: if the machine was stalled for most of that window, no process, the simulated robot
    included, could have delivered a fresh sample. A long stall often comes in parts (the probe
    wakes for a moment in between), so the parts are added up.
    """
    covered = 0.0
    reached = start
    for stall in sorted(stalls, key=lambda s: s.start):
        lo, hi = max(stall.start, reached), min(stall.end, end)
        if hi > lo:
            covered += hi - lo
            reached = hi
    return covered


__all__ = ["Stall", "watch", "format_stall", "read_stalls", "stalled_time"]
