"""Register-level fake of the MS5837-30BA / -02BA depth sensor for :class:`~quadruped_drivers.i2c.fake_bus.FakeI2CBus`.

Attach it at 0x76. Command behaviour follows the data sheets ("COMMANDS", "CONVERSION SEQUENCE"):

* every write's first byte is a command; ``0x1E`` reset (cancels a conversion, clears the result),
  ``0xA0 + 2 n`` selects PROM word n for the next read (2 bytes, MSB first), ``0x40..0x4A`` / ``0x50..0x5A``
  start a D1 / D2 conversion at the OSR of the command (done after the OSR's conversion time x
  ``conversion_scale``), ``0x00`` selects the ADC result for the next read (3 bytes, MSB first);
* reading the ADC before the conversion is finished returns 0 and spoils that conversion ("the conversion
  will not stop and the final result will be wrong"); a repeated ADC read returns 0; a conversion command
  during a conversion also spoils the result; an unknown command is ACKed and ignored (``ignored_commands``).

The raw codes follow :meth:`FakeMs5837.set_state` through the inverse of the datasheet maths
(:func:`~quadruped_drivers.ms5837_datasheet.raw_codes`), plus ``noise_counts`` of uniform noise (a real
chip's codes are never exactly repeated; the driver's stuck-ADC check relies on it).

Faults: NACKs / I/O errors through the bus's ``inject_fault``; :meth:`corrupt_prom` (a PROM word whose CRC no
longer matches), :meth:`stick_adc` (every ADC read returns one code), :meth:`inject_codes` (the next ADC reads
return garbage codes), ``conversion_scale`` > 1 (a chip slower than the data sheet's maximum).
"""
from __future__ import annotations

import math
import random
import threading
import time
from typing import Callable, List, Optional, Sequence

from quadruped_drivers.ms5837_datasheet import (ADC_MAX, CMD_ADC_READ, CMD_CONVERT_D1, CMD_CONVERT_D2, CMD_PROM_READ,
                                                CMD_RESET, CONVERSION_TIME_MAX, OSR_OFFSET, PROM_WORDS, TYPICAL_PROM,
                                                Calibration, Model, raw_codes)

_OSR_BY_OFFSET = {offset: osr for osr, offset in OSR_OFFSET.items()}
#: Conversions finish at this fraction of the data sheet's maximum time (about the typical time).
TYPICAL_FRACTION = 0.91


