"""The depth sensor's run loop without ROS: (re)start the MS5837, poll it, find the surface, judge its health.

:class:`DepthSensorRunner` is what ``ms5837_node`` calls from its timer, twice per reading period
(:func:`poll_period`; :meth:`~quadruped_drivers.ms5837.Ms5837.poll` needs two calls per reading):

* not started (at first, after a start that failed, after ``restart_after_errors`` bus errors in a row):
  :meth:`~quadruped_drivers.ms5837.Ms5837.start` at most every ``retry_period`` seconds: the reset the data
  sheets ask for after power-on ("RESET SEQUENCE": it loads the PROM into the chip's register; a sensor that
  lost its supply needs it again), the PROM read and its CRC-4 ("CYCLIC REDUNDANCY CHECK"). A sensor that does
  not answer, or a PROM that fails the CRC, is tried again; each failure is a ``problem`` for the node to log;
* started: one poll; a reading comes back with its depth from :class:`SurfaceReference`'s surface pressure.

A reading is published only when :func:`publishable` (fresh by the driver's checks, and finite and plausible
again) and, for the depth, once the surface is known. :meth:`DepthSensorRunner.health` is ``health/depth``: ERROR when the PROM failed its CRC, when no fresh
reading came yet or for longer than ``depth.timeout_s``; WARN when a reading was dropped within
``depth.warn_window_s``; else OK. A sensor that is not fitted is OK with reason ``not_fitted``.
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Tuple

from quadruped_common.health import ERROR, OK, WARN, Health
from quadruped_drivers.hardware_config import DepthSensorHardware
from quadruped_drivers.ms5837 import DepthReading, Ms5837, PromCrcError, depth_m

#: Standard gravity (m/s^2), as the driver's depth.
G = 9.80665
#: Variance (m^2, rad^2) published for what a depth sensor does not measure (x, y and the attitude of
#: depth/pose): large enough that a filter (robot_localization) takes nothing from them.
UNMEASURED_VARIANCE = 1e6


def poll_period(depth: DepthSensorHardware) -> float:
    """Seconds between two polls: half a reading period (a reading is a D1 and a D2 conversion)."""
    return 0.5 / depth.rate_hz


def make_driver(bus: Any, depth: DepthSensorHardware, clock: Callable[[], float] = time.monotonic,
                sleep: Callable[[float], None] = time.sleep) -> Ms5837:
    """The MS5837 driver configured by ``depth.*`` (model, address, OSR, density, rate check)."""
    return Ms5837(bus, depth.ms5837_model, address=depth.address, osr=depth.osr, clock=clock, sleep=sleep,
                  surface_pa=depth.surface_pa, density=depth.fluid_density, g=G, max_depth_rate=depth.max_rate_m_s)


def depth_variance(depth: DepthSensorHardware) -> float:
    """Variance of a depth reading (m^2): the pressure's, through depth = p / (rho g)."""
    return (depth.pressure_stddev_pa / (depth.fluid_density * G)) ** 2


def pose_covariance(depth: DepthSensorHardware) -> List[float]:
    """Row-major 6 x 6 covariance of depth/pose (x, y, z, roll, pitch, yaw): z's from the pressure, every other
    variance :data:`UNMEASURED_VARIANCE`, no correlation."""
    diagonal = [UNMEASURED_VARIANCE, UNMEASURED_VARIANCE, depth_variance(depth)] + [UNMEASURED_VARIANCE] * 3
    covariance = [0.0] * 36
    for index, value in enumerate(diagonal):
        covariance[7 * index] = value
    return covariance


def publishable(reading: Optional[DepthReading], driver: Ms5837) -> bool:
    """May ``reading`` be published: fresh, and (again, whatever the driver said) finite and inside the driver's
    plausible pressure and temperature ranges."""
    if reading is None or not reading.fresh:
        return False
    pressure, temperature = reading.pressure_pa, reading.temperature_c
    return (math.isfinite(pressure) and math.isfinite(temperature) and math.isfinite(reading.depth_m)
            and driver.plausible_pa[0] <= pressure <= driver.plausible_pa[1]
            and driver.plausible_c[0] <= temperature <= driver.plausible_c[1])


