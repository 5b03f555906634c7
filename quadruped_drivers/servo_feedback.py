"""Servo position feedback: twelve ADS1115 behind a TCA9548A, read once per 100 Hz control cycle.

The paper's control node (section "Electronics and software") reads the analog feedback of all twelve
servos through twelve ADS1115 ADCs every 10 ms; the joint angles feed the joint-velocity filtering
and the leg torque estimate of eq. (torque_leg). Layout: four ADC addresses (0x48..0x4B) per mux
channel, three mux channels (``config/hardware.yaml``).

Bus traffic per cycle is kept minimal: each ADC is configured once (continuous conversion on its own
input at 860 SPS, address pointer left on the conversion register), so a cycle reads only the 2-byte
conversion registers (one plain read transaction each), and the mux control register is written only
when the channel changes (a cycle starts on the channel still selected from the previous one).

Why not adafruit-circuitpython-ads1x15 3.0 / -tca9548a 0.7 (``docs/hardware_libraries.md``):

* ads1x15 3.0 in continuous mode ignores a change of the requested channel once it has read a pin
  and its "fast" read path reads without setting the pointer, so after a config access (mode switch,
  its own ``_write_config`` reads the config register) it returns the config register as data. Its
  constructor writes the config register several times (once per property), single-shot reads
  busy-wait without timeout, and twelve single-shot reads at 860 SPS take longer than a 10 ms cycle.
* tca9548a 0.7 writes select + deselect around every transaction (2 extra transactions per read),
  and its channel ``try_lock``/``unlock`` leave the parent bus locked forever when the select or the
  deselect write fails. Here the bus lock is always released in ``finally`` and a failed mux write only
  invalidates the cached channel.
* ``adafruit_bus_device.I2CDevice`` locks per transaction and spins on ``try_lock`` without bound;
  a cycle must hold the bus across mux select + reads, with a bounded wait (:func:`bus_locked`).

Wrong data is never reported fresh:

* every mux switch is read back (one 1-byte read): a control write that was ACKed but not applied
  would otherwise make four joints report another channel's ADCs; the channel's joints go stale and
  ``mux_mismatches`` counts it;
* one ADC per cycle, in turn, has its config register read back (one write-read of the config
  register, the conversion then read with its pointer byte: 67 bits more than a plain read): an
  ADS1115 that browned out without a NACK is back in single-shot mode at its defaults, reading a
  stale 0 V; it is found within 12 cycles, counted in ``config_losses`` and configured again (a joint
  whose code is implausible is checked first, on the next cycle);
* a code whose angle lies outside the joint's calibrated range (its pulse limits mapped through the
  servo calibration) by more than ``adc.plausible_margin_deg`` is stale (``implausible_counts``).

Spare inputs (``spare_inputs``: the battery dividers of ``config/hardware.yaml``) are read on a joint's ADC
between its joint reads, one every ``spare_period / len(spare_inputs)`` seconds, in turn. The ADC is *lent*:
in the cycle that reads its joint, its config is switched to the spare input (continuous mode, same range and
rate); at least two conversion periods later (the conversion under way when the config was written finishes
on the old input first; 2.3 ms at 860 SPS, so the next 10 ms cycle) the conversion register holds the spare
input, is read after its config register is read back (a switch that did not take is a failed read, never
the joint's voltage taken for the spare input's; :meth:`ServoFeedbackArray.take_spare_samples`) and the joint's
config is written back. That
cycle the joint has no sample of its own: it is listed in ``FeedbackReading.lent`` (not stale) and its
``held_angles`` entry is its previous angle, one cycle old. A rotating config check never runs on a lent ADC.
"""
from __future__ import annotations

import errno
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Sequence, Set, Tuple

import numpy as np

from quadruped_drivers.hardware_config import ADS1115_FSR_PGA, ADS1115_RATES, HardwareConfig
from quadruped_drivers.i2c import bus_locked

ADS_REG_CONVERSION = 0x00
ADS_REG_CONFIG = 0x01


def plausible_angle_range(hardware_config: HardwareConfig, calibration: Any) -> Tuple[np.ndarray, np.ndarray]:
    """(low, high) joint angles (rad) a working servo's feedback can show: the angles of its pulse
    limits through the calibration, widened by ``adc.plausible_margin_deg`` on both sides."""
    ends = np.stack([calibration.pulses_to_angles(hardware_config.min_us),
                     calibration.pulses_to_angles(hardware_config.max_us)])
    margin = math.radians(hardware_config.adc_plausible_margin_deg)
    return ends.min(axis=0) - margin, ends.max(axis=0) + margin


