"""Depth sensor driver core: MS5837-30BA (Bar30) / MS5837-02BA (Bar02) on I2C, no ROS.

The enclosure is Blue Robotics'; its depth sensors are the MS5837 family at address 0x76. The datasheet
maths (commands, CRC-4, first- and second-order compensation) live in :mod:`quadruped_drivers.ms5837_datasheet`
and are re-exported here.

:class:`Ms5837` talks to any bus object (fake, bridged or real; ``quadruped_drivers.i2c``), each bus access
under :func:`~quadruped_drivers.i2c.bus_locked` (bounded wait, always unlocked):

* :meth:`Ms5837.start`: reset, wait, read the 7 PROM words, check the CRC-4 (:class:`PromCrcError` names the
  computed and the read CRC);
* :meth:`Ms5837.poll`: non-blocking two-phase state machine for a periodic loop: start D1, come back after
  the conversion time to read it and start D2, come back to read D2 and produce a reading (and start the
  next D1). Returns ``None`` while a conversion is under way. Each call is at most two short transactions;
* :meth:`Ms5837.read`: both conversions in one call, waiting with the injectable ``sleep``.

Nothing wrong is reported fresh (:class:`DepthReading.fresh` False, ``reason`` says why, a counter counts it):
a bus error or lock timeout (``bus_error``), an ADC result of 0 (conversion not finished: ``adc_not_ready``),
a pressure outside the model's plausible range or a temperature outside -20..85 degC (``implausible_pressure``,
``implausible_temperature``), the same raw (D1, D2) pair ``stuck_readings`` times in a row (``stuck_adc``: a
real sensor's codes carry a few counts of noise), and a depth change faster than ``max_depth_rate`` (m/s) x
the time since the last good reading + ``rate_margin_m`` (``rate``), until ``rate_confirm_readings``
consecutive readings agree with each other within the same bound (then the new depth is taken,
``jumps_accepted``) -- the servo feedback's jump check.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional, Tuple

from quadruped_drivers.i2c import DEFAULT_LOCK_TIMEOUT, bus_locked
from quadruped_drivers.ms5837_datasheet import (ADC_MAX, ADDRESS, CMD_ADC_READ, CMD_PROM_READ, CMD_RESET,
                                                CONVERSION_TIME_MAX, OSR_OFFSET, PROM_WORDS,
                                                RATED_TEMPERATURE_C, RESET_WAIT, SPECS, TYPICAL_PROM, Calibration,
                                                Compensation, Model, ModelSpec, PromCrcError, compensate,
                                                compensation, crc4, depth_m, osr_commands, raw_codes, with_crc)

#: Reasons a reading is not fresh (each has a counter of the same name).
REASONS = ("bus_error", "adc_not_ready", "implausible_pressure", "implausible_temperature", "stuck_adc", "rate")

_IDLE, _D1, _D2 = "idle", "d1", "d2"
#: Rounding slack when comparing clock differences with the conversion time (s).
_CLOCK_SLACK = 1e-7


@dataclass(frozen=True)
class DepthReading:
    """One pressure/temperature sample. ``fresh`` False: do not publish it (``reason`` says why); the
    values are then those decoded (NaN if nothing was decoded), kept for diagnostics."""

    stamp: float
    pressure_pa: float
    temperature_c: float
    depth_m: float
    fresh: bool
    reason: str = ""
    d1: int = 0
    d2: int = 0


def _stale(stamp: float, reason: str, d1: int = 0, d2: int = 0) -> DepthReading:
    return DepthReading(stamp, math.nan, math.nan, math.nan, False, reason, d1, d2)


class Ms5837:
    """MS5837 driver on a bus object (module docstring). One thread owns the instance.

    ``surface_pa``/``density``/``g`` turn pressure into depth (:func:`depth_m`); ``plausible_pa`` defaults to
    the model's rated range with a margin (:data:`SPECS`), ``plausible_c`` to the rated -20..85 degC.
    ``max_depth_rate`` None disables the rate check.
    """

    def __init__(self, bus: Any, model: Model = Model.BA30, address: int = ADDRESS, osr: int = 4096,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 lock_timeout: float = DEFAULT_LOCK_TIMEOUT, surface_pa: float = 101325.0, density: float = 997.0,
                 g: float = 9.80665, second_order: bool = True, max_depth_rate: Optional[float] = 2.0,
                 rate_margin_m: float = 0.05, rate_confirm_readings: int = 3, stuck_readings: int = 3,
                 plausible_pa: Optional[Tuple[float, float]] = None,
                 plausible_c: Tuple[float, float] = RATED_TEMPERATURE_C) -> None:
        if not isinstance(model, Model):
            raise ValueError("model must be a Model, got %r" % (model,))
        self._cmd_d1, self._cmd_d2, self._conversion_time = osr_commands(osr)
        if max_depth_rate is not None and not (math.isfinite(max_depth_rate) and max_depth_rate > 0.0):
            raise ValueError("max_depth_rate must be a positive number of m/s or None, got %r" % (max_depth_rate,))
        if rate_confirm_readings < 1 or stuck_readings < 2:
            raise ValueError("rate_confirm_readings must be >= 1 and stuck_readings >= 2")
        depth_m(surface_pa, surface_pa, density, g)  # validates them
        self.bus = bus
        self.model = model
        self.address = address
        self.osr = osr
        self._clock = clock
        self._sleep = sleep
        self._lock_timeout = lock_timeout
        self._surface_pa, self._density, self._g = float(surface_pa), float(density), float(g)
        self._second_order = second_order
        self._max_rate = max_depth_rate
        self._rate_margin = float(rate_margin_m)
        self._confirm = int(rate_confirm_readings)
        self._stuck_limit = int(stuck_readings)
        self.plausible_pa = tuple(plausible_pa) if plausible_pa is not None else SPECS[model].plausible_pa
        self.plausible_c = tuple(plausible_c)
        self.calibration: Optional[Calibration] = None
        self._state = _IDLE
        self._started_at = -math.inf
        self._d1 = 0
        self._last_good_depth = math.nan
        self._last_good_time = -math.inf
        self._jump_run = 0
        self._jump_depth = math.nan
        self._jump_time = -math.inf
        self._last_codes: Tuple[int, int] = (-1, -1)
        self._same_codes = 0
        self.counts: Dict[str, int] = {name: 0 for name in ("starts", "crc_failures", "readings", "fresh",
                                                             "jumps_accepted") + REASONS}
        self.last_error = ""

    # --- properties --------------------------------------------------------------------------------
    @property
    def conversion_time(self) -> float:
        """Maximum conversion time of the configured OSR (s): the driver waits at least this long."""
        return self._conversion_time

    def counters(self) -> Dict[str, int]:
        """Diagnostics counters (copy)."""
        return dict(self.counts)

    # --- bus primitives ----------------------------------------------------------------------------
    def _command(self, command: int) -> None:
        self.bus.writeto(self.address, bytes([command]))

    def _read_bytes(self, command: int, count: int) -> bytes:
        self.bus.writeto(self.address, bytes([command]))
        buffer = bytearray(count)
        self.bus.readfrom_into(self.address, buffer)
        return bytes(buffer)

    # --- start -------------------------------------------------------------------------------------
    def start(self) -> Calibration:
        """Reset, wait, read the PROM and check its CRC-4. Raises ``OSError`` (bus) or :class:`PromCrcError`."""
        self.counts["starts"] += 1
        self.calibration = None
        self._state = _IDLE
        with bus_locked(self.bus, self._lock_timeout, self._clock):
            self._command(CMD_RESET)
        self._sleep(RESET_WAIT)
        words = []
        with bus_locked(self.bus, self._lock_timeout, self._clock):
            for index in range(PROM_WORDS):
                data = self._read_bytes(CMD_PROM_READ + 2 * index, 2)
                words.append((data[0] << 8) | data[1])
        try:
            self.calibration = Calibration.from_prom(words)
        except PromCrcError as error:
            self.counts["crc_failures"] += 1
            self.last_error = str(error)
            raise
        return self.calibration

    # --- conversions -------------------------------------------------------------------------------
    def _require_started(self) -> Calibration:
        if self.calibration is None:
            raise RuntimeError("Ms5837: start() has not succeeded")
        return self.calibration

    def _read_adc(self) -> int:
        data = self._read_bytes(CMD_ADC_READ, 3)
        return (data[0] << 16) | (data[1] << 8) | data[2]

    def poll(self) -> Optional[DepthReading]:
        """Advance the conversion state machine without waiting; a reading when D2 was read, else None
        (a stale reading right away on a bus error or an unfinished conversion)."""
        self._require_started()
        now = self._clock()
        if self._state != _IDLE and now - self._started_at < self._conversion_time - _CLOCK_SLACK:
            return None
        try:
            with bus_locked(self.bus, self._lock_timeout, self._clock):
                if self._state == _IDLE:
                    self._command(self._cmd_d1)
                    self._state, self._started_at = _D1, self._clock()
                    return None
                code = self._read_adc()
                if code == 0:
                    self._state = _IDLE
                    return self._reject(now, "adc_not_ready")
                if self._state == _D1:
                    self._d1 = code
                    self._command(self._cmd_d2)
                    self._state, self._started_at = _D2, self._clock()
                    return None
                d1, d2 = self._d1, code
                self._command(self._cmd_d1)  # the next cycle's pressure conversion runs meanwhile
                self._state, self._started_at = _D1, self._clock()
        except OSError as error:
            self._state = _IDLE  # the chip's conversion state is unknown: start over
            self.last_error = str(error)
            return self._reject(now, "bus_error")
        return self._evaluate(now, d1, d2)

    def read(self) -> DepthReading:
        """A D1 and a D2 conversion with the waits in between (blocking, ``sleep``); always a reading."""
        self._require_started()
        for _ in range(4):  # idle -> D1 started -> D2 started -> reading: three polls (one spare)
            if self._state != _IDLE:
                self._sleep(max(0.0, self._conversion_time - (self._clock() - self._started_at)))
            reading = self.poll()
            if reading is not None:
                return reading
        return self._reject(self._clock(), "adc_not_ready")  # ``sleep`` did not let the conversion time pass

    # --- checks ------------------------------------------------------------------------------------
    def _reject(self, now: float, reason: str, d1: int = 0, d2: int = 0,
                values: Optional[Tuple[float, float, float]] = None) -> DepthReading:
        self.counts["readings"] += 1
        self.counts[reason] += 1
        if values is None:
            return _stale(now, reason, d1, d2)
        return DepthReading(now, values[0], values[1], values[2], False, reason, d1, d2)

    def _within_reach(self, depth: float, reference: float, since: float) -> bool:
        return abs(depth - reference) <= self._max_rate * since + self._rate_margin  # type: ignore[operator]

    def _evaluate(self, now: float, d1: int, d2: int) -> DepthReading:
        calibration = self._require_started()
        pressure, temperature = compensate(d1, d2, calibration, self.model, self._second_order)
        depth = depth_m(pressure, self._surface_pa, self._density, self._g)
        values = (pressure, temperature, depth)
        if (d1, d2) == self._last_codes:
            self._same_codes += 1
        else:
            self._last_codes, self._same_codes = (d1, d2), 1
        if not (math.isfinite(pressure) and self.plausible_pa[0] <= pressure <= self.plausible_pa[1]):
            return self._reject(now, "implausible_pressure", d1, d2, values)
        if not (math.isfinite(temperature) and self.plausible_c[0] <= temperature <= self.plausible_c[1]):
            return self._reject(now, "implausible_temperature", d1, d2, values)
        if self._same_codes >= self._stuck_limit:
            return self._reject(now, "stuck_adc", d1, d2, values)
        if self._max_rate is not None and math.isfinite(self._last_good_depth) and not self._within_reach(
                depth, self._last_good_depth, now - self._last_good_time):
            if self._jump_run > 0 and self._within_reach(depth, self._jump_depth, now - self._jump_time):
                self._jump_run += 1
            else:
                self._jump_run = 1
            self._jump_depth, self._jump_time = depth, now
            if self._jump_run < self._confirm:
                return self._reject(now, "rate", d1, d2, values)
            self.counts["jumps_accepted"] += 1
        self._jump_run = 0
        self._last_good_depth, self._last_good_time = depth, now
        self.counts["readings"] += 1
        self.counts["fresh"] += 1
        return DepthReading(now, pressure, temperature, depth, True, "", d1, d2)


__all__ = ["ADC_MAX", "ADDRESS", "CONVERSION_TIME_MAX", "Calibration", "Compensation", "DepthReading", "Model",
           "ModelSpec", "Ms5837", "OSR_OFFSET", "PromCrcError", "REASONS", "SPECS", "TYPICAL_PROM", "compensate",
           "compensation", "crc4", "depth_m", "osr_commands", "raw_codes", "with_crc"]
