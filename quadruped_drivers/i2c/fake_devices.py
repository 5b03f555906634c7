"""Register-level fakes of the servo electronics: TCA9548A mux, ADS1115 ADC, PCA9685 PWM driver (and, wired as
``config/hardware.yaml`` says, the MS5837 depth sensor of :mod:`quadruped_drivers.i2c.fake_ms5837`).

They implement the chips' register maps closely enough that both our drivers and the unchanged
adafruit CircuitPython drivers work against them (tested), and that the simulator (``sim_node``) can
read the pulse widths the PCA9685 holds and feed servo feedback voltages into the ADCs.

Behaviour follows the TI/NXP datasheets where it matters to a driver:

* TCA9548A: one control register, bit n connects downstream channel n; several bits = several
  channels at once; reads return the control register.
* ADS1115: address pointer register (2 LSBs of the first written byte), 16-bit big-endian registers
  (conversion 0x00, config 0x01, Lo_thresh 0x02, Hi_thresh 0x03); power-up config 0x8583 (single-shot,
  AIN0-AIN1, +-2.048 V, 128 SPS, comparator off). Continuous mode: the conversion register follows the
  selected input; single-shot: writing OS=1 converts once (OS reads 0 while converting -- here the
  conversion completes at once, so OS reads 1), result held. Config OS bit reads 0 in continuous mode.
  Result = clamp(round(V / FSR * 32768), -32768, 32767).
* PCA9685: MODE1 (RESTART, EXTCLK, AI, SLEEP, SUB1..3, ALLCALL), MODE2, LEDn_ON/OFF_L/H with the
  full-on / full-off bit 4 of the _H registers, ALL_LED_* (write-only, read 0), PRE_SCALE writable only
  while SLEEP = 1 (ignored otherwise, as the chip does; values < 3 read as 3). Auto-increment (AI)
  walks 0x00..0x45 then wraps to 0x00; 0xFA..0xFE likewise. Going to sleep with outputs running sets
  RESTART; outputs stay halted after waking until RESTART is written with 1 (or any LED register is
  written). Power-up state: MODE1 0x11 (SLEEP | ALLCALL), all outputs full-off, PRE_SCALE 0x1E.
"""
from __future__ import annotations

import errno
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_drivers.i2c.fake_bus import FakeI2CBus
from quadruped_drivers.i2c.fake_ms5837 import FakeMs5837

# ------------------------------------------------------------------------------------------------
# TCA9548A
# ------------------------------------------------------------------------------------------------


class FakeTca9548a:
    """TCA9548A 8-channel I2C multiplexer.

    Attach it at its address on the parent bus; the parent then asks :meth:`route` for every other
    address and the mux forwards to the devices on its selected channel buses (:meth:`channel_bus`).
    """

    CHANNELS = 8

    def __init__(self) -> None:
        self.control = 0
        self._channels = [FakeI2CBus(name="tca9548a-ch%d" % channel) for channel in range(self.CHANNELS)]
        self._deselect_failures: Optional[int] = 0
        self._deselect_kind = errno.EIO
        self._ignored_writes = 0
        self.writes = 0

    def channel_bus(self, channel: int) -> FakeI2CBus:
        """The downstream bus of ``channel`` (0..7): attach devices there."""
        if not 0 <= channel < self.CHANNELS:
            raise ValueError("TCA9548A channel must be 0..7, got %r" % (channel,))
        return self._channels[channel]

    @property
    def selected_channels(self) -> List[int]:
        """Channels currently connected to the parent bus."""
        return [channel for channel in range(self.CHANNELS) if self.control & (1 << channel)]

    def inject_deselect_failure(self, count: Optional[int] = 1, nack: bool = False) -> None:
        """Fail the next ``count`` writes of control = 0 (``None``: every one) with OSError, state unchanged."""
        if count is not None and count < 1:
            raise ValueError("count must be >= 1 or None")
        self._deselect_failures = count
        self._deselect_kind = errno.ENXIO if nack else errno.EIO
        if count is None:
            self._deselect_failures = None

    def inject_ignored_writes(self, count: int = 1) -> None:
        """ACK the next ``count`` control writes without taking them (a glitch on SDA while latching):
        the master sees success, the old channel stays selected."""
        if count < 1:
            raise ValueError("count must be >= 1")
        self._ignored_writes = count

    def clear_deselect_failure(self) -> None:
        """Stop failing deselect writes."""
        self._deselect_failures = 0

    def reset(self) -> None:
        """Hardware reset (RESET pin low / power cycle): all channels deselected."""
        self.control = 0

    # --- device protocol --------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        if not data:
            return
        value = data[-1]
        if value == 0 and (self._deselect_failures is None or self._deselect_failures > 0):
            if self._deselect_failures is not None:
                self._deselect_failures -= 1
            raise OSError(self._deselect_kind, "TCA9548A: injected deselect failure")
        self.writes += 1
        if self._ignored_writes > 0:
            self._ignored_writes -= 1
            return
        self.control = value

    def read(self, count: int) -> bytes:
        return bytes([self.control] * count)

    def route(self, address: int) -> List[Tuple[FakeI2CBus, Any]]:
        targets: List[Tuple[FakeI2CBus, Any]] = []
        for channel in self.selected_channels:
            targets.extend(self._channels[channel].resolve(address))
        return targets


