"""LiPo packs read through a resistor divider on a spare ADS1115 input: voltage, charge and level, no ROS.

``servo_feedback_node`` reads each fitted pack's input between its joint reads
(:class:`~quadruped_drivers.servo_feedback.ServoFeedbackArray` ``spare_inputs``) and feeds the volts at the ADC
to :meth:`BatteryMonitor.update`; it publishes each :class:`PackStatus` as ``battery/<pack>`` and
:meth:`BatteryMonitor.health` as ``health/battery``.

Per pack: voltage = ADC volts x ``divider_ratio``, mean cell voltage = voltage / ``cells``, charge from
:data:`LIPO_CURVE` (a resting LiPo's; under load the cell voltage sags and the charge reads low). Its level:

* ERROR ``absent``: below :data:`ABSENT_CELL_V` per cell (pack unplugged, divider not wired);
* ERROR ``implausible``: the ADC saturated or above :data:`~quadruped_drivers.hardware_config.LIPO_MAX_CELL_V`
  per cell (wrong cell count or divider);
* ERROR ``critical`` below ``critical_cell_v``, WARN ``low`` below ``warn_cell_v``, else OK. A worse level is
  taken after ``batteries.confirm_readings`` readings in a row below its threshold; a level is left only once a
  reading is ``hysteresis_v`` above its threshold (a voltage hovering at a threshold does not flicker);
* ERROR ``stale``: no reading for ``batteries.stale_after_s`` (``no_reading`` before the first).

``health/battery`` is the worst fitted pack's level; OK ``not_fitted`` when no pack is fitted.
"""
from __future__ import annotations

import bisect
import math
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple

from quadruped_common.health import ERROR, LEVEL_NAMES, OK, WARN, Health
from quadruped_drivers.hardware_config import LIPO_MAX_CELL_V, BatteryHardware, BatteryPackHardware

#: Resting LiPo cell voltage (V) -> state of charge (fraction), piecewise linear. [estimate] The curve most
#: hobby chargers and flight controllers use; a given pack differs by a few percent, and under load the
#: voltage sags 0.1..0.3 V, so the charge reads low while the servos work.
LIPO_CURVE: Tuple[Tuple[float, float], ...] = (
    (3.27, 0.00), (3.61, 0.05), (3.69, 0.10), (3.71, 0.15), (3.73, 0.20), (3.75, 0.25), (3.77, 0.30),
    (3.79, 0.35), (3.80, 0.40), (3.82, 0.45), (3.84, 0.50), (3.85, 0.55), (3.87, 0.60), (3.91, 0.65),
    (3.95, 0.70), (3.98, 0.75), (4.02, 0.80), (4.08, 0.85), (4.11, 0.90), (4.15, 0.95), (4.20, 1.00))
_VOLTS = [volts for volts, _ in LIPO_CURVE]
_CHARGES = [charge for _, charge in LIPO_CURVE]
#: Below this mean cell voltage no pack is connected (a LiPo is ruined long before 1 V).
ABSENT_CELL_V = 1.0
#: ADS1115 conversion codes at or above this are saturated (the input is at or beyond the full scale).
ADS1115_SATURATED = 32767


def _interpolate(x: float, xs: Sequence[float], ys: Sequence[float]) -> float:
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    i = bisect.bisect_right(xs, x)
    return ys[i - 1] + (ys[i] - ys[i - 1]) * (x - xs[i - 1]) / (xs[i] - xs[i - 1])


def lipo_charge(cell_v: float) -> float:
    """State of charge (0..1) of a resting LiPo cell at ``cell_v`` volts (:data:`LIPO_CURVE`); NaN if not finite."""
    if not math.isfinite(cell_v):
        return math.nan
    return _interpolate(cell_v, _VOLTS, _CHARGES)


def lipo_open_circuit_voltage(charge: float) -> float:
    """Resting cell voltage (V) at state of charge ``charge`` (0..1, clamped): the inverse of :func:`lipo_charge`."""
    if not math.isfinite(charge):
        raise ValueError("charge must be finite, got %r" % (charge,))
    return _interpolate(charge, _CHARGES, _VOLTS)


class PackStatus(NamedTuple):
    """One pack reading: ``voltage`` (V, the pack's), ``cell_voltage`` (V, the mean), ``charge`` (0..1, NaN when
    not present or implausible), ``present``, ``level`` and ``reason`` after this reading."""

    name: str
    stamp: float
    voltage: float
    cell_voltage: float
    charge: float
    present: bool
    level: int
    reason: str


