"""What a working IMU can report: ONE check for the driver and the controller.

``quadruped_drivers.vn100.conversions.vn_to_ros`` checks every VN-100 sample with it before converting
it (the driver drops it), and the controller's supervisor checks every /imu/data message with it again
before the controller may use it (so a corrupted message from anywhere is dropped too). The bounds are
the VN-100's ranges (VectorNav VN-100 datasheet / product brief, "IMU specifications": gyro +-2000 deg/s,
accelerometer +-16 g); both nodes take their values from ``config/vn100.yaml`` (``max_angular_rate``,
``max_acceleration``, ``quaternion_norm_tolerance``: the ranges + 5 %). Axis permutations and sign
flips (NED/FRD <-> ENU/FLU) change neither a per-axis magnitude nor a norm, so the same check holds in
either frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple, Union

import numpy as np

ArrayLike = Union[Sequence[float], np.ndarray]

#: A quaternion whose norm differs from 1 by more than this is rejected (the VN-100 sends float32 unit
#: quaternions, norm error ~1e-7; anything larger means corruption).
UNIT_TOLERANCE = 1e-3
#: VN-100 measurement ranges (datasheet): the sensor saturates there, so a larger component can only
#: come from a corrupted packet. Defaults of :class:`SensorLimits`.
GYRO_RANGE_RAD_S = math.radians(2000.0)
ACCEL_RANGE_M_S2 = 16.0 * 9.80665


class ImplausibleSample(ValueError):
    """A sample that cannot come from a working IMU (non-finite, non-unit quaternion, out of range).

    ``reason`` is a short, stable key for counters and diagnostics: ``non-finite``,
    ``quaternion norm``, ``angular rate range``, ``acceleration range``, ``angular acceleration``.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


#: Largest plausible angular acceleration of the body, rad/s^2, and the noise allowance on a rate change,
#: rad/s (defaults of :class:`SensorLimits`; config/vn100.yaml says why).
MAX_ANGULAR_ACCELERATION = 200.0
RATE_CHANGE_MARGIN = 0.1


@dataclass(frozen=True)
class SensorLimits:
    """Plausibility bounds of one sample: ``|component| <= max_angular_rate`` (rad/s) and
    ``<= max_acceleration`` (m/s^2), quaternion norm within ``unit_tolerance`` of 1; and across samples
    (:class:`RateChangeCheck`): the rate changes by at most ``max_angular_acceleration`` (rad/s^2) x the
    time between samples + ``rate_change_margin`` (rad/s), unless ``rate_change_confirm`` consecutive
    samples agree."""

    max_angular_rate: float = GYRO_RANGE_RAD_S
    max_acceleration: float = ACCEL_RANGE_M_S2
    unit_tolerance: float = UNIT_TOLERANCE
    max_angular_acceleration: float = MAX_ANGULAR_ACCELERATION
    rate_change_margin: float = RATE_CHANGE_MARGIN
    rate_change_confirm: int = 3

    def __post_init__(self) -> None:
        for name in ("max_angular_rate", "max_acceleration", "unit_tolerance", "max_angular_acceleration",
                     "rate_change_margin"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                    math.isfinite(value) and value > 0):
                raise ValueError("SensorLimits.%s must be a positive finite number, got %r" % (name, value))
        confirm = self.rate_change_confirm
        if isinstance(confirm, bool) or not isinstance(confirm, int) or confirm < 1:
            raise ValueError("SensorLimits.rate_change_confirm must be an integer >= 1, got %r" % (confirm,))


DEFAULT_LIMITS = SensorLimits()


def unit_quaternion(q: ArrayLike, name: str, tolerance: float) -> np.ndarray:
    """``q`` normalised; ImplausibleSample unless finite and of norm 1 within ``tolerance``."""
    v = np.asarray(q, dtype=float).reshape(-1)
    if v.shape != (4,):
        raise ValueError("%s must have 4 elements (x, y, z, w), got shape %s" % (name, np.shape(q)))
    if not np.all(np.isfinite(v)):
        raise ImplausibleSample("non-finite", "%s has non-finite elements: %s" % (name, v))
    scale = float(np.max(np.abs(v)))
    norm = scale * float(np.linalg.norm(v / scale)) if scale > 0.0 else 0.0  # no overflow for 3.4e38
    if not abs(norm - 1.0) <= tolerance:  # also catches an overflowing norm (inf)
        raise ImplausibleSample("quaternion norm", "%s is not a unit quaternion (norm %.6g)" % (name, norm))
    return v / norm