# ------------------------------------------------------------------------------------------------
# ADS1115
# ------------------------------------------------------------------------------------------------

ADS_REG_CONVERSION = 0x00
ADS_REG_CONFIG = 0x01
ADS_REG_LO_THRESH = 0x02
ADS_REG_HI_THRESH = 0x03
ADS_CONFIG_DEFAULT = 0x8583
ADS_OS = 0x8000
ADS_MODE_SINGLE = 0x0100
#: PGA field (bits 11:9) -> full-scale range in volts.
ADS_PGA_FSR: Tuple[float, ...] = (6.144, 4.096, 2.048, 1.024, 0.512, 0.256, 0.256, 0.256)
#: DR field (bits 7:5) -> samples per second.
ADS_DR_SPS: Tuple[int, ...] = (8, 16, 32, 64, 128, 250, 475, 860)
#: MUX field (bits 14:12) -> (positive input, negative input or None for GND).
ADS_MUX_INPUTS: Tuple[Tuple[int, Optional[int]], ...] = (
    (0, 1), (0, 3), (1, 3), (2, 3), (0, None), (1, None), (2, None), (3, None))


def ads1115_code(volts: float, full_scale_v: float) -> int:
    """ADS1115 result for a differential input of ``volts``: clamp(round(V / FSR * 32768))."""
    if not np.isfinite(volts):
        raise ValueError("input voltage must be finite, got %r" % volts)
    return int(max(-32768, min(32767, int(round(volts / full_scale_v * 32768.0)))))