class PackMonitor:
    """One fitted pack's readings and level (module docstring). ``full_scale_v``: the ADC's range (adc.full_scale_v)."""

    def __init__(self, pack: BatteryPackHardware, full_scale_v: float, confirm_readings: int = 2,
                 stale_after: float = 2.0) -> None:
        if confirm_readings < 1:
            raise ValueError("confirm_readings must be >= 1")
        self.pack = pack
        self.saturated_v = full_scale_v * ADS1115_SATURATED / 32768.0
        self.confirm_readings = int(confirm_readings)
        self.stale_after = float(stale_after)
        self.level = ERROR
        self.reason = "no_reading"  # the first reading sets the level at once
        self.last: Optional[PackStatus] = None
        self._worse_run: List[Tuple[int, str]] = []
        self.counts: Dict[str, int] = {"readings": 0, "read_errors": 0, "absent": 0, "implausible": 0}

    def _proposed(self, cell_v: float) -> Tuple[int, str]:
        """The level this cell voltage asks for, with the hysteresis of the current level."""
        pack = self.pack
        release = pack.hysteresis_v if self.reason in ("critical", "low", "") else 0.0
        if cell_v < pack.critical_cell_v or (self.reason == "critical" and cell_v < pack.critical_cell_v + release):
            return ERROR, "critical"
        if cell_v < pack.warn_cell_v or (self.level >= WARN and self.reason in ("critical", "low")
                                         and cell_v < pack.warn_cell_v + release):
            return WARN, "low"
        return OK, ""

    def update(self, stamp: float, adc_volts: Optional[float]) -> Optional[PackStatus]:
        """Take one reading (``adc_volts`` None or NaN: the read failed, counted, nothing returned)."""
        if adc_volts is None or not math.isfinite(adc_volts):
            self.counts["read_errors"] += 1
            return None
        self.counts["readings"] += 1
        voltage = float(adc_volts) * self.pack.divider_ratio
        cell = voltage / self.pack.cells
        charge = math.nan
        present = True
        if adc_volts >= self.saturated_v or cell > LIPO_MAX_CELL_V:
            self.counts["implausible"] += 1
            level, reason = ERROR, "implausible"
        elif cell < ABSENT_CELL_V:
            self.counts["absent"] += 1
            level, reason, present = ERROR, "absent", False
        else:
            charge = lipo_charge(cell)
            level, reason = self._proposed(cell)
        if reason in ("implausible", "absent") or self.reason in ("implausible", "absent", "no_reading"):
            self._worse_run = []
            self.level, self.reason = level, reason  # a wiring fault, or the first good reading: at once
        elif level > self.level:
            self._worse_run.append((level, reason))
            if len(self._worse_run) >= self.confirm_readings:
                self.level, self.reason = min(self._worse_run)
                self._worse_run = []
        else:
            self._worse_run = []
            self.level, self.reason = level, reason
        self.last = PackStatus(self.pack.name, stamp, voltage, cell, charge, present, self.level, self.reason)
        return self.last

    def status(self, now: float) -> Tuple[int, str, str]:
        """(level, reason, sentence) now: the last reading's level, or ERROR when it is stale."""
        name = self.pack.name
        last = self.last
        if last is None:
            return ERROR, "no_reading", "%s: no reading yet" % name
        age = now - last.stamp
        if age > self.stale_after:
            return ERROR, "stale", "%s: no reading for %.1f s" % (name, age)
        if self.reason == "absent":
            return ERROR, "absent", "%s: %.2f V, no pack (unplugged, or the divider not wired)" % (name, last.voltage)
        if self.reason == "implausible":
            return ERROR, "implausible", ("%s: %.2f V is beyond a %dS LiPo or the ADC's range (cells or "
                                          "divider_ratio wrong?)" % (name, last.voltage, self.pack.cells))
        words = {"critical": "below critical %.2f V/cell" % self.pack.critical_cell_v,
                 "low": "below warn %.2f V/cell" % self.pack.warn_cell_v}.get(self.reason, "OK")
        return self.level, self.reason, "%s: %.2f V (%.2f V/cell, %.0f %%) %s" % (
            name, last.voltage, last.cell_voltage, 100.0 * last.charge, words)


class BatteryMonitor:
    """Every fitted pack of ``batteries`` (hardware.yaml ``batteries``) and ``health/battery``."""

    def __init__(self, batteries: BatteryHardware, full_scale_v: float) -> None:
        self.packs: Dict[str, PackMonitor] = {
            pack.name: PackMonitor(pack, full_scale_v, batteries.confirm_readings, batteries.stale_after_s)
            for pack in batteries.fitted}

    def update(self, name: str, stamp: float, adc_volts: Optional[float]) -> Optional[PackStatus]:
        """One reading of pack ``name`` (:meth:`PackMonitor.update`)."""
        return self.packs[name].update(stamp, adc_volts)

    def health(self, now: float) -> Health:
        """``health/battery``: the worst fitted pack's level, every pack's sentence."""
        if not self.packs:
            return Health(OK, "not_fitted", "no battery pack fitted (hardware.yaml batteries.packs.*.fitted)",
                          (("fitted", "none"),))
        statuses = [(name,) + monitor.status(now) for name, monitor in self.packs.items()]
        level = max(status[1] for status in statuses)
        reason = ",".join("%s:%s" % (name, why) for name, lvl, why, _ in statuses if lvl == level and lvl != OK)
        values: List[Tuple[str, str]] = []
        for name, monitor in self.packs.items():
            last = monitor.last
            values.append(("%s level" % name, LEVEL_NAMES[monitor.status(now)[0]]))
            if last is not None:
                values += [("%s voltage [V]" % name, "%.3f" % last.voltage),
                           ("%s cell voltage [V]" % name, "%.3f" % last.cell_voltage),
                           ("%s age [s]" % name, "%.2f" % (now - last.stamp))]
            values += [("%s %s" % (name, key), str(count)) for key, count in sorted(monitor.counts.items())]
        return Health(level, reason, "; ".join(status[3] for status in statuses), tuple(values))


__all__ = ["ABSENT_CELL_V", "ADS1115_SATURATED", "BatteryMonitor", "LIPO_CURVE", "PackMonitor", "PackStatus",
           "lipo_charge", "lipo_open_circuit_voltage"]