def bounded_vector3(v: ArrayLike, name: str, bound: float = math.inf, reason: str = "") -> np.ndarray:
    """``v`` as a 3-array; ImplausibleSample (``reason``) unless finite and every |component| <= ``bound``."""
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,):
        raise ValueError("%s must have 3 elements, got shape %s" % (name, np.shape(v)))
    if not np.all(np.isfinite(a)):
        raise ImplausibleSample("non-finite", "%s has non-finite elements: %s" % (name, a))
    if not np.all(np.abs(a) <= bound):
        raise ImplausibleSample(reason, "%s %s is outside the sensor range +-%.6g" % (name, a, bound))
    return a


def check_sample(quaternion_xyzw: ArrayLike, angular_rate: ArrayLike, acceleration: Optional[ArrayLike],
                 limits: SensorLimits = DEFAULT_LIMITS) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """(unit quaternion, rate, acceleration) of a sample that could come from a working IMU: finite, unit
    quaternion, every rate and acceleration (when given) component within the range; ImplausibleSample
    (a ValueError, with ``reason``) otherwise, ValueError for wrong shapes."""
    q = unit_quaternion(quaternion_xyzw, "quaternion", limits.unit_tolerance)
    rate = bounded_vector3(angular_rate, "angular rate", limits.max_angular_rate, "angular rate range")
    if acceleration is None:
        return q, rate, None
    return q, rate, bounded_vector3(acceleration, "acceleration", limits.max_acceleration, "acceleration range")


class RateChangeCheck:
    """Physical-rate plausibility across samples: a rate inside the gyro's range can still be impossible.

    The body's angular rate cannot change faster than ``limits.max_angular_acceleration``: a sample whose
    rate differs from the last accepted one by more than max_angular_acceleration x (t - t_last) +
    ``limits.rate_change_margin`` (largest component) raises :class:`ImplausibleSample` ("angular
    acceleration"), e.g. a one-sample spike from a corrupted packet that passed the CRC. So that a real,
    violent change (a knock against the tank wall) cannot lock the check out, ``limits.rate_change_confirm``
    consecutive samples that agree with each other within the same bound are accepted (``confirmed``
    counts those). Times are the samples' own stamps (s); a sample without a finite stamp, or older than
    the last accepted one, is not judged (and does not move the reference). One instance per stream.
    """

    def __init__(self, limits: SensorLimits = DEFAULT_LIMITS) -> None:
        self.limits = limits
        self.confirmed = 0
        self._rate: Optional[np.ndarray] = None
        self._time = -math.inf
        self._run = 0
        self._run_rate = np.zeros(3)
        self._run_time = -math.inf

    def reset(self) -> None:
        """Forget the stream (e.g. after a reconnect): the next sample is accepted as the reference."""
        self._rate, self._time, self._run = None, -math.inf, 0

    def _agrees(self, rate: np.ndarray, reference: np.ndarray, elapsed: float) -> bool:
        allowed = self.limits.max_angular_acceleration * elapsed + self.limits.rate_change_margin
        return float(np.max(np.abs(rate - reference))) <= allowed

    def check(self, stamp: float, angular_rate: ArrayLike) -> None:
        """Accept ``angular_rate`` (rad/s) taken at ``stamp`` (s), or raise ImplausibleSample."""
        rate = np.asarray(angular_rate, dtype=float).reshape(3)
        if not (math.isfinite(stamp) and stamp >= self._time):
            return
        if self._rate is None or self._agrees(rate, self._rate, stamp - self._time):
            self._rate, self._time, self._run = rate, stamp, 0
            return
        if self._run > 0 and self._agrees(rate, self._run_rate, stamp - self._run_time):
            self._run += 1
        else:
            self._run = 1
        self._run_rate, self._run_time = rate, stamp
        if self._run >= self.limits.rate_change_confirm:
            self.confirmed += 1
            self._rate, self._time, self._run = rate, stamp, 0
            return
        change = float(np.max(np.abs(rate - self._rate)))
        raise ImplausibleSample("angular acceleration",
                                "angular rate changed by %.4g rad/s in %.4g s (more than %.4g rad/s^2 allows)"
                                % (change, stamp - self._time, self.limits.max_angular_acceleration))