def ads1115_continuous_config(adc_input: int, full_scale_v: float, data_rate: int) -> int:
    """ADS1115 config word: single-ended AIN``adc_input`` vs GND (MUX 1xx), PGA for ``full_scale_v``,
    MODE 0 (continuous), DR for ``data_rate``, comparator disabled (COMP_QUE 11)."""
    if not 0 <= adc_input <= 3:
        raise ValueError("ADS1115 input must be 0..3, got %r" % (adc_input,))
    return ((0x4 | adc_input) << 12) | (ADS1115_FSR_PGA[full_scale_v] << 9) | (ADS1115_RATES[data_rate] << 5) | 0x0003


@dataclass(frozen=True)
class SpareInput:
    """An extra single-ended input read on one of the joints' ADS1115s (a battery divider): ``name`` and where."""

    name: str
    mux_channel: int
    adc_address: int
    adc_input: int


class SpareSample(NamedTuple):
    """One spare-input reading: ``volts`` at the ADC input (NaN: the read failed) at ``stamp``."""

    name: str
    stamp: float
    volts: float


@dataclass
class FeedbackReading:
    """One cycle's feedback (arrays in JOINT_NAMES order).

    ``volts``/``angles``: this cycle's samples, NaN where no fresh sample was read (``valid`` False).
    ``held_angles``: the freshest good angle no older than ``stale_after`` (NaN beyond): a single
    dropped sample does not blank the joint for a consumer that tolerates ``stale_after`` of latency.
    ``stale``: joints without a fresh sample whose last good one is at most ``failed_after`` old;
    ``failed``: joints without a good sample for longer than ``failed_after`` (or never, once
    ``failed_after`` has passed since :meth:`ServoFeedbackArray.start`). ``age``: seconds since each
    joint's last good sample (inf if none). ``error_counts``: cumulative failed ADC transactions per
    joint; ``mux_errors``: cumulative failed or unverified mux switches. ``implausible``: joints whose
    code was read this cycle but lies outside their plausible range, or further from their last good
    angle than the servo can move (``volts`` holds it, ``angles`` is NaN, ``valid`` False). ``lent``: joints
    whose ADC read a spare input this cycle (module docstring): no sample of their own, not stale, their
    ``held_angles`` entry one cycle old.
    """

    stamp: float
    volts: np.ndarray
    angles: np.ndarray
    valid: np.ndarray
    stale: List[int]
    failed: List[int]
    error_counts: np.ndarray
    mux_errors: int
    implausible: List[int] = field(default_factory=list)
    held_angles: np.ndarray = field(default_factory=lambda: np.full(12, np.nan))
    age: np.ndarray = field(default_factory=lambda: np.full(12, np.inf))
    lent: List[int] = field(default_factory=list)


