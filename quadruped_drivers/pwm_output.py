"""Servo PWM output through a PCA9685: clamping, one-write updates, command watchdog, failsafe.

The paper's control node (section "Electronics and software") sends the twelve servo pulse widths
computed from the inverse kinematics (eq. ik_theta3, ik_theta1245) every 10 ms. This module is the
last line of defence before the servos: every pulse is clamped into its channel's configured limits,
non-finite commands never reach the chip, and a silent controller trips a watchdog that applies each
channel's failsafe (hold | neutral | off).

Register-level rather than adafruit-circuitpython-pca9685 3.4 (``docs/hardware_libraries.md``): its
constructor's ``reset()`` writes MODE1 = 0, which wakes the oscillator with whatever prescale and LED
registers survived a process restart and clears auto-increment; its ``deinit()`` does not stop the
outputs; its register buffers are class-level (shared by all instances, not thread-safe); and it
updates one channel per transaction where one auto-increment write from LED0 carries all twelve.
The prescale formula is the same as the library's (``int(osc / 4096 / f + 0.5) - 1``; cross-checked
in the tests by running the library against the fake chip).

pulse (us) -> ticks: ticks = round(us * f_actual * 4096 / 1e6), f_actual = osc / (4096 (prescale + 1)).

**Writes that cannot tear a pulse out of its limits.** An I2C write that aborts part-way (bus error,
arbitration lost) leaves a prefix of its bytes in the chip: a new OFF_L with the old OFF_H could put
3,743 us on a channel commanded to 2,495 us. The twelve channels still go out in one auto-increment
write, but each channel's four bytes (ON_L, ON_H, OFF_L, OFF_H, in that order) are chosen so that every
prefix leaves a pulse inside the channel's tick window [m, M] (:meth:`ServoPwmOutput.channel_bytes`):

* ON_L is a per-channel constant c = (-m) mod 256, so with ON = 256 a + c and a pulse of w ticks,
  OFF_L = (w - m) mod 256 for every pulse this driver writes;
* the new ON is either the chip's current ON, when that keeps the torn state below in [m, M], or
  256 OFF_H_chip - m. With the latter, after ON_H the chip holds OFF_chip - ON_new = m + OFF_L_chip,
  after OFF_L it holds m + OFF_L_new; each is m + ((w - m) mod 256) for an old or the new w, which is
  w itself when w - m < 256 and w - 256 (>= m, <= M) otherwise. After OFF_H it holds the new w.
* turning a channel on from full-off: OFF_H (with the full-off bit) is the last byte, so every prefix
  is still off; turning it off changes only OFF_H (one byte, cannot tear).

The rule needs the chip's OFF_H. After a failed write the chip holds some prefix of it, so until a write
succeeds the same bytes are retried (every prefix of a retry is one of the states above; channels that
are to turn off get their full-off bit in the retry already); only then is a new block computed. A failed write is retried up to ``write_attempts`` times per call (counted in
``write_retries``).

**A chip that reset** (brown-out: MODE1 back to SLEEP | ALLCALL, outputs off, still ACKing writes) is
found by reading MODE1/MODE2 every ``mode_check_interval`` s in :meth:`ServoPwmOutput.update`
(counted in ``chip_resets``, described in ``last_fault``); the start-up sequence is run again and the
current widths re-applied.
"""
from __future__ import annotations

import time
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_drivers.hardware_config import HardwareConfig
from quadruped_drivers.i2c import bus_locked