class FakeMs5837:
    """MS5837 with a configurable PROM (the data sheet's typical one, valid CRC, by default)."""

    def __init__(self, model: Model = Model.BA30, prom: Optional[Sequence[int]] = None,
                 clock: Callable[[], float] = time.monotonic, pressure_pa: float = 101325.0,
                 temperature_c: float = 20.0, noise_counts: int = 16, seed: int = 0) -> None:
        self.model = model
        self.prom: List[int] = list(prom if prom is not None else TYPICAL_PROM[model])
        if len(self.prom) != PROM_WORDS:
            raise ValueError("the MS5837 PROM has 7 words, got %d" % len(self.prom))
        # The chip's own arithmetic uses the PROM as programmed (the CRC is not checked by the chip).
        word0 = self.prom[0]
        self._calibration = Calibration(self.prom[1], self.prom[2], self.prom[3], self.prom[4], self.prom[5],
                                        self.prom[6], word0 >> 12, (word0 >> 5) & 0x7F, word0 & 0x1F)
        self._clock = clock
        self._rng = random.Random(seed)
        self.noise_counts = int(noise_counts)
        self.conversion_scale = 1.0
        self.lock = threading.RLock()
        self.commands: List[int] = []
        self.ignored_commands = 0
        self.early_reads = 0
        self.resets = 0
        self._stuck: Optional[int] = None
        self._garbage: List[int] = []
        self._pointer: Optional[int] = None  # PROM word index, or "adc" via _adc_selected
        self._adc_selected = False
        self._converting: Optional[str] = None  # "D1"/"D2"
        self._done_at = math.inf
        self._spoiled = False
        self._result = 0  # 0: nothing to read
        self.set_state(pressure_pa, temperature_c)

    # --- simulation side ---------------------------------------------------------------------------
    def set_state(self, pressure_pa: float, temperature_c: float) -> None:
        """The absolute pressure (Pa) and temperature (degC) the next conversions measure."""
        d1, d2 = raw_codes(float(pressure_pa), float(temperature_c), self._calibration, self.model)
        with self.lock:
            self.pressure_pa, self.temperature_c = float(pressure_pa), float(temperature_c)
            self._codes = {"D1": d1, "D2": d2}

    def power_cycle(self) -> None:
        """Lose the supply and get it back: no conversion under way, no result, nothing selected."""
        with self.lock:
            self._converting, self._result, self._spoiled = None, 0, False
            self._adc_selected, self._pointer = False, None

    def corrupt_prom(self, index: int = 3, xor: int = 0x0100) -> None:
        """Flip bits of PROM word ``index`` (its CRC then no longer matches)."""
        with self.lock:
            self.prom[index] ^= xor & 0xFFFF

    def stick_adc(self, code: Optional[int]) -> None:
        """Every ADC read returns ``code`` (24-bit) from now on; None: back to normal."""
        if code is not None and not 0 <= code <= ADC_MAX:
            raise ValueError("ADC codes are 24-bit, got %r" % (code,))
        self._stuck = code

    def inject_codes(self, codes: Sequence[int]) -> None:
        """The next ADC reads (one per code) return ``codes`` instead of the conversion results."""
        for code in codes:
            if not 0 <= int(code) <= ADC_MAX:
                raise ValueError("ADC codes are 24-bit, got %r" % (code,))
        with self.lock:
            self._garbage = [int(code) for code in codes]

    # --- chip side ----------------------------------------------------------------------------------
    def _finish(self, now: float) -> None:
        if self._converting is not None and now >= self._done_at:
            code = self._codes[self._converting]
            if self.noise_counts:
                code += self._rng.randint(-self.noise_counts, self.noise_counts)
            if self._spoiled:
                code ^= self._rng.randrange(1, 1 << 16)
            self._result = max(0, min(ADC_MAX, code))
            self._converting, self._spoiled = None, False

    def write(self, data: bytes) -> None:
        if not data:
            return  # address probe
        command = data[0]
        with self.lock:
            now = self._clock()
            self._finish(now)
            self.commands.append(command)
            self._adc_selected, self._pointer = False, None
            if command == CMD_RESET:
                self.resets += 1
                self._converting, self._result, self._spoiled = None, 0, False
            elif command & 0xF1 == CMD_PROM_READ:
                self._pointer = (command >> 1) & 0x7
            elif command == CMD_ADC_READ:
                self._adc_selected = True
            elif command & 0xE0 == 0x40 and (command & 0x0F) in _OSR_BY_OFFSET and command & 0xF0 in (
                    CMD_CONVERT_D1, CMD_CONVERT_D2):
                if self._converting is not None:
                    self._spoiled = True  # a conversion command during a conversion: a wrong result
                osr = _OSR_BY_OFFSET[command & 0x0F]
                self._converting = "D1" if command & 0xF0 == CMD_CONVERT_D1 else "D2"
                self._done_at = now + CONVERSION_TIME_MAX[osr] * TYPICAL_FRACTION * self.conversion_scale
                self._result = 0
            else:
                self.ignored_commands += 1

    def read(self, count: int) -> bytes:
        with self.lock:
            now = self._clock()
            self._finish(now)
            if self._adc_selected:
                self._adc_selected = False
                if self._garbage:
                    value = self._garbage.pop(0)
                elif self._stuck is not None:
                    value = self._stuck
                elif self._converting is not None:
                    self.early_reads += 1
                    self._spoiled = True
                    value = 0
                else:
                    value, self._result = self._result, 0  # a repeated read gives 0
                data = value.to_bytes(3, "big")
            elif self._pointer is not None:
                word = self.prom[self._pointer] if self._pointer < PROM_WORDS else 0
                data = word.to_bytes(2, "big")
            else:
                data = b""
            return (data + b"\x00" * count)[:count]


__all__ = ["FakeMs5837", "TYPICAL_FRACTION"]
