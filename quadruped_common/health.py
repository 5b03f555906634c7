"""Health summaries of the hazard watchers (``health/depth``, ``health/battery``, ``health/leak``), no ROS.

A :class:`Health` is what a node publishes as one ``diagnostic_msgs/DiagnosticStatus``: a level (the message's
OK / WARN / ERROR values), a stable ``reason`` code (what a consumer may switch on), a message for people and
key/value pairs. :class:`HealthGate` decides when to publish: every ``period`` and at once when the level or
the reason changes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

#: diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}


@dataclass(frozen=True)
class Health:
    """One health summary: ``level`` (:data:`OK`, :data:`WARN`, :data:`ERROR`), ``reason`` (a short code, ""
    when OK), ``message`` (for people), ``values`` ((key, value) strings)."""

    level: int
    reason: str
    message: str
    values: Tuple[Tuple[str, str], ...] = ()


class HealthGate:
    """Publish a health summary every ``period`` seconds and at once when its level or reason changes (or the
    clock went back). The periodic deadlines stay on a grid, so a caller ticking faster than ``period`` publishes
    at 1 / ``period`` on average whatever its tick's jitter."""

    def __init__(self, period: float = 0.5) -> None:
        if not (math.isfinite(period) and period > 0.0):
            raise ValueError("period must be positive, got %r" % (period,))
        self.period = float(period)
        self._last: Optional[Tuple[int, str]] = None
        self._last_time = -math.inf
        self._next = -math.inf

    def due(self, now: float, health: Health) -> bool:
        """True when ``health`` should be published now (and it is then taken as published)."""
        key = (health.level, health.reason)
        changed = key != self._last or now < self._last_time
        if not changed and now < self._next:
            return False
        on_grid = not changed and now - self._next < self.period
        self._next = self._next + self.period if on_grid else now + self.period
        self._last, self._last_time = key, now
        return True


__all__ = ["ERROR", "Health", "HealthGate", "LEVEL_NAMES", "OK", "WARN"]