MODE1 = 0x00
MODE2 = 0x01
LED0_ON_L = 0x06
ALL_LED_ON_L = 0xFA
ALL_LED_OFF_H = 0xFD
PRE_SCALE = 0xFE
MODE1_RESTART = 0x80
MODE1_AI = 0x20
MODE1_SLEEP = 0x10
MODE2_OUTDRV = 0x04  # totem-pole outputs (servo signal lines)
FULL = 0x10
#: Tick offset between the rising edges of consecutive channels when staggering is enabled.
STAGGER_TICKS = 256
#: Oscillator start-up time after clearing SLEEP before RESTART may be written (datasheet: 500 us).
OSCILLATOR_STARTUP_S = 0.0005
#: Applied-width marker for a channel whose output is off.
OFF = 0.0
#: Attempts per write (the first try and its retries) within one call: with half of all transactions
#: failing, a write misses one call with probability 1/256 (the failsafe must land within one period).
WRITE_ATTEMPTS = 8
#: Seconds between MODE1/MODE2 checks for a chip that reset (one 2-byte read, ~50 bits on the wire).
MODE_CHECK_INTERVAL = 0.1
#: LEDn registers of a channel that is off and was never driven (start-up / ALL_LED state).
_OFF_BYTES = (0, 0, 0, FULL)


class PwmOutputError(RuntimeError):
    """The PCA9685 did not come up as configured (read-back mismatch) or is unreachable."""