class SurfaceReference:
    """The absolute pressure at the water surface that depth is measured from.

    ``known`` (a surface found before, e.g. by this node before a restart) wins. Else, with ``zero_at_start``
    the mean of the first ``readings`` fresh pressures becomes the surface, unless it is further than
    ``max_offset_pa`` from ``surface_pa`` (the robot is already under water): then ``surface_pa`` stays and
    :meth:`add` says so. Without ``zero_at_start``: ``surface_pa``."""

    def __init__(self, surface_pa: float, zero_at_start: bool = False, max_offset_pa: float = 3000.0,
                 readings: int = 10, known: Optional[float] = None) -> None:
        if readings < 1:
            raise ValueError("readings must be >= 1")
        self.configured_pa = float(surface_pa)
        self.max_offset_pa = float(max_offset_pa)
        self._wanted = int(readings)
        self._samples: List[float] = []
        self.zeroed = False
        if known is not None and math.isfinite(known):
            self.surface_pa: Optional[float] = float(known)
            self.zeroed = True
        elif zero_at_start:
            self.surface_pa = None
        else:
            self.surface_pa = self.configured_pa

    @property
    def ready(self) -> bool:
        """The surface pressure is known (depth can be computed)."""
        return self.surface_pa is not None

    def add(self, pressure_pa: float) -> Optional[str]:
        """Take a fresh pressure while zeroing; a sentence when zeroing has just ended (taken or refused)."""
        if self.ready:
            return None
        self._samples.append(float(pressure_pa))
        if len(self._samples) < self._wanted:
            return None
        mean = sum(self._samples) / len(self._samples)
        if abs(mean - self.configured_pa) > self.max_offset_pa:
            self.surface_pa = self.configured_pa
            return ("zero at start refused: %.0f Pa is %.0f Pa from depth.surface_pa %.0f Pa (more than %.0f Pa: "
                    "under water?); depth from %.0f Pa" % (mean, mean - self.configured_pa, self.configured_pa,
                                                          self.max_offset_pa, self.configured_pa))
        self.surface_pa = mean
        self.zeroed = True
        return "surface pressure %.0f Pa taken from the first %d readings" % (mean, len(self._samples))


class DepthStep(NamedTuple):
    """What one :meth:`DepthSensorRunner.step` did: ``reading`` (None: no reading this call), whether its
    pressure/temperature and its depth may be published, and a ``problem`` / ``event`` sentence to log."""

    reading: Optional[DepthReading]
    publish_pressure: bool
    publish_depth: bool
    problem: Optional[str]
    event: Optional[str]