class FakeAds1115:
    """ADS1115 16-bit ADC with its four inputs driven by :meth:`set_input_voltage`."""

    def __init__(self) -> None:
        self.inputs = [0.0, 0.0, 0.0, 0.0]
        self.power_cycle()

    def power_cycle(self) -> None:
        """Power-on reset: default registers, pointer on the conversion register."""
        self.pointer = ADS_REG_CONVERSION
        self.config = ADS_CONFIG_DEFAULT
        self.lo_thresh = 0x8000
        self.hi_thresh = 0x7FFF
        self._held = 0
        self.config_writes = 0
        self._garbage: List[int] = []

    def inject_codes(self, codes: Sequence[int]) -> None:
        """The next conversion-register reads return ``codes`` (16-bit, signed) instead of a conversion:
        e.g. a disturbed input or a bit error on the bus."""
        for code in codes:
            if not -32768 <= int(code) <= 32767:
                raise ValueError("ADS1115 codes are 16-bit signed, got %r" % (code,))
        self._garbage = [int(code) for code in codes]
    def set_input_voltage(self, ain: int, volts: float) -> None:
        """Drive input AIN``ain`` (0..3) with ``volts`` (finite)."""
        if not 0 <= ain <= 3:
            raise ValueError("ADS1115 input must be 0..3, got %r" % (ain,))
        if not np.isfinite(volts):
            raise ValueError("input voltage must be finite, got %r" % (volts,))
        self.inputs[ain] = float(volts)

    # --- decoded configuration --------------------------------------------------------------
    @property
    def continuous(self) -> bool:
        """True in continuous-conversion mode (MODE bit 8 = 0)."""
        return not self.config & ADS_MODE_SINGLE

    @property
    def full_scale_v(self) -> float:
        """Full-scale range selected by the PGA field."""
        return ADS_PGA_FSR[(self.config >> 9) & 0x7]

    @property
    def data_rate(self) -> int:
        """Samples per second selected by the DR field."""
        return ADS_DR_SPS[(self.config >> 5) & 0x7]

    @property
    def mux(self) -> Tuple[int, Optional[int]]:
        """(positive input, negative input or None = GND) selected by the MUX field."""
        return ADS_MUX_INPUTS[(self.config >> 12) & 0x7]

    def convert(self) -> int:
        """The conversion result the chip would produce right now for its configured input."""
        positive, negative = self.mux
        volts = self.inputs[positive] - (self.inputs[negative] if negative is not None else 0.0)
        return ads1115_code(volts, self.full_scale_v)

    # --- device protocol --------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        if not data:
            return
        self.pointer = data[0] & 0x03
        if len(data) < 3:
            return
        value = (data[1] << 8) | data[2]
        if self.pointer == ADS_REG_CONFIG:
            self.config_writes += 1
            self.config = value & 0x7FFF
            if not self.continuous and value & ADS_OS:
                self._held = self.convert()  # single-shot conversion (completes at once here)
            if not self.continuous:
                self.config |= ADS_OS  # OS reads 1: not converting
        elif self.pointer == ADS_REG_LO_THRESH:
            self.lo_thresh = value
        elif self.pointer == ADS_REG_HI_THRESH:
            self.hi_thresh = value
        # the conversion register is read-only

    def _register(self) -> int:
        if self.pointer == ADS_REG_CONVERSION:
            if self._garbage:
                return self._garbage.pop(0) & 0xFFFF
            if self.continuous:
                self._held = self.convert()
            return self._held & 0xFFFF
        if self.pointer == ADS_REG_CONFIG:
            return self.config
        if self.pointer == ADS_REG_LO_THRESH:
            return self.lo_thresh
        return self.hi_thresh

    def read(self, count: int) -> bytes:
        value = self._register()
        pair = bytes([(value >> 8) & 0xFF, value & 0xFF])
        return (pair * ((count + 1) // 2))[:count]


# ------------------------------------------------------------------------------------------------
# PCA9685
# ------------------------------------------------------------------------------------------------

PCA_MODE1 = 0x00
PCA_MODE2 = 0x01
PCA_LED0_ON_L = 0x06
PCA_ALL_LED_ON_L = 0xFA
PCA_ALL_LED_OFF_H = 0xFD
PCA_PRE_SCALE = 0xFE
PCA_RESTART = 0x80
PCA_EXTCLK = 0x40
PCA_AI = 0x20
PCA_SLEEP = 0x10
PCA_ALLCALL = 0x01
PCA_FULL = 0x10  # bit 4 of LEDn_ON_H (full on) / LEDn_OFF_H (full off)
PCA_LAST_LED_REGISTER = 0x45


class FakePca9685:
    """PCA9685 16-channel 12-bit PWM driver (register map, sleep/restart, prescale, auto-increment)."""

    CHANNELS = 16

    def __init__(self, oscillator_hz: float = 25e6, allcall_address: int = 0x70) -> None:
        self.oscillator_hz = float(oscillator_hz)
        self.allcall_address = allcall_address
        self.power_cycle()

    def power_cycle(self) -> None:
        """Power-on reset state (datasheet register defaults)."""
        self.registers = bytearray(256)
        self.registers[PCA_MODE1] = PCA_SLEEP | PCA_ALLCALL
        self.registers[PCA_MODE2] = 0x04
        self.registers[0x02], self.registers[0x03], self.registers[0x04] = 0xE2, 0xE4, 0xE8
        self.registers[0x05] = 0xE0
        for channel in range(self.CHANNELS):
            self.registers[PCA_LED0_ON_L + 4 * channel + 3] = PCA_FULL
        self.registers[PCA_PRE_SCALE] = 0x1E
        self.pointer = 0
        self._restart_pending = False
        self.led_writes = 0

    # --- decoded state ----------------------------------------------------------------------
    @property
    def mode1(self) -> int:
        """MODE1 as a read returns it (RESTART bit reflects a pending restart)."""
        return (self.registers[PCA_MODE1] & 0x7F) | (PCA_RESTART if self._restart_pending else 0)

    @property
    def asleep(self) -> bool:
        """True while MODE1.SLEEP = 1 (oscillator off, outputs off)."""
        return bool(self.registers[PCA_MODE1] & PCA_SLEEP)

    @property
    def auto_increment(self) -> bool:
        """MODE1.AI."""
        return bool(self.registers[PCA_MODE1] & PCA_AI)

    @property
    def prescale(self) -> int:
        """PRE_SCALE register."""
        return self.registers[PCA_PRE_SCALE]

    def frequency_hz(self) -> float:
        """Output frequency: osc / (4096 (PRE_SCALE + 1))."""
        return self.oscillator_hz / (4096.0 * (self.prescale + 1))

    def channel_registers(self, channel: int) -> Tuple[int, int, bool, bool]:
        """(on tick, off tick, full_on, full_off) of ``channel``."""
        if not 0 <= channel < self.CHANNELS:
            raise ValueError("PCA9685 channel must be 0..15, got %r" % (channel,))
        base = PCA_LED0_ON_L + 4 * channel
        on_l, on_h, off_l, off_h = self.registers[base:base + 4]
        return (((on_h & 0x0F) << 8) | on_l, ((off_h & 0x0F) << 8) | off_l,
                bool(on_h & PCA_FULL), bool(off_h & PCA_FULL))

    def outputs_active(self, channel: int) -> bool:
        """True if ``channel`` currently produces pulses (or is held fully on)."""
        return self.pulse_width_us(channel) > 0.0

    def pulse_width_us(self, channel: int) -> float:
        """High time per period of ``channel`` in microseconds (0 when off, asleep or awaiting RESTART)."""
        on, off, full_on, full_off = self.channel_registers(channel)
        if self.asleep or self._restart_pending or full_off:
            return 0.0
        tick_us = 1e6 * (self.prescale + 1) / self.oscillator_hz
        if full_on:
            return 4096 * tick_us
        return ((off - on) % 4096) * tick_us

    def pulse_widths_us(self) -> np.ndarray:
        """All 16 channels' pulse widths (us)."""
        return np.array([self.pulse_width_us(channel) for channel in range(self.CHANNELS)])

    # --- device protocol --------------------------------------------------------------------
    def also_answers(self, address: int) -> bool:
        return address == self.allcall_address and bool(self.registers[PCA_MODE1] & PCA_ALLCALL)

    def _any_output_running(self) -> bool:
        return any(not self.channel_registers(channel)[3] for channel in range(self.CHANNELS))

    def _next(self, pointer: int) -> int:
        if not self.auto_increment:
            return pointer
        if pointer == PCA_LAST_LED_REGISTER:
            return 0x00
        if pointer == 0xFF:
            return 0x00
        return (pointer + 1) & 0xFF

    def _write_register(self, register: int, value: int) -> None:
        if register == PCA_MODE1:
            was_asleep = self.asleep
            if value & PCA_RESTART and self._restart_pending and not was_asleep:
                self._restart_pending = False  # writing 1 to RESTART restarts the PWM channels
            self.registers[PCA_MODE1] = value & 0x7F
            if not was_asleep and self.asleep and self._any_output_running():
                self._restart_pending = True
        elif register == PCA_PRE_SCALE:
            if self.asleep:  # PRE_SCALE can only be set while the oscillator is off
                self.registers[PCA_PRE_SCALE] = max(3, value)
        elif PCA_ALL_LED_ON_L <= register <= PCA_ALL_LED_OFF_H:
            offset = register - PCA_ALL_LED_ON_L
            stored = value & 0x1F if offset in (1, 3) else value
            for channel in range(self.CHANNELS):
                self.registers[PCA_LED0_ON_L + 4 * channel + offset] = stored
            self.led_writes += 1
            self._restart_pending = False
        elif PCA_LED0_ON_L <= register <= PCA_LAST_LED_REGISTER:
            offset = (register - PCA_LED0_ON_L) % 4
            self.registers[register] = value & 0x1F if offset in (1, 3) else value
            self.led_writes += 1
            self._restart_pending = False
        elif register in (PCA_MODE2, 0x02, 0x03, 0x04, 0x05):
            self.registers[register] = value
        # 0x46..0xF9 are reserved; 0xFF is the test mode register: writes ignored

    def write(self, data: bytes) -> None:
        if not data:
            return
        self.pointer = data[0]
        for value in data[1:]:
            self._write_register(self.pointer, value)
            self.pointer = self._next(self.pointer)

    def read(self, count: int) -> bytes:
        out = bytearray()
        for _ in range(count):
            if self.pointer == PCA_MODE1:
                out.append(self.mode1)
            elif PCA_ALL_LED_ON_L <= self.pointer <= PCA_ALL_LED_OFF_H:
                out.append(0)
            else:
                out.append(self.registers[self.pointer])
            self.pointer = self._next(self.pointer)
        return bytes(out)


# ------------------------------------------------------------------------------------------------
# The whole servo electronics
# ------------------------------------------------------------------------------------------------


@dataclass
class FakeHardware:
    """Fake bus with the mux, twelve ADC inputs and the PCA9685 wired as in ``hardware_config``."""

    bus: FakeI2CBus
    mux: FakeTca9548a
    adcs: Dict[int, FakeAds1115]
    pca: FakePca9685
    config: Any
    #: The bus's own lock: hold it to change several device states atomically w.r.t. bus traffic.
    lock: Any = field(default_factory=threading.RLock)
    #: The MS5837 depth sensor on the main bus (None when hardware.yaml says none is fitted).
    depth: Optional[FakeMs5837] = None

    def adc(self, mux_channel: int, address: int) -> FakeAds1115:
        """The ADS1115 at ``address`` on mux channel ``mux_channel`` (ValueError if there is none)."""
        device = self.mux.channel_bus(mux_channel).device_at(address)
        if not isinstance(device, FakeAds1115):
            raise ValueError("no ADS1115 at 0x%02x on mux channel %d" % (address, mux_channel))
        return device

    def set_spare_voltage(self, mux_channel: int, address: int, ain: int, volts: float) -> None:
        """Put ``volts`` on input AIN``ain`` of the ADS1115 at ``address`` on ``mux_channel`` (a battery divider)."""
        with self.bus.lock:
            self.adc(mux_channel, address).set_input_voltage(ain, volts)

    @property
    def depth_powered(self) -> bool:
        """False while the depth sensor is off the bus (:meth:`set_depth_power`) or not fitted."""
        with self.bus.lock:
            return self.depth is not None and self.bus.device_at(self.config.depth.address) is self.depth

    def set_depth_power(self, powered: bool) -> None:
        """Cut or restore the depth sensor's supply: unpowered it leaves the bus (every transaction NACKs);
        powered again it answers from its power-on state (no conversion under way)."""
        if self.depth is None:
            raise ValueError("no depth sensor fitted (hardware.yaml depth.fitted false)")
        with self.bus.lock:
            if powered == self.depth_powered:
                return
            self.depth.power_cycle()
            if powered:
                self.bus.attach(self.config.depth.address, self.depth)
            else:
                self.bus.detach(self.config.depth.address)

    def set_joint_voltages(self, volts: Sequence[float]) -> None:
        """Put ``volts[j]`` on joint j's ADC input (12 finite values, JOINT_NAMES order)."""
        values = np.asarray(volts, dtype=float)
        if values.shape != (len(self.config.joints),):
            raise ValueError("expected %d joint voltages, got shape %s" % (len(self.config.joints), values.shape))
        if not np.all(np.isfinite(values)):
            raise ValueError("joint voltages must be finite, got %s" % values)
        with self.bus.lock:
            for joint in self.config.joints:
                self.adcs[joint.index].set_input_voltage(joint.adc_input, float(values[joint.index]))

    def pulse_widths_us(self) -> np.ndarray:
        """Pulse width (us) each joint's servo receives now (0 = no pulses), JOINT_NAMES order."""
        with self.bus.lock:
            return np.array([self.pca.pulse_width_us(joint.pwm_channel) for joint in self.config.joints])

    @property
    def pca_powered(self) -> bool:
        """False while the PCA9685 has lost its supply (:meth:`set_pca_power`)."""
        with self.bus.lock:
            return self.bus.device_at(self.config.pca_address) is self.pca

    def set_pca_power(self, powered: bool) -> None:
        """Cut or restore the PCA9685's supply. Unpowered, the chip leaves the bus (every transaction to
        it NACKs) and produces no pulses (servos limp); powered again, it starts from its power-on reset
        state (asleep, every output off) until its driver configures it again."""
        with self.bus.lock:
            if powered == self.pca_powered:
                return
            self.pca.power_cycle()  # registers lost with the supply; reads as no pulses while off
            if powered:
                self.bus.attach(self.config.pca_address, self.pca)
            else:
                self.bus.detach(self.config.pca_address)


def build_fake_hardware(hardware_config: Any, require_lock: bool = False, log_transactions: bool = True,
                        clock: Callable[[], float] = time.monotonic, seed: int = 0) -> FakeHardware:
    """Build the fake bus, TCA9548A, ADS1115s (one per distinct mux channel/address), PCA9685 and, when
    ``hardware_config.depth.fitted``, the MS5837 (its conversions timed on ``clock``, its noise from ``seed``,
    at the surface pressure and 20 degC until told otherwise).

    Joints that share a mux channel and ADC address share one :class:`FakeAds1115` (different AINs).
    ``log_transactions``: keep every transaction in ``bus.log`` (tests read it). A long-running server
    such as sim_node must turn it off: the drivers make 18 transactions per 10 ms cycle
    (benchmarks/bench_bus_budget.py), so the log grows without bound, and Python's full garbage
    collections of that growing heap stalled the simulated robot for 55 ms every ~48 s
    (docs/sim_timing.md).
    """
    bus = FakeI2CBus(require_lock=require_lock, name="fake-i2c-%d" % hardware_config.i2c_bus)
    bus.log_enabled = log_transactions
    mux = FakeTca9548a()
    bus.attach(hardware_config.mux_address, mux)
    pca = FakePca9685(oscillator_hz=hardware_config.pca_oscillator_hz)
    bus.attach(hardware_config.pca_address, pca)
    adcs: Dict[int, FakeAds1115] = {}
    for joint in hardware_config.joints:
        channel_bus = mux.channel_bus(joint.mux_channel)
        adc = channel_bus.device_at(joint.adc_address)
        if adc is None:
            adc = channel_bus.attach(joint.adc_address, FakeAds1115())
        adcs[joint.index] = adc
    depth = None
    if hardware_config.depth.fitted:
        depth = bus.attach(hardware_config.depth.address,
                           FakeMs5837(hardware_config.depth.ms5837_model, clock=clock, seed=seed,
                                      pressure_pa=hardware_config.depth.surface_pa, temperature_c=20.0))
    return FakeHardware(bus=bus, mux=mux, adcs=adcs, pca=pca, config=hardware_config, lock=bus.lock, depth=depth)


__all__ = ["FakeTca9548a", "FakeAds1115", "FakePca9685", "FakeHardware", "build_fake_hardware", "ads1115_code",
           "ADS_REG_CONVERSION", "ADS_REG_CONFIG", "PCA_MODE1", "PCA_MODE2", "PCA_LED0_ON_L", "PCA_ALL_LED_ON_L",
           "PCA_PRE_SCALE", "PCA_RESTART", "PCA_AI", "PCA_SLEEP", "PCA_ALLCALL", "PCA_FULL"]
