"""Pure helpers the ROS nodes use to judge their inputs and their own timing (no rospy here).

* :class:`WindowStatistics`: percentiles of the last N samples (loop periods, latencies), for the
  diagnostics the nodes publish and for the latency benchmark.
* :class:`RateMonitor`: message rate over a sliding time window.
* :func:`imu_sample_problem`: why an IMU sample must not be used by the controller (NaN, non-unit
  quaternion, too old), or ``None`` when it is fine. The controller node turns a problem into a hold.
* :class:`LowPassDifferentiator`: filtered joint velocities from sampled positions (servo feedback).
* :class:`HoldEpisodes`: hold episodes and time held (controller diagnostics), not just held steps.
"""
from __future__ import annotations

import collections
import math
from typing import Deque, Dict, Optional, Sequence

import numpy as np

#: A quaternion whose norm is further than this from 1 is rejected (the VN-100 outputs unit
#: quaternions to float precision; anything worse is a corrupted or uninitialised message).
QUATERNION_NORM_TOLERANCE = 1e-3


class WindowStatistics:
    """Percentiles over the most recent ``size`` samples (O(size log size) per query, queries are rare)."""

    def __init__(self, size: int = 1000) -> None:
        if size < 1:
            raise ValueError("window size must be at least 1, got %r" % (size,))
        self._samples: Deque[float] = collections.deque(maxlen=size)
        self.total = 0

    def add(self, value: float) -> None:
        if math.isfinite(value):
            self._samples.append(float(value))
            self.total += 1

    def __len__(self) -> int:
        return len(self._samples)

    def percentile(self, q: float) -> float:
        """The q-th percentile (0..100) of the window, NaN when empty."""
        if not self._samples:
            return math.nan
        return float(np.percentile(np.fromiter(self._samples, float), q))

    def maximum(self) -> float:
        return max(self._samples) if self._samples else math.nan

    def summary(self, scale: float = 1.0) -> Dict[str, float]:
        """p50, p99 and max of the window, multiplied by ``scale`` (e.g. 1e3 for ms)."""
        return {"p50": self.percentile(50) * scale, "p99": self.percentile(99) * scale,
                "max": self.maximum() * scale, "count": float(len(self))}


class RateMonitor:
    """Rate of events (Hz) over the last ``window`` seconds of an injected clock."""

    def __init__(self, window: float = 2.0) -> None:
        if not window > 0:
            raise ValueError("window must be positive, got %r" % (window,))
        self.window = float(window)
        self._stamps: Deque[float] = collections.deque()

    def tick(self, now: float) -> None:
        self._stamps.append(now)
        self._trim(now)

    def _trim(self, now: float) -> None:
        while self._stamps and self._stamps[0] < now - self.window:
            self._stamps.popleft()

    def rate(self, now: float) -> float:
        self._trim(now)
        if len(self._stamps) < 2:
            return 0.0
        span = self._stamps[-1] - self._stamps[0]
        return (len(self._stamps) - 1) / span if span > 0 else 0.0


def imu_sample_problem(orientation_xyzw: Sequence[float], angular_velocity: Sequence[float],
                       sample_time: float, now: float, max_age: float) -> Optional[str]:
    """Why an IMU sample is unusable for control, or ``None``.

    Rejects non-finite values, a quaternion whose norm differs from 1 by more than
    :data:`QUATERNION_NORM_TOLERANCE`, and samples older than ``max_age`` seconds (or stamped in the
    future by more than ``max_age``: a clock jump is as untrustworthy as a stale sample).
    """
    q = np.asarray(orientation_xyzw, dtype=float)
    w = np.asarray(angular_velocity, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        return "IMU orientation is not finite"
    if w.shape != (3,) or not np.all(np.isfinite(w)):
        return "IMU angular velocity is not finite"
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        return "IMU quaternion is not unit (norm %.4f)" % norm
    age = now - sample_time
    if age > max_age:
        return "IMU sample is stale (%.0f ms old, limit %.0f ms)" % (age * 1e3, max_age * 1e3)
    if age < -max_age:
        return "IMU sample is stamped %.0f ms in the future" % (-age * 1e3)
    return None


class LowPassDifferentiator:
    """Joint velocities by finite differences of sampled positions, through a first-order low-pass.

    ``time_constant`` tau (s): the filter gain per sample is dt / (tau + dt). Joints whose position is
    NaN (invalid feedback) keep their last velocity estimate decaying to zero and restart cleanly.
    """

    def __init__(self, size: int, time_constant: float = 0.03) -> None:
        if time_constant < 0:
            raise ValueError("time_constant must be >= 0, got %r" % (time_constant,))
        self.time_constant = float(time_constant)
        self._last_position = np.full(size, np.nan)
        self._last_time: Optional[float] = None
        self.velocity = np.zeros(size)

    def update(self, t: float, positions: Sequence[float]) -> np.ndarray:
        position = np.asarray(positions, dtype=float)
        if self._last_time is not None and t > self._last_time:
            dt = t - self._last_time
            alpha = dt / (self.time_constant + dt)
            valid = np.isfinite(position) & np.isfinite(self._last_position)
            raw = np.zeros_like(position)
            raw[valid] = (position[valid] - self._last_position[valid]) / dt
            self.velocity = np.where(valid, self.velocity + alpha * (raw - self.velocity),
                                     (1.0 - alpha) * self.velocity)
        self._last_position = position.copy()
        self._last_time = t
        return self.velocity.copy()


class HoldEpisodes:
    """Hold episodes and time held, from a per-tick "holding or not" signal on one clock.

    A run of consecutive holding ticks is one episode, however many ticks it lasts (a 70 ms stale-IMU
    gap is one episode of seven held steps at 100 Hz). ``time_held`` adds, for every interval between
    two updates, its length when the earlier update was holding (so an episode lasts from its first
    held tick to the first tick that strokes again). Episodes are also counted per ``kind`` (the caller
    names the reason, e.g. "stale IMU"). A non-finite or backward time adds no time.
    """

    def __init__(self) -> None:
        self.episodes = 0
        self.held_ticks = 0
        self.time_held = 0.0
        self.by_kind: Dict[str, int] = {}
        self._holding = False
        self._last_t: Optional[float] = None

    @property
    def holding(self) -> bool:
        return self._holding

    def update(self, t: float, holding: bool, kind: str = "") -> None:
        t = float(t)
        if self._holding and self._last_t is not None and math.isfinite(t) and t > self._last_t:
            self.time_held += t - self._last_t
        if math.isfinite(t) and (self._last_t is None or t > self._last_t):
            self._last_t = t
        if holding:
            self.held_ticks += 1
            if not self._holding:
                self.episodes += 1
                self.by_kind[kind] = self.by_kind.get(kind, 0) + 1
        self._holding = bool(holding)

    def episodes_of(self, kind: str) -> int:
        return self.by_kind.get(kind, 0)
