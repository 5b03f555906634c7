"""Servo tracking watch: does each joint's feedback follow its command as a working servo would?

While armed, the watch runs the servo's own model (:func:`~quadruped_control.model.servo.rate_limited_lag_step`:
a first-order lag of ``time_constant`` with the no-load speed as its limit) on the commands the supervisor sends,
from the measured angles at arming. Each feedback sample, stamped at its reading, is compared with the band the
model's angle swept over the ``latency`` before that stamp (the command's way to the chip and the reading's way
back); its distance outside the band is the sample's tracking error. A joint whose error's RMS over the last
``window`` stays above ``bound`` is WARN after ``warn_after`` and ERROR after ``error_after``, by name, and stays
WARN for ``report_hold`` after it falls back (a slowed servo lags only in the fast moves: its report must not
flicker). The bound comes from healthy joints' tracking (docs/faults.md); a reversed, stalled or slowed servo
exceeds it. A slowed servo shows only in moves faster than its speed that last longer than ``latency``: the
pre-dive check times each servo's speed instead (``ServoCheck.check_speeds`` in quadruped_control.bringup).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_control.model.servo import rate_limited_lag_step

OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class TrackingSettings:
    """The watch's model and thresholds (``tracking.*`` of config/safety.yaml; SI units)."""

    max_speed: float = 95.0 * math.pi / 30.0  # rad/s, the servo's no-load speed (robot.yaml; the supervisor sets it)
    time_constant: float = 0.03
    latency: float = 0.03
    window: float = 0.5
    bound: float = 0.087
    warn_after: float = 0.1
    error_after: float = 0.5
    report_hold: float = 2.0

    def __post_init__(self) -> None:
        for name in ("max_speed", "latency", "window", "bound"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError("tracking %s must be positive, got %r" % (name, value))
        if not (math.isfinite(self.time_constant) and self.time_constant >= 0.0):
            raise ValueError("tracking time_constant must be >= 0, got %r" % (self.time_constant,))
        if not (math.isfinite(self.report_hold) and self.report_hold >= 0.0):
            raise ValueError("tracking report_hold must be >= 0, got %r" % (self.report_hold,))
        if not (0.0 <= self.warn_after <= self.error_after and math.isfinite(self.error_after)):
            raise ValueError("tracking needs 0 <= warn_after <= error_after, got %r, %r"
                             % (self.warn_after, self.error_after))


class ServoTrackingWatch:
    """The watch of 12 joints (module docstring). Feed :meth:`start` on arming, :meth:`command` with each tick's
    targets, :meth:`feedback` with each reading, :meth:`stop` on disarming; read :meth:`levels`."""

    def __init__(self, settings: TrackingSettings, names: Sequence[str]) -> None:
        self.settings = settings
        self.names = tuple(names)
        self._n = len(self.names)
        self.active = False
        self._model = np.zeros(self._n)
        self._target = np.zeros(self._n)
        self._t = 0.0
        self._history: Deque[Tuple[float, np.ndarray]] = deque()
        self._errors: Deque[Tuple[float, np.ndarray]] = deque()
        self._over_since: List[Optional[float]] = [None] * self._n
        self._last_over: List[Optional[float]] = [None] * self._n
        self.largest_rms = np.zeros(self._n)  # since start: what a healthy run reaches (the bound's evidence)

    def start(self, t: float, positions: Sequence[float]) -> None:
        """Armed at ``t`` with the joints measured at ``positions`` (finite): the model starts there."""
        q = np.asarray(positions, dtype=float).reshape(self._n)
        self._model, self._target, self._t = q.copy(), q.copy(), float(t)
        self._history = deque([(self._t, q.copy())])
        self._errors = deque()
        self._over_since = [None] * self._n
        self._last_over = [None] * self._n
        self.largest_rms = np.zeros(self._n)
        self.active = bool(np.all(np.isfinite(q)))

    def stop(self) -> None:
        """Disarmed: nothing is judged until the next :meth:`start`."""
        self.active = False
        self._over_since = [None] * self._n
        self._last_over = [None] * self._n

    def _advance(self, t: float) -> None:
        dt = t - self._t
        if not dt > 0.0:
            return
        s = self.settings
        self._model = np.array([rate_limited_lag_step(q, c, s.max_speed, s.time_constant, dt)
                                for q, c in zip(self._model.tolist(), self._target.tolist())])
        self._t = t
        self._history.append((t, self._model.copy()))
        horizon = t - 2.0 * s.latency - 0.1
        while len(self._history) > 2 and self._history[1][0] < horizon:
            self._history.popleft()

    def command(self, t: float, targets: Sequence[float]) -> None:
        """The targets sent at ``t`` (rad); the model has followed the previous ones until then."""
        if not self.active:
            return
        self._advance(float(t))
        target = np.asarray(targets, dtype=float).reshape(self._n)
        self._target = np.where(np.isfinite(target), target, self._target)

    def feedback(self, stamp: float, positions: Sequence[float]) -> Optional[np.ndarray]:
        """A reading stamped ``stamp``; returns each joint's tracking error (rad, NaN where not judged)."""
        if not self.active or not math.isfinite(stamp):
            return None
        q = np.asarray(positions, dtype=float).reshape(self._n)
        start = stamp - self.settings.latency
        band = [m for t, m in self._history if start <= t <= stamp]
        before = [m for t, m in self._history if t < start]
        if before:
            band.append(before[-1])  # the model's angle at the band's start
        if stamp > self._t:
            band.append(self._model)  # no command since: the model has not moved far from its last point
        if not band:
            return None
        swept = np.array(band)
        low, high = swept.min(axis=0), swept.max(axis=0)
        error = np.maximum(0.0, np.maximum(low - q, q - high))
        error[~np.isfinite(q)] = np.nan
        self._errors.append((float(stamp), error))
        while self._errors and self._errors[0][0] < stamp - self.settings.window:
            self._errors.popleft()
        return error

    def rms(self) -> np.ndarray:
        """Each joint's tracking error RMS over the last window (rad; NaN without samples)."""
        if not self._errors:
            return np.full(self._n, np.nan)
        errors = np.array([e for _, e in self._errors])
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(errors ** 2, axis=0)) if np.any(np.isfinite(errors)) \
                else np.full(self._n, np.nan)

    def levels(self, now: float) -> List[Tuple[str, int, float]]:
        """(name, OK / WARN / ERROR, RMS) per joint at ``now``: over the bound for ``warn_after`` / ``error_after``,
        or over it within the last ``report_hold`` (WARN). A window not yet full is judged on what it holds."""
        rms = self.rms()
        s = self.settings
        out = []
        for i, name in enumerate(self.names):
            value = float(rms[i])
            level = OK
            if self.active and math.isfinite(value):
                self.largest_rms[i] = max(self.largest_rms[i], value)
            if self.active and value > s.bound:
                if self._over_since[i] is None:
                    self._over_since[i] = now
                self._last_over[i] = now
                over = now - self._over_since[i]
                level = ERROR if over >= s.error_after else WARN if over >= s.warn_after else OK
            else:
                self._over_since[i] = None
            last = self._last_over[i]
            if level == OK and self.active and last is not None and now - last < s.report_hold:
                level = WARN
            out.append((name, level, value))
        return out