class ServoFeedbackArray:
    """Reads the twelve servo feedback voltages and converts them to joint angles.

    ``bus`` is any bus object (fake, bridged or real), ``calibration`` a
    :class:`~quadruped_drivers.calibration.ServoCalibration` (volts -> angle), ``clock`` the time source
    (inject one in tests). One thread owns the instance.

    ``max_joint_speed`` (rad/s; the servos' no-load speed, ``quadruped_common.robot.load_servo_no_load_speed``)
    turns on the physical-rate check: a reading further from the joint's last good angle than
    ``max_joint_speed`` x the time since it + ``adc.jump_margin_deg`` is implausible (stale, counted in
    ``jump_counts``, its ADC config checked next) until ``adc.jump_confirm_readings`` consecutive readings
    agree with each other within the same bound; then the new angle is taken (``jumps_accepted``). None:
    no rate check (a calibration sweep, tests that set voltages freely).

    ``spare_inputs`` are read on the joints' ADCs in turn, each every ``spare_period`` seconds (module docstring).
    """

    def __init__(self, bus: Any, hardware_config: HardwareConfig, calibration: Any,
                 clock: Callable[[], float] = time.monotonic, max_joint_speed: Optional[float] = None,
                 spare_inputs: Sequence[SpareInput] = (), spare_period: float = 0.5) -> None:
        if max_joint_speed is not None and not (math.isfinite(max_joint_speed) and max_joint_speed > 0.0):
            raise ValueError("max_joint_speed must be a positive number of rad/s, got %r" % (max_joint_speed,))
        if not (math.isfinite(spare_period) and spare_period > 0.0):
            raise ValueError("spare_period must be a positive number of seconds, got %r" % (spare_period,))
        self._bus = bus
        self._config = hardware_config
        self._calibration = calibration
        self._clock = clock
        self._count = len(hardware_config.joints)
        # ADC devices: (mux channel, address) -> joint indices on it; each joint has its own input.
        self._configs = {joint.index: ads1115_continuous_config(joint.adc_input, hardware_config.adc_full_scale_v,
                                                                hardware_config.adc_data_rate)
                         for joint in hardware_config.joints}
        self._channels: Dict[int, List[int]] = {}
        for joint in hardware_config.joints:
            self._channels.setdefault(joint.mux_channel, []).append(joint.index)
        # Cached mux state: the selected channel, -1 = known deselected, None = unknown (after an error).
        self._selected: Optional[int] = None
        self._configured = np.zeros(self._count, dtype=bool)
        self._last_good = np.full(self._count, -np.inf)
        self._last_angle = np.full(self._count, np.nan)
        self._error_counts = np.zeros(self._count, dtype=int)
        self._low, self._high = plausible_angle_range(hardware_config, calibration)
        self._implausible_counts = np.zeros(self._count, dtype=int)
        self._max_speed = max_joint_speed
        self._jump_margin = math.radians(hardware_config.adc_jump_margin_deg)
        self._jump_counts = np.zeros(self._count, dtype=int)
        self._jumps_accepted = np.zeros(self._count, dtype=int)
        # The run of disagreeing readings of each joint: its latest angle and time, and its length.
        self._jump_angle = np.full(self._count, np.nan)
        self._jump_time = np.full(self._count, -np.inf)
        self._jump_run = np.zeros(self._count, dtype=int)
        self._config_losses = np.zeros(self._count, dtype=int)
        self._next_check = 0  # the joint whose ADC config is read back next (rotating)
        self._suspects: Set[int] = set()  # joints to check first (implausible code last cycle)
        self._mux_mismatches = 0
        self._mux_errors = 0
        self._lock_timeouts = 0
        self._started_at: Optional[float] = None
        self._buffer = bytearray(2)
        self._mux_buffer = bytearray(1)
        # Spare inputs: (input, index of the joint whose ADC reads it, its config word).
        hosts = {(joint.mux_channel, joint.adc_address): joint for joint in hardware_config.joints}
        self._spares: List[Tuple[SpareInput, int, int]] = []
        for spare in spare_inputs:
            joint = hosts.get((spare.mux_channel, spare.adc_address))
            if joint is None or joint.adc_input == spare.adc_input:
                raise ValueError("spare input %s: no joint's ADS1115 at 0x%02x on mux channel %d with input %d free"
                                 % (spare.name, spare.adc_address, spare.mux_channel, spare.adc_input))
            self._spares.append((spare, joint.index, ads1115_continuous_config(
                spare.adc_input, hardware_config.adc_full_scale_v, hardware_config.adc_data_rate)))
        self._spare_interval = spare_period / max(1, len(self._spares))
        # Two conversion periods and a margin between switching an ADC to a spare input and reading it.
        self._spare_settle = 2.0 / hardware_config.adc_data_rate + 0.0005
        self._spare_turn = 0  # the spare read next
        self._spare_due = -math.inf
        self._spare_active: Optional[int] = None  # the spare whose conversion is under way
        self._spare_switched = -math.inf
        self._spare_samples: List[SpareSample] = []
        self._spare_errors: Dict[str, int] = {spare.name: 0 for spare, _, _ in self._spares}
        self._lent = np.zeros(self._count, dtype=bool)

    # --- properties -------------------------------------------------------------------------
    @property
    def mux_errors(self) -> int:
        """Cumulative failed mux control writes."""
        return self._mux_errors

    @property
    def mux_mismatches(self) -> int:
        """Mux switches that were ACKed but read back another channel (also in ``mux_errors``)."""
        return self._mux_mismatches

    @property
    def implausible_counts(self) -> np.ndarray:
        """Codes outside each joint's plausible range, cumulative (copy)."""
        return self._implausible_counts.copy()

    @property
    def jump_counts(self) -> np.ndarray:
        """Readings further from the last good angle than the servo can move, cumulative (copy)."""
        return self._jump_counts.copy()

    @property
    def jumps_accepted(self) -> np.ndarray:
        """Jumps taken as the new angle after ``adc.jump_confirm_readings`` agreeing readings (copy)."""
        return self._jumps_accepted.copy()

    @property
    def config_losses(self) -> np.ndarray:
        """ADCs found with a config register other than the one written (brown-out), per joint (copy)."""
        return self._config_losses.copy()

    @property
    def plausible_range(self) -> Tuple[np.ndarray, np.ndarray]:
        """(low, high) plausible joint angles in rad (copies)."""
        return self._low.copy(), self._high.copy()

    @property
    def lock_timeouts(self) -> int:
        """Cycles skipped because the bus stayed locked by another user."""
        return self._lock_timeouts

    @property
    def error_counts(self) -> np.ndarray:
        """Cumulative failed ADC transactions per joint (copy)."""
        return self._error_counts.copy()

    @property
    def configured(self) -> np.ndarray:
        """Which joints' ADCs are currently known to be configured (copy)."""
        return self._configured.copy()

    @property
    def spare_errors(self) -> Dict[str, int]:
        """Failed spare-input reads per spare input, cumulative (copy)."""
        return dict(self._spare_errors)

    def take_spare_samples(self) -> List[SpareSample]:
        """The spare-input readings made since the last call (oldest first), failed ones with NaN volts."""
        samples, self._spare_samples = self._spare_samples, []
        return samples

    # --- bus helpers ------------------------------------------------------------------------
    def _select(self, channel: int) -> bool:
        """Connect mux ``channel`` (write only if not already selected) and read the control register
        back. False on a bus error or when the mux holds another value."""
        if self._selected == channel:
            return True
        try:
            self._bus.writeto(self._config.mux_address, bytes([1 << channel]))
            self._bus.readfrom_into(self._config.mux_address, self._mux_buffer)
        except OSError:
            self._selected = None  # the mux may or may not have taken the byte
            self._mux_errors += 1
            return False
        if self._mux_buffer[0] != 1 << channel:
            self._selected = None
            self._mux_errors += 1
            self._mux_mismatches += 1
            return False
        self._selected = channel
        return True

    def _deselect(self) -> None:
        try:
            self._bus.writeto(self._config.mux_address, b"\x00")
            self._selected = -1
        except OSError:
            self._selected = None
            self._mux_errors += 1

    def _configure(self, index: int) -> None:
        """Write joint ``index``'s config word, then leave the pointer on the conversion register."""
        joint = self._config.joints[index]
        word = self._configs[index]
        self._bus.writeto(joint.adc_address, bytes([ADS_REG_CONFIG, word >> 8, word & 0xFF]))
        self._bus.writeto(joint.adc_address, bytes([ADS_REG_CONVERSION]))

    def _read_code(self, index: int, set_pointer: bool = False) -> int:
        """Joint ``index``'s conversion register (signed); ``set_pointer`` writes the pointer byte first."""
        address = self._config.joints[index].adc_address
        if set_pointer:
            self._bus.writeto_then_readfrom(address, bytes([ADS_REG_CONVERSION]), self._buffer)
        else:
            self._bus.readfrom_into(address, self._buffer)
        code = (self._buffer[0] << 8) | self._buffer[1]
        return code - 0x10000 if code & 0x8000 else code

    def _config_intact(self, index: int) -> bool:
        """Read joint ``index``'s config register back (OS bit ignored) and put the pointer back on the
        conversion register by reading that with its pointer byte. False: the ADC lost its config."""
        address = self._config.joints[index].adc_address
        self._bus.writeto_then_readfrom(address, bytes([ADS_REG_CONFIG]), self._buffer)
        word = (self._buffer[0] << 8) | self._buffer[1]
        return (word & 0x7FFF) == (self._configs[index] & 0x7FFF)

    def _due_for_check(self) -> int:
        if self._suspects:
            return self._suspects.pop()
        index = self._next_check
        self._next_check = (index + 1) % self._count
        return index

    def _mark_error(self, index: int) -> None:
        self._error_counts[index] += 1
        self._configured[index] = False
        self._selected = None  # a NACK may also mean the mux lost its state (power glitch): re-select

    # --- public API -------------------------------------------------------------------------
    def start(self) -> List[int]:
        """Configure every ADC (continuous, its input, 860 SPS). Returns joints that failed (retried by read)."""
        self._started_at = self._clock()
        self._selected = None
        self._abort_spare(self._started_at)  # every ADC is configured for its joint again below
        failed: List[int] = []
        with bus_locked(self._bus, self._config.bus_lock_timeout):
            try:
                for channel, indices in self._channels.items():
                    if not self._select(channel):
                        failed.extend(indices)
                        continue
                    for index in indices:
                        try:
                            self._configure(index)
                            self._configured[index] = True
                        except OSError:
                            self._mark_error(index)
                            failed.append(index)
            finally:
                if self._config.mux_deselect_after_read:
                    self._deselect()
        return sorted(failed)

    def read(self) -> FeedbackReading:
        """Read all conversion registers once; never raises for bus errors (they mark joints stale)."""
        if self._started_at is None:
            raise RuntimeError("ServoFeedbackArray.read() before start()")
        codes = np.full(self._count, np.nan)
        self._lent[:] = False
        try:
            with bus_locked(self._bus, self._config.bus_lock_timeout):
                try:
                    self._read_cycle(codes)
                finally:
                    if self._config.mux_deselect_after_read:
                        self._deselect()
        except OSError as exc:
            if exc.errno != errno.EBUSY:
                raise
            self._lock_timeouts += 1
        return self._assemble(codes)

    def _abort_spare(self, now: float) -> None:
        """Give up the spare read under way (its ADC is re-configured for its joint by the caller's path)."""
        if self._spare_active is not None:
            spare = self._spares[self._spare_active][0]
            self._spare_errors[spare.name] += 1
            self._spare_samples.append(SpareSample(spare.name, now, math.nan))
            self._spare_active = None

    def _spare_step(self, index: int, now: float) -> bool:
        """The spare-input work on joint ``index``'s ADC before its joint read. True: the ADC is lent this
        cycle (its conversion register is the spare input's), so the joint is not read."""
        active = self._spare_active
        if active is None or self._spares[active][1] != index:
            return False
        self._lent[index] = True
        if now - self._spare_switched < self._spare_settle:
            return True  # the spare input's conversion is not done yet (a data rate far below 860 SPS)
        spare, _host, word = self._spares[active]
        address = self._config.joints[index].adc_address
        self._bus.writeto_then_readfrom(address, bytes([ADS_REG_CONFIG]), self._buffer)
        if (((self._buffer[0] << 8) | self._buffer[1]) & 0x7FFF) != (word & 0x7FFF):
            self._config_losses[index] += 1  # the switch did not take (or a brown-out): not the spare input
            self._abort_spare(now)
        else:
            volts = self._read_code(index, set_pointer=True) * (self._config.adc_full_scale_v / 32768.0)
            self._spare_active = None
            self._spare_samples.append(SpareSample(spare.name, now, volts))
        self._configure(index)  # the joint's input again; its first result is ready 1/DR later
        return True

    def _maybe_lend(self, index: int, now: float) -> None:
        """After joint ``index``'s read: switch its ADC to the spare input whose turn it is, if it is due."""
        if self._spare_active is not None or not self._spares or now < self._spare_due:
            return
        turn = self._spare_turn
        _spare, host, word = self._spares[turn]
        if host != index:
            return
        self._spare_turn = (turn + 1) % len(self._spares)
        # on a grid (each pack at 1 / spare_period on average), unless far behind (a stuck bus, a start)
        late = now - self._spare_due
        self._spare_due = self._spare_due + self._spare_interval if late < self._spare_interval else (
            now + self._spare_interval)
        self._spare_active, self._spare_switched = turn, now
        address = self._config.joints[index].adc_address
        self._bus.writeto(address, bytes([ADS_REG_CONFIG, word >> 8, word & 0xFF]))
        self._bus.writeto(address, bytes([ADS_REG_CONVERSION]))

    def _read_cycle(self, codes: np.ndarray) -> None:
        now = self._clock()
        check = self._due_for_check()
        order = sorted(self._channels)
        if self._selected in self._channels:  # start where the mux already points: one switch saved
            start = order.index(self._selected)
            order = order[start:] + order[:start]
        for channel in order:
            if not self._select(channel):
                continue
            for index in self._channels[channel]:
                try:
                    if not self._configured[index]:
                        # Re-configure a device that NACKed: it may have power-cycled back to its
                        # single-shot default. Its first continuous result is ready 1/DR (1.2 ms) later,
                        # so this cycle's conversion register is not trusted: the joint stays stale
                        # for one more cycle.
                        self._configure(index)
                        self._configured[index] = True
                        continue
                    if self._spare_step(index, now):
                        continue
                    if index == check and not self._config_intact(index):
                        self._config_losses[index] += 1
                        self._configure(index)  # same path as after a NACK: stale one more cycle
                        continue
                    codes[index] = self._read_code(index, set_pointer=index == check)
                    self._maybe_lend(index, now)
                except OSError:
                    if self._spare_active is not None and self._spares[self._spare_active][1] == index:
                        self._abort_spare(now)
                    self._mark_error(index)

    def _within_reach(self, angle: Any, reference: Any, since: Any) -> Any:
        """|angle - reference| within what the servo can turn in ``since`` s (floats or arrays alike)."""
        return np.abs(angle - reference) <= self._max_speed * since + self._jump_margin  # type: ignore[operator]

    def _check_rates(self, now: float, angles: np.ndarray, valid: np.ndarray) -> None:
        """Physical-rate check (class docstring); clears ``valid`` and ``angles`` of implausible jumps."""
        # Every joint at once; only the few readings out of reach go through the run bookkeeping.
        with np.errstate(invalid="ignore"):  # no last good angle yet: NaN, counts as within reach
            beyond = valid & ~self._within_reach(angles, self._last_angle, now - self._last_good)
        beyond &= np.isfinite(self._last_angle)
        self._jump_run[valid & ~beyond] = 0
        for index in np.flatnonzero(beyond):
            angle = float(angles[index])
            if self._jump_run[index] > 0 and self._within_reach(angle, float(self._jump_angle[index]),
                                                               now - self._jump_time[index]):
                self._jump_run[index] += 1
            else:
                self._jump_run[index] = 1
            self._jump_angle[index], self._jump_time[index] = angle, now
            if self._jump_run[index] >= self._config.adc_jump_confirm_readings:
                self._jump_run[index] = 0
                self._jumps_accepted[index] += 1
                continue
            self._jump_counts[index] += 1
            self._suspects.add(int(index))
            valid[index] = False
            angles[index] = np.nan

    def _assemble(self, codes: np.ndarray) -> FeedbackReading:
        now = self._clock()
        valid = np.isfinite(codes)
        volts = np.full(self._count, np.nan)
        volts[valid] = codes[valid] * (self._config.adc_full_scale_v / 32768.0)
        angles = np.full(self._count, np.nan)
        if np.any(valid):
            all_angles = self._calibration.volts_to_angles(np.where(valid, volts, 0.0))
            plausible = (all_angles >= self._low) & (all_angles <= self._high)
            implausible = valid & ~plausible
            self._implausible_counts[implausible] += 1
            self._suspects.update(int(i) for i in np.flatnonzero(implausible))
            valid = valid & plausible
            angles[valid] = all_angles[valid]
            if self._max_speed is not None:
                self._check_rates(now, angles, valid)
        self._last_good[valid] = now
        self._last_angle[valid] = angles[valid]
        age = now - self._last_good
        held = np.where(age <= self._config.stale_after, self._last_angle, np.nan)
        since_start = now - (self._started_at if self._started_at is not None else now)
        stale: List[int] = []
        failed: List[int] = []
        lent: List[int] = []
        for index in np.flatnonzero(~valid):
            if self._lent[index] and np.isfinite(held[index]):
                lent.append(int(index))
                continue
            reference = age[index] if math.isfinite(age[index]) else since_start
            (failed if reference > self._config.failed_after else stale).append(int(index))
        return FeedbackReading(stamp=now, volts=volts, angles=angles, valid=valid, stale=stale, failed=failed,
                               error_counts=self._error_counts.copy(), mux_errors=self._mux_errors,
                               implausible=[int(i) for i in np.flatnonzero(np.isfinite(volts) & ~valid)],
                               held_angles=held, age=age, lent=lent)


__all__ = ["FeedbackReading", "ServoFeedbackArray", "SpareInput", "SpareSample", "ads1115_continuous_config",
           "plausible_angle_range"]
