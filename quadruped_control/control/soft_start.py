"""A bound on how fast the commanded joint angles move: the soft start and the hold's retrace.

The supervisor (:mod:`quadruped_control.control.supervisor`) starts a :class:`JointSpeedLimiter` from the
joints' measured angles on arming and at the start of every hold; while engaged, each tick's targets move
towards the controller's by at most ``max_speed`` times the elapsed time per joint. It releases once it has
caught up, so the strokes themselves (whose speed the paper's stroke cycle sets) pass unchanged.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np


class JointSpeedLimiter:
    """Rate limit on 12 joint targets (rad): |q_k - q_(k-1)| <= ``max_speed`` (t_k - t_(k-1)) per joint."""

    def __init__(self, max_speed: float) -> None:
        if not (math.isfinite(max_speed) and max_speed > 0.0):
            raise ValueError("max_speed must be a positive number of rad/s, got %r" % (max_speed,))
        self.max_speed = float(max_speed)
        self._last: Optional[np.ndarray] = None
        self._t: Optional[float] = None
        self.engaged = False

    @property
    def last(self) -> Optional[np.ndarray]:
        """The targets of the last tick (copy), or None before the first."""
        return None if self._last is None else self._last.copy()

    def engage(self, t: float, start: Optional[np.ndarray] = None) -> None:
        """Limit from now on, starting at ``start`` (the measured angles), else at the last targets."""
        if start is not None:
            start = np.asarray(start, dtype=float).reshape(12)
            if not np.all(np.isfinite(start)):
                raise ValueError("the limiter needs 12 finite start angles")
            self._last = start.copy()
            self._t = float(t)
        self.engaged = self._last is not None

    def step(self, t: float, targets: np.ndarray) -> np.ndarray:
        """This tick's targets: ``targets`` itself when released, else moved towards it within the bound. A
        non-finite or backwards time counts as no time (the targets stay)."""
        desired = np.asarray(targets, dtype=float).reshape(12)
        if not self.engaged or self._last is None:
            self._last, self._t = desired.copy(), float(t)
            return desired
        dt = float(t) - self._t if self._t is not None else 0.0
        if not (math.isfinite(dt) and dt > 0.0):
            dt = 0.0
        step = self.max_speed * dt
        out = self._last + np.clip(desired - self._last, -step, step)
        self._last = out
        if math.isfinite(float(t)):
            self._t = float(t)
        if np.all(out == desired):
            self.engaged = False
        return out.copy()