class DepthSensorRunner:
    """Start, poll, restart and judge one MS5837 (module docstring). ``clock``: the driver's clock."""

    def __init__(self, driver: Optional[Ms5837], depth: DepthSensorHardware,
                 clock: Callable[[], float] = time.monotonic, retry_period: float = 1.0,
                 restart_after_errors: int = 5, surface: Optional[SurfaceReference] = None) -> None:
        if depth.fitted and driver is None:
            raise ValueError("a fitted depth sensor needs a driver")
        if restart_after_errors < 1 or not retry_period > 0.0:
            raise ValueError("restart_after_errors must be >= 1 and retry_period > 0")
        self.driver = driver
        self.depth = depth
        self._clock = clock
        self.retry_period = float(retry_period)
        self.restart_after_errors = int(restart_after_errors)
        self.surface = surface if surface is not None else SurfaceReference(
            depth.surface_pa, depth.zero_at_start, depth.zero_max_offset_pa)
        self.started_at = clock()
        self.started = False
        self.start_error = ""
        self.prom_failed = False
        self._next_start = -math.inf
        self._bus_errors_in_row = 0
        self.last_fresh: Optional[DepthReading] = None
        self.last_rejected: Optional[DepthReading] = None
        self.counts: Dict[str, int] = {"start_failures": 0, "restarts": 0, "published": 0}

    # --- the loop -----------------------------------------------------------------------------------
    def step(self) -> DepthStep:
        """One call of the node's timer: a start attempt when due, else a poll (never raises for the bus)."""
        if not self.depth.fitted or self.driver is None:
            return DepthStep(None, False, False, None, None)
        if not self.started:
            return self._try_start()
        reading = self.driver.poll()
        if reading is None:
            return DepthStep(None, False, False, None, None)
        if not publishable(reading, self.driver):
            self.last_rejected = reading
            problem = None
            if reading.reason == "bus_error":
                self._bus_errors_in_row += 1
                if self._bus_errors_in_row >= self.restart_after_errors:
                    self.started = False
                    self.counts["restarts"] += 1
                    self.start_error = self.driver.last_error
                    problem = ("%d bus errors in a row (%s): starting the sensor again"
                               % (self._bus_errors_in_row, self.driver.last_error))
            return DepthStep(reading, False, False, problem, None)
        self._bus_errors_in_row = 0
        event = self.surface.add(reading.pressure_pa)
        if self.surface.ready:
            reading = dataclasses.replace(reading, depth_m=depth_m(reading.pressure_pa, self.surface.surface_pa,
                                                                   self.depth.fluid_density, G))
        self.last_fresh = reading
        self.counts["published"] += 1
        return DepthStep(reading, True, self.surface.ready, None, event)

    def _try_start(self) -> DepthStep:
        now = self._clock()
        if now < self._next_start:
            return DepthStep(None, False, False, None, None)
        self._next_start = now + self.retry_period
        assert self.driver is not None
        try:
            calibration = self.driver.start()
        except PromCrcError as error:
            self.counts["start_failures"] += 1
            self.prom_failed = True
            self.start_error = str(error)
            return DepthStep(None, False, False, "PROM refused, retrying: %s" % error, None)
        except OSError as error:
            self.counts["start_failures"] += 1
            self.start_error = "does not answer at 0x%02x: %s" % (self.depth.address, error)
            return DepthStep(None, False, False, "MS5837 %s; retrying every %.0f s" % (self.start_error,
                                                                                       self.retry_period), None)
        self.started, self.prom_failed, self._bus_errors_in_row = True, False, 0
        self.start_error = ""
        return DepthStep(None, False, False, None, "MS5837 (%s) started: PROM CRC 0x%X, version 0x%02X"
                         % (self.depth.model, calibration.crc, calibration.version))

    # --- health -------------------------------------------------------------------------------------
    def health(self, now: float) -> Health:
        """``health/depth`` now (module docstring)."""
        if not self.depth.fitted:
            return Health(OK, "not_fitted", "no depth sensor fitted (hardware.yaml depth.fitted false)",
                          (("fitted", "false"),))
        values = self.values(now)
        if not self.started and self.prom_failed:
            return Health(ERROR, "prom_crc", "MS5837 PROM failed its CRC-4: %s" % self.start_error, values)
        fresh = self.last_fresh
        if fresh is None:
            if self.start_error:
                return Health(ERROR, "no_answer", "MS5837 not running: %s" % self.start_error, values)
            return Health(ERROR, "no_reading", "no fresh depth reading yet", values)
        age = now - fresh.stamp
        if age > self.depth.timeout_s:
            last = self.last_rejected.reason if self.last_rejected is not None else "none"
            why = "; not running: %s" % self.start_error if not self.started and self.start_error else ""
            return Health(ERROR, "stale", "no fresh depth reading for %.1f s (last rejection: %s%s)"
                          % (age, last, why), values)
        rejected = self.last_rejected
        if rejected is not None and now - rejected.stamp <= self.depth.warn_window_s:
            return Health(WARN, "dropped", "a reading was dropped %.1f s ago (%s)" % (now - rejected.stamp,
                                                                                   rejected.reason), values)
        if not self.surface.ready:
            return Health(OK, "", "fresh readings, %.0f Pa; finding the surface pressure" % fresh.pressure_pa,
                          values)
        return Health(OK, "", "fresh readings, depth %.2f m" % fresh.depth_m, values)

    def values(self, now: float) -> Tuple[Tuple[str, str], ...]:
        """Key/value strings of the last readings and the counters (health and diagnostics)."""
        fresh = self.last_fresh
        items = [("model", self.depth.model), ("started", str(self.started))]
        if fresh is not None:
            items += [("depth [m]", "%.3f" % fresh.depth_m), ("pressure [Pa]", "%.0f" % fresh.pressure_pa),
                      ("temperature [degC]", "%.2f" % fresh.temperature_c),
                      ("age of last fresh reading [s]", "%.3f" % (now - fresh.stamp))]
        if self.surface.surface_pa is not None:
            items.append(("surface [Pa]", "%.0f" % self.surface.surface_pa))
        if self.last_rejected is not None:
            items.append(("last rejection", self.last_rejected.reason))
        counters = self.driver.counters() if self.driver is not None else {}
        items += [(name, str(count)) for name, count in sorted(counters.items())]
        items += [(name, str(count)) for name, count in sorted(self.counts.items())]
        return tuple(items)


__all__ = ["DepthSensorRunner", "DepthStep", "G", "SurfaceReference", "UNMEASURED_VARIANCE", "depth_variance",
           "make_driver", "poll_period", "pose_covariance", "publishable"]
