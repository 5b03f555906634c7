"""The last check between the VN-100 and /imu/data: plausibility, burst dating, per-sample isolation.

:class:`SampleGate` takes the decoded samples of one read (a burst of packets that arrived together)
and returns the ones that may be published, each with how long before the arrival time it was taken.
A sample is dropped, and counted under its reason, when

* a field is missing (``missing field``),
* :func:`~quadruped_drivers.vn100.conversions.vn_to_ros` finds it implausible against
  :class:`~quadruped_drivers.vn100.conversions.SensorLimits` (``non-finite``, ``quaternion norm``,
  ``angular rate range``, ``acceleration range``): a corrupted packet that passed the CRC by chance
  (1 in 65,536 corrupted packets) can carry any float32, e.g. 3.4e38 rad/s,
* its angular rate differs from the last published one by more than the body can change it
  (``angular acceleration``: :class:`~quadruped_common.imu_plausibility.RateChangeCheck`, judged on the
  samples' dated arrival times when :meth:`SampleGate.process` is given the arrival time), e.g. a rate
  spike inside the gyro's range,
* anything else goes wrong while converting it (``internal error``; never raised: the reader thread
  and the good samples after it carry on).

Sensor time (TimeStartup, u64 ns) only dates a burst back: a sample is stamped ``arrival - (t_last -
t_sample)``. A difference that is negative, not an integer, or larger than ``max_backdate`` (e.g. a
corrupted stamp of ~1e19 ns) is not trusted: the sample keeps the arrival time and ``sensor time``
is counted, but the sample itself is still published (its measurement passed the checks).
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional, Sequence, Tuple

from quadruped_common.imu_plausibility import RateChangeCheck
from quadruped_drivers.vn100.conversions import (DEFAULT_LIMITS, ImplausibleSample, ImuReading, SensorLimits,
                                                 vn_to_ros)
from quadruped_drivers.vn100.protocol import Vn100Sample

#: Reasons a sample is dropped (counter keys), in diagnostics order.
DROP_REASONS: Tuple[str, ...] = ("missing field", "non-finite", "quaternion norm", "angular rate range",
                                 "acceleration range", "angular acceleration", "internal error")
#: Counter of samples whose sensor time could not date them (published with the arrival time).
TIME_ANOMALY = "sensor time"


def backdate_seconds(last_ns: object, sample_ns: object, max_backdate: float) -> Optional[float]:
    """How long before the burst's last sample this one was taken, in s, or None if not trustworthy.

    Both stamps must be integers (u64 ns of the sensor clock); the difference must lie in
    ``[0, max_backdate]``. Pure integer arithmetic first, so huge values cannot overflow a float.
    """
    if isinstance(last_ns, bool) or isinstance(sample_ns, bool):
        return None
    if not isinstance(last_ns, int) or not isinstance(sample_ns, int):
        return None
    difference = last_ns - sample_ns
    if difference < 0 or difference > int(max_backdate * 1e9):
        return None
    return difference * 1e-9


class SampleGate:
    """Filters and dates bursts of :class:`Vn100Sample`; counters in :attr:`counts` (see module doc)."""

    def __init__(self, limits: SensorLimits = DEFAULT_LIMITS, max_backdate: float = 0.1) -> None:
        if isinstance(max_backdate, bool) or not isinstance(max_backdate, (int, float)) or not (
                math.isfinite(max_backdate) and max_backdate >= 0):
            raise ValueError("max_backdate must be a finite number >= 0, got %r" % (max_backdate,))
        self.limits = limits
        self.rate_check = RateChangeCheck(limits)
        self.max_backdate = float(max_backdate)
        self.counts: Dict[str, int] = {reason: 0 for reason in DROP_REASONS + (TIME_ANOMALY,)}
        self.accepted = 0
        self.last_drop = ""

    @property
    def dropped(self) -> int:
        """Samples dropped for any reason."""
        return sum(self.counts[reason] for reason in DROP_REASONS)

    def _drop(self, reason: str, message: str) -> None:
        self.counts[reason] += 1
        self.last_drop = "%s: %s" % (reason, message)

    def _convert(self, sample: Vn100Sample) -> Optional[ImuReading]:
        try:
            if sample.quaternion_xyzw is None or sample.angular_rate is None or sample.acceleration is None:
                self._drop("missing field", "packet without quaternion, rate or acceleration")
                return None
            return vn_to_ros(sample.quaternion_xyzw, sample.angular_rate, sample.acceleration, self.limits)
        except ImplausibleSample as exc:
            self._drop(exc.reason, str(exc))
        except Exception as exc:  # noqa: BLE001 - one bad sample must never stop the stream
            self._drop("internal error", "%s: %s" % (type(exc).__name__, exc))
        return None

    def process(self, samples: Sequence[Vn100Sample], arrival: Optional[float] = None) -> List[Tuple[ImuReading, float]]:
        """(reading, seconds before arrival) for every publishable sample of one burst, in order.

        ``arrival`` (s, the clock the node stamps with): with it, each sample's rate change is judged
        against the previous published sample's at their dated times (``angular acceleration``)."""
        if not samples:
            return []
        last_ns = getattr(samples[-1], "time_startup_ns", None)
        out: List[Tuple[ImuReading, float]] = []
        for sample in samples:
            reading = self._convert(sample)
            if reading is None:
                continue
            offset = backdate_seconds(last_ns, getattr(sample, "time_startup_ns", None), self.max_backdate)
            if offset is None:
                self.counts[TIME_ANOMALY] += 1
                offset = 0.0
            if arrival is not None:
                try:
                    self.rate_check.check(arrival - offset, reading.angular_velocity)
                except ImplausibleSample as exc:
                    self._drop(exc.reason, str(exc))
                    continue
            out.append((reading, offset))
            self.accepted += 1
        return out


__all__ = ["SampleGate", "backdate_seconds", "DROP_REASONS", "TIME_ANOMALY"]