class ServoPwmOutput:
    """Twelve servo outputs on one PCA9685 (channels and limits from ``hardware_config``).

    ``applied_us`` holds what the chip outputs per joint (0.0 = off). One thread owns the instance.
    """

    def __init__(self, bus: Any, hardware_config: HardwareConfig, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, update_period: float = 0.0,
                 write_attempts: int = WRITE_ATTEMPTS, mode_check_interval: float = MODE_CHECK_INTERVAL) -> None:
        """``update_period``: how often the caller runs :meth:`update` (s); the watchdog trips on the
        last check that comes before its timeout, so the failsafe is never a period late."""
        if not (0.0 <= update_period < hardware_config.watchdog_timeout):
            raise ValueError("update_period must be in [0, watchdog timeout), got %r" % (update_period,))
        if isinstance(write_attempts, bool) or not isinstance(write_attempts, int) or write_attempts < 1:
            raise ValueError("write_attempts must be an integer >= 1, got %r" % (write_attempts,))
        if not mode_check_interval > 0.0:
            raise ValueError("mode_check_interval must be positive, got %r" % (mode_check_interval,))
        self.update_period = float(update_period)
        self.write_attempts = write_attempts
        self.mode_check_interval = float(mode_check_interval)
        self._bus = bus
        self._config = hardware_config
        self._clock = clock
        self._sleep = sleep
        self._count = len(hardware_config.joints)
        self._channels = hardware_config.pwm_channels
        self._min = hardware_config.min_us
        self._max = hardware_config.max_us
        self._neutral = hardware_config.neutral_us
        self._failsafe = [joint.failsafe for joint in hardware_config.joints]
        self.prescale = hardware_config.prescale
        self.frequency_hz = hardware_config.actual_pwm_frequency_hz
        self._ticks_per_us = self.frequency_hz * 4096.0 / 1e6
        # Tick bounds per joint that keep even the quantised pulse inside [min_us, max_us].
        self._min_ticks = np.ceil(self._min * self._ticks_per_us - 1e-9).astype(int)
        self._max_ticks = np.floor(self._max * self._ticks_per_us + 1e-9).astype(int)
        self._span = int(self._channels.max()) + 1  # LED0 .. highest channel in use: one write
        self._joint_of_channel = {int(channel): index for index, channel in enumerate(self._channels)}
        # What the chip's LEDn registers hold (known after a successful write), and the block of a failed
        # write that may have landed in part (None: the chip state is known).
        self._chip = [_OFF_BYTES] * self._span
        self._in_flight: Optional[bytes] = None
        self._commanded = np.zeros(self._count, dtype=bool)
        self._next_mode_check = -np.inf
        self._applied = np.zeros(self._count)
        self._requested = np.full(self._count, np.nan)
        self._started = False
        self._enabled = False
        self._watchdog_tripped = False
        self._last_command: Optional[float] = None
        self._pending_write = False
        self._pending = np.zeros(self._count)
        self.write_errors = 0
        self.write_retries = 0
        self.chip_resets = 0
        self.mode_read_errors = 0
        self.last_fault = ""
        self.clamp_count = 0
        self.invalid_count = 0
        self.watchdog_trips = 0
        self._estop = ""
        self._estop_off_pending = False
        self._io_fault = ""  # the last bus transaction's failure; cleared by the next that succeeds

    # --- properties -------------------------------------------------------------------------
    @property
    def applied_us(self) -> np.ndarray:
        """Pulse widths (us) the chip outputs per joint, quantised to its 4096 ticks per period
        (about 4.9 us at 50 Hz); 0.0 = output off (copy)."""
        return self._applied.copy()

    @property
    def requested_us(self) -> np.ndarray:
        """The last commanded widths after clamping (recorded even while disabled) (copy)."""
        return self._requested.copy()

    @property
    def enabled(self) -> bool:
        """False: outputs are off and commands are recorded but not applied."""
        return self._enabled

    @property
    def estop_reason(self) -> str:
        """Why the e-stop is latched; empty when it is not."""
        return self._estop

    def estop(self, reason: str) -> bool:
        """Latch the e-stop: every output off at once (one ALL_LED full-off write, repeated by :meth:`update`
        until it takes), commands recorded but not applied, :meth:`enable` refused until :meth:`reset_estop`.
        Returns True when the outputs are off."""
        self._require_started()
        self._estop = reason or "e-stop"
        self._enabled = False
        self._pending_write = False
        self._estop_off_pending = not self._all_off()
        return not self._estop_off_pending

    def reset_estop(self) -> None:
        """Release the e-stop; the outputs stay off until :meth:`enable`."""
        self._estop = ""

    @property
    def not_ready(self) -> str:
        """Why the outputs cannot take the controller's commands now (empty when they can): the e-stop, outputs
        disabled, or the chip not answering on its last transaction."""
        if self._estop:
            return "e-stop latched (%s)" % self._estop
        if not self._started:
            return "the PCA9685 is not set up yet"
        if not self._enabled:
            return "outputs disabled (pwm_node/enable true)"
        if self._io_fault:
            return "the PCA9685 does not answer: %s" % self._io_fault
        return ""

    @property
    def watchdog_tripped(self) -> bool:
        """True from a watchdog trip until the next command."""
        return self._watchdog_tripped

    def ticks(self, pulse_us: float) -> int:
        """PCA9685 ticks for a pulse of ``pulse_us`` at the actual output frequency (1..4095)."""
        return int(min(4095, max(1, int(round(pulse_us * self._ticks_per_us)))))

    def quantize(self, widths: np.ndarray) -> np.ndarray:
        """The widths (us) the chip really produces for per-joint ``widths`` (0 stays 0 = off), with the
        tick count kept inside each joint's limits (so rounding never leaves [min_us, max_us])."""
        out = np.zeros(self._count)
        on = widths > 0.0
        ticks = np.clip(np.round(widths * self._ticks_per_us), self._min_ticks, self._max_ticks)
        out[on] = ticks[on] / self._ticks_per_us
        return out

    # --- bus helpers ------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        self._bus.writeto(self._config.pca_address, data)

    def _read_register(self, register: int) -> int:
        buffer = bytearray(1)
        self._bus.writeto_then_readfrom(self._config.pca_address, bytes([register]), buffer)
        return buffer[0]

    def channel_bytes(self, index: int, width_us: float, chip: Sequence[int]) -> Tuple[int, int, int, int]:
        """LEDn (ON_L, ON_H, OFF_L, OFF_H) for joint ``index`` at ``width_us`` (0 = off), given the bytes
        ``chip`` its channel holds now, such that every prefix of the write is in limits (module doc)."""
        on_l, on_h, off_l, off_h = chip
        if width_us <= 0.0:
            return on_l, on_h, off_l, (off_h & 0x0F) | FULL  # only OFF_H changes: one byte
        low = int(self._min_ticks[index])
        high = int(self._max_ticks[index])
        ticks = int(round(width_us * self._ticks_per_us))
        constant = (-low) % 256
        channel = int(self._channels[index])
        if off_h & FULL or on_l != constant:
            # Off now: every prefix stays off (OFF_H with its full-off bit goes last); stagger the edge.
            base = (channel * STAGGER_TICKS) % 4096 if self._config.pwm_stagger else 0
            on = (base - low) % 4096
        else:
            on_chip = (on_h & 0x0F) << 8 | on_l
            torn = ((((off_h & 0x0F) << 8) | ((on_chip + ticks) & 0xFF)) - on_chip) % 4096
            on = on_chip if low <= torn <= high else (((off_h & 0x0F) << 8) - low) % 4096
        off = (on + ticks) % 4096
        return on & 0xFF, on >> 8, off & 0xFF, off >> 8

    def _block(self, widths: np.ndarray) -> bytes:
        """LED0..LED(span-1) registers for per-joint ``widths`` (0 = full off; unused channels off),
        computed from the chip's current registers (:meth:`channel_bytes`)."""
        data = bytearray([LED0_ON_L])
        for channel in range(self._span):
            index = self._joint_of_channel.get(channel)
            chip = self._chip[channel]
            if index is None:
                data += bytes(chip[:3]) + bytes([(chip[3] & 0x0F) | FULL])
            else:
                data += bytes(self.channel_bytes(index, float(widths[index]), chip))
        return bytes(data)

    def _write_block(self, block: bytes) -> bool:
        """One LED block write (up to ``write_attempts`` tries); the chip state follows on success."""
        for attempt in range(self.write_attempts):
            if attempt:
                self.write_retries += 1
            try:
                with bus_locked(self._bus, self._config.bus_lock_timeout):
                    self._write(block)
            except OSError as exc:
                self.write_errors += 1
                self.last_fault = self._io_fault = "LED write failed: %s" % (exc,)
                self._in_flight = block
                continue
            self._chip = [tuple(block[1 + 4 * c:5 + 4 * c]) for c in range(self._span)]
            self._in_flight = None
            self._io_fault = ""
            return True
        return False

    def _merge_off(self, block: bytes, widths: np.ndarray) -> bytes:
        """``block`` (a failed write) with the full-off bit set for every joint ``widths`` turns off: each
        prefix of it is still a prefix of ``block`` or an output turned off, so it may be sent at once."""
        data = bytearray(block)
        for index, channel in enumerate(self._channels):
            if widths[index] <= 0.0:
                data[4 + 4 * int(channel)] |= FULL
        return bytes(data)

    def _apply(self, widths: np.ndarray) -> bool:
        """Put ``widths`` on the chip; on success they become ``applied_us``, else they stay pending."""
        widths = self.quantize(widths)
        self._pending = widths.copy()
        self._pending_write = True
        retried = self._in_flight is not None
        if retried and not self._write_block(self._merge_off(self._in_flight, widths)):
            return False  # the chip holds a prefix of the failed block: only that block may be retried
        block = self._block(widths)
        if not (retried and block[1:] == bytes(b for chip in self._chip for b in chip)) \
                and not self._write_block(block):
            return False
        self._applied = widths.copy()
        self._pending_write = False
        return True

    # --- lifecycle --------------------------------------------------------------------------
    def start(self, enable: bool = True) -> None:
        """Bring the chip to a known state and verify it; outputs stay off until the first command.

        Sequence: MODE1 = SLEEP|AI (oscillator off, auto-increment, all-call off), ALL_LED full-off,
        MODE2 = OUTDRV, PRE_SCALE (only takes while asleep), MODE1 = AI (wake), wait 500 us, write
        RESTART, read back MODE1/MODE2/PRE_SCALE. Raises :class:`PwmOutputError` on a bus error or a
        read-back mismatch (the caller must not run the servos then).
        """
        self._initialise()
        self._applied = np.zeros(self._count)
        self._pending_write = False
        self._commanded[:] = False
        self._started = True
        self._enabled = enable
        self._watchdog_tripped = False
        self._last_command = self._clock()
        self._next_mode_check = self._clock() + self.mode_check_interval

    def _initialise(self) -> None:
        """The start-up register sequence with read-back; the chip's LED state is known afterwards."""
        try:
            with bus_locked(self._bus, self._config.bus_lock_timeout):
                self._write(bytes([MODE1, MODE1_SLEEP | MODE1_AI]))
                self._write(bytes([ALL_LED_ON_L, 0, 0, 0, FULL]))
                self._write(bytes([MODE2, MODE2_OUTDRV]))
                self._write(bytes([PRE_SCALE, self.prescale]))
                self._write(bytes([MODE1, MODE1_AI]))
                self._sleep(OSCILLATOR_STARTUP_S)
                self._write(bytes([MODE1, MODE1_RESTART | MODE1_AI]))
                mode1 = self._read_register(MODE1)
                mode2 = self._read_register(MODE2)
                prescale = self._read_register(PRE_SCALE)
        except OSError as exc:
            raise PwmOutputError("PCA9685 at 0x%02x did not answer during start-up: %s"
                                 % (self._config.pca_address, exc)) from exc
        problems: List[str] = []
        if mode1 & (MODE1_SLEEP | MODE1_AI) != MODE1_AI:
            problems.append("MODE1 = 0x%02x (expected AI set, SLEEP clear)" % mode1)
        if mode2 != MODE2_OUTDRV:
            problems.append("MODE2 = 0x%02x (expected 0x%02x)" % (mode2, MODE2_OUTDRV))
        if prescale != self.prescale:
            problems.append("PRE_SCALE = %d (expected %d)" % (prescale, self.prescale))
        if problems:
            raise PwmOutputError("PCA9685 at 0x%02x read-back mismatch: %s"
                                 % (self._config.pca_address, "; ".join(problems)))
        self._chip = [_OFF_BYTES] * self._span  # ALL_LED full-off wrote 0, 0, 0, FULL everywhere
        self._in_flight = None

    def _require_started(self) -> None:
        if not self._started:
            raise RuntimeError("ServoPwmOutput used before start()")

    def command(self, pulse_widths_us: Sequence[float]) -> np.ndarray:
        """Apply twelve pulse widths (us, JOINT_NAMES order); returns the widths applied (0 = off).

        Each width is clamped into its channel's [min_us, max_us] (``clamp_count`` counts clamped
        channels). A NaN/inf keeps the channel's last applied width, or its failsafe if it has none
        (``invalid_count``). Feeds the watchdog. While disabled the command is only recorded.
        """
        self._require_started()
        values = np.asarray(pulse_widths_us, dtype=float)
        if values.shape != (self._count,):
            raise ValueError("expected %d pulse widths, got shape %s" % (self._count, values.shape))
        finite = np.isfinite(values)
        self.invalid_count += int(np.count_nonzero(~finite))
        target = np.where(finite, values, 0.0)
        clamped = np.clip(target, self._min, self._max)
        self.clamp_count += int(np.count_nonzero(finite & (clamped != target)))
        for index in np.flatnonzero(~finite):
            clamped[index] = self._fallback(index, self._applied[index])
        self._requested = clamped
        self._last_command = self._clock()
        self._watchdog_tripped = False
        if not self._enabled:
            return self.applied_us
        self._commanded |= finite
        self._apply(clamped)
        return self.applied_us

    def _fallback(self, index: int, current: float) -> float:
        """Width for a channel without a usable command: keep ``current`` if on, else its failsafe."""
        if current > 0.0:
            return float(current)
        return self._failsafe_width(index, current)

    def _failsafe_width(self, index: int, current: float) -> float:
        action = self._failsafe[index]
        if action == "neutral" and self._commanded[index]:  # never move a servo nobody commanded
            return float(self._neutral[index])
        if action == "off":
            return OFF
        return float(current)  # hold, or neutral before any command (an output that is off stays off)

    def update(self) -> bool:
        """Call every ``update_period``: checks the chip for a reset (every ``mode_check_interval``), trips
        the watchdog (failsafe once) on the last check before ``watchdog_timeout`` without a command
        runs out, and retries a write that failed. Returns :attr:`watchdog_tripped`."""
        self._require_started()
        if self._estop_off_pending:  # the e-stop's all-off write failed: again, every update, until it takes
            self._estop_off_pending = not self._all_off()
        now = self._clock()
        if now >= self._next_mode_check:
            self._next_mode_check = now + self.mode_check_interval
            self._check_mode()
        if (self._enabled and not self._watchdog_tripped and self._last_command is not None
                and now - self._last_command + self.update_period > self._config.watchdog_timeout):
            self._watchdog_tripped = True
            self.watchdog_trips += 1
            base = self._pending if self._pending_write else self._applied
            widths = np.array([self._failsafe_width(index, base[index]) for index in range(self._count)])
            self._apply(widths)
        elif self._pending_write and self._enabled:
            self._apply(self._pending)
        return self._watchdog_tripped

    def _check_mode(self) -> None:
        """Read MODE1/MODE2; a chip that lost its configuration (reset) is set up again and re-driven."""
        buffer = bytearray(2)
        try:
            with bus_locked(self._bus, self._config.bus_lock_timeout):
                self._bus.writeto_then_readfrom(self._config.pca_address, bytes([MODE1]), buffer)
        except OSError as exc:
            self.mode_read_errors += 1
            self.last_fault = self._io_fault = "MODE1 read failed: %s" % (exc,)
            return
        self._io_fault = ""
        mode1, mode2 = buffer
        if mode1 & (MODE1_SLEEP | MODE1_AI | 0x0F) == MODE1_AI and mode2 == MODE2_OUTDRV:
            return
        self.chip_resets += 1
        self.last_fault = ("PCA9685 lost its configuration (MODE1 0x%02x, MODE2 0x%02x): set up again"
                           % (mode1, mode2))
        target = self._pending if self._pending_write else self._applied
        try:
            self._initialise()
        except PwmOutputError as exc:
            self.last_fault += "; failed: %s" % (exc,)
            self._io_fault = self.last_fault
            self._next_mode_check = -np.inf  # try again on the next update
            return
        self._applied = np.zeros(self._count)
        if self._enabled and np.any(target > 0.0):
            self._apply(target)

    def disable(self) -> None:
        """Outputs off (ALL_LED full-off); later commands are recorded but not applied."""
        self._require_started()
        self._enabled = False
        self._pending_write = False
        if not self._all_off():
            raise PwmOutputError("could not switch the PCA9685 outputs off")

    def enable(self) -> None:
        """Accept commands again; outputs stay off until the next command (no jump to an old one).
        :class:`EStopLatched` while the e-stop is latched."""
        self._require_started()
        if self._estop:
            raise EStopLatched("e-stop latched (%s): reset it first" % self._estop)
        self._enabled = True
        self._watchdog_tripped = False
        self._commanded[:] = False
        self._last_command = self._clock()

    def _all_off(self) -> bool:
        """Every output off with one byte (ALL_LED_OFF_H full-off bit): nothing else changes, so an aborted
        write cannot tear a pulse (writing ALL_LED_ON_L would shift every running pulse)."""
        try:
            with bus_locked(self._bus, self._config.bus_lock_timeout):
                self._write(bytes([ALL_LED_OFF_H, FULL]))
        except OSError as exc:
            self.write_errors += 1
            self.last_fault = self._io_fault = "all-off write failed: %s" % (exc,)
            return False
        if self._in_flight is not None:  # a prefix of it may sit in the chip; OFF_H is now full-off anyway
            self._chip = [tuple(self._in_flight[1 + 4 * c:5 + 4 * c]) for c in range(self._span)]
            self._in_flight = None
        self._chip = [chip[:3] + (FULL,) for chip in self._chip]
        self._applied = np.zeros(self._count)
        return True

    def shutdown(self) -> bool:
        """ALL_LED full-off, then sleep (oscillator off). Returns True if both writes succeeded."""
        self._enabled = False
        self._pending_write = False
        ok = self._all_off()
        try:
            with bus_locked(self._bus, self._config.bus_lock_timeout):
                self._write(bytes([MODE1, MODE1_SLEEP | MODE1_AI]))
        except OSError:
            self.write_errors += 1
            ok = False
        self._started = False
        return ok


class EStopLatched(RuntimeError):
    """Outputs asked on while the e-stop is latched."""


__all__ = ["EStopLatched", "ServoPwmOutput", "PwmOutputError", "STAGGER_TICKS", "OFF"]
