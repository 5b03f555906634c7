"""Pure helpers the ROS nodes use to judge their inputs and their own timing (no rospy here).

* :class:`WindowStatistics`: percentiles of the last N samples (loop periods, latencies), for the
  diagnostics the nodes publish and for the latency benchmark.
* :class:`RateMonitor`: message rate over a sliding time window.
* :func:`imu_sample_problem`: why an IMU sample must not be used by the controller (NaN, non-unit
  quaternion, rate or acceleration beyond the sensor's range (the check shared with the VN-100 driver,
  :mod:`quadruped_common.imu_plausibility`), non-finite or old
  stamp), or ``None`` when it is fine; :func:`time_problem` is the one freshness check (a non-finite
  stamp or clock is never fresh). The supervisor drops and counts implausible samples and holds.
* :class:`LowPassDifferentiator`: filtered joint velocities from sampled positions (servo feedback).
* :class:`HoldEpisodes`: hold episodes and time held (controller diagnostics), not just held steps.
"""
from __future__ import annotations

import collections
import math
from typing import Deque, Dict, Optional, Sequence

import numpy as np

from quadruped_common.imu_plausibility import DEFAULT_LIMITS, ImplausibleSample, SensorLimits, check_sample



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


def time_problem(stamp: float, now: float, max_age: float, what: str = "IMU sample") -> Optional[str]:
    """Why a sample stamped ``stamp`` is not fresh at ``now``, or ``None``: a non-finite stamp or clock
    (NaN, +-inf, both inf: the age would be NaN and every comparison false), older than ``max_age``, or
    stamped more than ``max_age`` in the future (a clock jump is as untrustworthy as a stale sample)."""
    try:
        stamp, now = float(stamp), float(now)
    except (TypeError, ValueError, OverflowError):
        return "%s time is not a number (stamp %r, clock %r)" % (what, stamp, now)
    if not (math.isfinite(stamp) and math.isfinite(now)):
        return "%s time is not finite (stamp %r, clock %r)" % (what, stamp, now)
    age = now - stamp
    if not math.isfinite(age) or age > max_age:
        return "%s is stale (%.0f ms old, limit %.0f ms)" % (what, age * 1e3, max_age * 1e3)
    if age < -max_age:
        return "%s is stamped %.0f ms in the future" % (what, -age * 1e3)
    return None


def imu_values_problem(orientation_xyzw: Sequence[float], angular_velocity: Sequence[float],
                       linear_acceleration: Optional[Sequence[float]] = None,
                       limits: SensorLimits = DEFAULT_LIMITS) -> Optional[str]:
    """Why an IMU sample's values cannot come from a working sensor (``"<reason>: <message>"``, reason as
    in :class:`~quadruped_common.imu_plausibility.ImplausibleSample`), or ``None``: the shared check
    :func:`~quadruped_common.imu_plausibility.check_sample` (non-finite, non-unit quaternion, rate or
    acceleration beyond the sensor's range)."""
    try:
        check_sample(orientation_xyzw, angular_velocity, linear_acceleration, limits)
    except ImplausibleSample as exc:
        return "IMU sample implausible, %s: %s" % (exc.reason, exc)
    except (TypeError, ValueError, OverflowError) as exc:
        return "IMU sample malformed: %s" % exc
    return None


def imu_sample_problem(orientation_xyzw: Sequence[float], angular_velocity: Sequence[float],
                       sample_time: float, now: float, max_age: float,
                       linear_acceleration: Optional[Sequence[float]] = None,
                       limits: SensorLimits = DEFAULT_LIMITS) -> Optional[str]:
    """Why an IMU sample is unusable for control, or ``None``: :func:`imu_values_problem` (non-finite,
    non-unit quaternion, beyond the sensor's range) or :func:`time_problem` (non-finite stamp or clock,
    stale, from the future)."""
    return (imu_values_problem(orientation_xyzw, angular_velocity, linear_acceleration, limits)
            or time_problem(sample_time, now, max_age))


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
        if not math.isfinite(t):  # a non-finite time cannot date anything: ignore the sample
            return self.velocity.copy()
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


#: Kind of hold whose reason is a stale sample (:func:`time_problem`): the timing failure.
STALE_IMU = "stale IMU"


def hold_kind(problem: str) -> str:
    """Bucket of a hold reason: :data:`STALE_IMU` for a stale sample (the wording of
    :func:`time_problem`), else "other". The controller's diagnostics and the bag report both use it."""
    return STALE_IMU if "stale" in problem else "other"


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
