"""MS5837 pressure sensor (Blue Robotics Bar30 = MS5837-30BA, Bar02 = MS5837-02BA): the datasheet maths, no I/O.

This module is what both the driver (:mod:`quadruped_drivers.ms5837`) and the register-level fake
(:mod:`quadruped_drivers.i2c.fake_ms5837`) need from the datasheets; it imports nothing from the I2C
package so that the fake (inside ``quadruped_drivers.i2c``) can use it without an import circle
(``.importlinter`` "No import circle").

Sources (TE Connectivity data sheets as shipped by Blue Robotics):

* MS5837-30BA, "Ultra Small Gel Filled Pressure Sensor", 10/11/2015 and REV C2 12/2019: "COMMANDS"
  (command byte table), "CONVERSION SEQUENCE" (ADC read of an unfinished or repeated conversion returns
  0), "Version PROM Word 0 programming" (bits [11:5] of word 0 = 0011010 for the 30BA26), "PRESSURE AND
  TEMPERATURE CALCULATION" (flow chart and typical values, reproduced by the tests).
* MS5837-02BA, "Ultra Small Gel Filled Pressure & Temperature Sensor", 09/2017: the same sections, and
  "CYCLIC REDUNDANCY CHECK (CRC)" (PROM map: CRC in bits [15:12] of word 0, C code of ``crc4``).

NOT yet checked against the PDFs (their pages were not in reach when this was written): the second-order
temperature compensation's coefficients (as the flow chart "SECOND ORDER TEMPERATURE COMPENSATION" is
remembered; the low-temperature terms agree with a third-party driver) and the maximum conversion times (the
sister MS5611's published figures). Check both against the data sheet before trusting readings below 20 degC.

Integer arithmetic follows the flow charts; a division by 2^n is a floor division (an arithmetic right
shift), which is what reproduces the data sheets' typical values (30BA: TEMP = 1981, SENS = 1145816755;
C's truncating ``/`` would give TEMP = 1982).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Dict, Sequence, Tuple

#: 7-bit I2C address (both data sheets: 1110110x).
ADDRESS = 0x76

# --- commands ("COMMANDS", command byte table) ------------------------------------------------------
CMD_RESET = 0x1E
CMD_ADC_READ = 0x00
CMD_PROM_READ = 0xA0  # + 2 * word address: 0xA0 .. 0xAC for the 7 words (0xAE: unused 8th word)
CMD_CONVERT_D1 = 0x40  # uncompensated pressure, + OSR offset
CMD_CONVERT_D2 = 0x50  # uncompensated temperature, + OSR offset
#: OSR -> offset added to CMD_CONVERT_D1 / CMD_CONVERT_D2 (bits Os2..Os0 << 1).
OSR_OFFSET: Dict[int, int] = {256: 0x0, 512: 0x2, 1024: 0x4, 2048: 0x6, 4096: 0x8, 8192: 0xA}
#: OSR -> maximum ADC conversion time in seconds (the MS5611's figures: to be checked, module docstring).
CONVERSION_TIME_MAX: Dict[int, float] = {256: 0.60e-3, 512: 1.17e-3, 1024: 2.28e-3, 2048: 4.54e-3,
                                         4096: 9.04e-3, 8192: 18.08e-3}
#: Wait after the reset command before talking to the chip (PROM reload; a few ms, with margin).
RESET_WAIT = 0.010
PROM_WORDS = 7
ADC_MAX = (1 << 24) - 1
#: PROM word 0 bits [11:5] of the MS5837-30BA26 (30BA data sheet, "Version PROM Word 0 programming").
PRODUCT_VERSION_30BA26 = 0b0011010


class Model(enum.Enum):
    """The two MS5837 variants Blue Robotics sells."""

    BA30 = "30BA"  # Bar30: 0..30 bar, P in 0.1 mbar
    BA02 = "02BA"  # Bar02: 0.3..1.2 bar (0.01..2 bar extended), P in 0.01 mbar


@dataclass(frozen=True)
class ModelSpec:
    """Per-variant constants of the first-order calculation and the plausible ranges."""

    off_shift: int  # OFF = C2 * 2^off_shift + C4 * dT / 2^tco_shift
    tco_shift: int
    sens_shift: int  # SENS = C1 * 2^sens_shift + C3 * dT / 2^tcs_shift
    tcs_shift: int
    p_shift: int  # P = (D1 * SENS / 2^21 - OFF) / 2^p_shift
    pa_per_count: float  # 0.1 mbar = 10 Pa (30BA), 0.01 mbar = 1 Pa (02BA)
    rated_pa: Tuple[float, float]  # operating pressure range of the data sheet
    plausible_pa: Tuple[float, float]  # rated range with a margin: outside it a reading is implausible


SPECS: Dict[Model, ModelSpec] = {
    Model.BA30: ModelSpec(16, 7, 15, 8, 13, 10.0, (0.0, 30e5), (0.0, 31.5e5)),
    Model.BA02: ModelSpec(17, 6, 16, 7, 15, 1.0, (0.3e5, 1.2e5), (0.27e5, 2.1e5)),
}
#: Operating temperature range of both variants (front page: -20 .. +85 degC).
RATED_TEMPERATURE_C = (-20.0, 85.0)


class PromCrcError(ValueError):
    """The PROM's CRC-4 does not match its contents (a bad read or a damaged chip)."""

    def __init__(self, expected: int, read: int, words: Sequence[int]) -> None:
        self.expected = expected
        self.read = read
        self.words = tuple(words)
        super().__init__("MS5837 PROM CRC mismatch: computed 0x%X from the words, PROM word 0 holds 0x%X "
                         "(words %s); refusing the calibration"
                         % (expected, read, " ".join("0x%04X" % word for word in words)))


def crc4(prom_words: Sequence[int]) -> int:
    """The PROM's 4-bit CRC (datasheet "CYCLIC REDUNDANCY CHECK", C code ``crc4``).

    ``prom_words``: the 7 PROM words (an 8th is ignored: the data sheet sets it to 0). The CRC bits
    [15:12] of word 0 are cleared before the computation, so a PROM with its CRC in place may be passed.
    Polynomial 0x3000 on a 16-bit remainder, 16 bytes MSB first; the result is bits [15:12] of it.
    """
    if len(prom_words) not in (PROM_WORDS, PROM_WORDS + 1):
        raise ValueError("crc4 needs the 7 PROM words, got %d" % len(prom_words))
    words = [int(word) & 0xFFFF for word in prom_words[:PROM_WORDS]] + [0]
    words[0] &= 0x0FFF
    remainder = 0
    for index in range(16):
        word = words[index >> 1]
        remainder ^= (word & 0x00FF) if index % 2 else (word >> 8)
        for _ in range(8):
            if remainder & 0x8000:
                remainder = ((remainder << 1) ^ 0x3000) & 0xFFFF
            else:
                remainder = (remainder << 1) & 0xFFFF
    return (remainder >> 12) & 0xF


def with_crc(prom_words: Sequence[int]) -> Tuple[int, ...]:
    """``prom_words`` (7) with the correct CRC written into bits [15:12] of word 0."""
    words = [int(word) & 0xFFFF for word in prom_words]
    words[0] = (words[0] & 0x0FFF) | (crc4(words) << 12)
    return tuple(words)


@dataclass(frozen=True)
class Calibration:
    """Factory calibration C1..C6 from a CRC-checked PROM, plus word 0's product version and factory bits."""

    c1: int  # pressure sensitivity SENS_T1
    c2: int  # pressure offset OFF_T1
    c3: int  # temperature coefficient of pressure sensitivity TCS
    c4: int  # temperature coefficient of pressure offset TCO
    c5: int  # reference temperature T_REF
    c6: int  # temperature coefficient of the temperature TEMPSENS
    crc: int
    version: int  # word 0 bits [11:5]
    factory: int  # word 0 bits [4:0]

    @classmethod
    def from_prom(cls, words: Sequence[int]) -> "Calibration":
        """Check the CRC-4 of the 7 PROM ``words`` and decode them; :class:`PromCrcError` if it fails."""
        if len(words) != PROM_WORDS:
            raise ValueError("the MS5837 PROM has 7 words, got %d" % len(words))
        for word in words:
            if isinstance(word, bool) or not isinstance(word, int) or not 0 <= word <= 0xFFFF:
                raise ValueError("PROM words are 16-bit unsigned integers, got %r" % (word,))
        expected, read = crc4(words), words[0] >> 12
        if expected != read:
            raise PromCrcError(expected, read, words)
        return cls(words[1], words[2], words[3], words[4], words[5], words[6], read,
                   (words[0] >> 5) & 0x7F, words[0] & 0x1F)

    @property
    def words(self) -> Tuple[int, ...]:
        """The 7 PROM words this calibration was decoded from."""
        word0 = (self.crc << 12) | (self.version << 5) | self.factory
        return (word0, self.c1, self.c2, self.c3, self.c4, self.c5, self.c6)


@dataclass(frozen=True)
class Compensation:
    """Every intermediate of the calculation, in the data sheet's integer units."""

    dT: int  # noqa: N815 - the data sheet's names
    TEMP: int  # noqa: N815  first order, 0.01 degC
    OFF: int  # noqa: N815
    SENS: int  # noqa: N815
    P: int  # noqa: N815  first order, 0.1 mbar (30BA) / 0.01 mbar (02BA)
    Ti: int  # noqa: N815
    OFFi: int  # noqa: N815
    SENSi: int  # noqa: N815
    TEMP2: int  # noqa: N815  second order
    P2: int  # noqa: N815  second order


def compensation(d1: int, d2: int, calibration: Calibration, model: Model) -> Compensation:
    """First- and second-order calculation from the raw conversions (both data sheets' flow charts)."""
    for name, value in (("D1", d1), ("D2", d2)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= ADC_MAX:
            raise ValueError("%s must be a 24-bit unsigned integer, got %r" % (name, value))
    spec = SPECS[model]
    c = calibration
    # dT: difference between actual and reference temperature, dT = D2 - C5 * 2^8
    dT = d2 - c.c5 * 256  # noqa: N806
    # TEMP: actual temperature, TEMP = 2000 + dT * C6 / 2^23 (0.01 degC)
    TEMP = 2000 + (dT * c.c6 >> 23)  # noqa: N806
    # OFF: offset at actual temperature, OFF = C2 * 2^16 + C4 * dT / 2^7 (30BA); C2 * 2^17 + C4 * dT / 2^6 (02BA)
    OFF = (c.c2 << spec.off_shift) + (c.c4 * dT >> spec.tco_shift)  # noqa: N806
    # SENS: sensitivity at actual temperature, SENS = C1 * 2^15 + C3 * dT / 2^8 (30BA); C1 * 2^16 + C3 * dT / 2^7 (02BA)
    SENS = (c.c1 << spec.sens_shift) + (c.c3 * dT >> spec.tcs_shift)  # noqa: N806
    # P: temperature compensated pressure, P = (D1 * SENS / 2^21 - OFF) / 2^13 (30BA); / 2^15 (02BA)
    P = ((d1 * SENS >> 21) - OFF) >> spec.p_shift  # noqa: N806
    # Second order temperature compensation (flow chart "SECOND ORDER TEMPERATURE COMPENSATION")
    low = TEMP - 2000
    if model is Model.BA30:
        if TEMP < 2000:
            # low temperature: Ti = 3 dT^2 / 2^33, OFFi = 3 (TEMP-2000)^2 / 2, SENSi = 5 (TEMP-2000)^2 / 2^3
            Ti = 3 * dT * dT >> 33  # noqa: N806
            OFFi = 3 * low * low >> 1  # noqa: N806
            SENSi = 5 * low * low >> 3  # noqa: N806
            if TEMP < -1500:
                # very low temperature: OFFi += 7 (TEMP+1500)^2, SENSi += 4 (TEMP+1500)^2
                very = TEMP + 1500
                OFFi += 7 * very * very  # noqa: N806
                SENSi += 4 * very * very  # noqa: N806
        else:
            # high temperature: Ti = 2 dT^2 / 2^37, OFFi = (TEMP-2000)^2 / 2^4, SENSi = 0
            Ti = 2 * dT * dT >> 37  # noqa: N806
            OFFi = low * low >> 4  # noqa: N806
            SENSi = 0  # noqa: N806
    else:
        if TEMP < 2000:
            # low temperature: Ti = 11 dT^2 / 2^35, OFFi = 31 (TEMP-2000)^2 / 2^3, SENSi = 63 (TEMP-2000)^2 / 2^5
            Ti = 11 * dT * dT >> 35  # noqa: N806
            OFFi = 31 * low * low >> 3  # noqa: N806
            SENSi = 63 * low * low >> 5  # noqa: N806
        else:
            # high temperature: no correction
            Ti = OFFi = SENSi = 0  # noqa: N806
    # OFF2 = OFF - OFFi, SENS2 = SENS - SENSi, TEMP2 = TEMP - Ti, P2 = (D1 * SENS2 / 2^21 - OFF2) / 2^13 (2^15)
    TEMP2 = TEMP - Ti  # noqa: N806
    P2 = ((d1 * (SENS - SENSi) >> 21) - (OFF - OFFi)) >> spec.p_shift  # noqa: N806
    return Compensation(dT, TEMP, OFF, SENS, P, Ti, OFFi, SENSi, TEMP2, P2)


def compensate(d1: int, d2: int, calibration: Calibration, model: Model,
               second_order: bool = True) -> Tuple[float, float]:
    """(pressure in Pa, temperature in degC) from the raw D1 (pressure) and D2 (temperature) conversions."""
    result = compensation(d1, d2, calibration, model)
    pressure, temperature = (result.P2, result.TEMP2) if second_order else (result.P, result.TEMP)
    return pressure * SPECS[model].pa_per_count, temperature / 100.0


def depth_m(pressure_pa: float, surface_pa: float, density: float, g: float = 9.80665) -> float:
    """Depth below the surface (m) from the absolute pressure: hydrostatic (p - p_surface) / (rho g)."""
    if not (math.isfinite(density) and density > 0.0 and math.isfinite(g) and g > 0.0):
        raise ValueError("density and g must be positive, got %r and %r" % (density, g))
    if not math.isfinite(surface_pa):
        raise ValueError("surface pressure must be finite, got %r" % (surface_pa,))
    return (pressure_pa - surface_pa) / (density * g)


def osr_commands(osr: int) -> Tuple[int, int, float]:
    """(D1 command, D2 command, maximum conversion time in s) for oversampling ratio ``osr``."""
    if osr not in OSR_OFFSET:
        raise ValueError("OSR must be one of %s, got %r" % (sorted(OSR_OFFSET), osr))
    return CMD_CONVERT_D1 + OSR_OFFSET[osr], CMD_CONVERT_D2 + OSR_OFFSET[osr], CONVERSION_TIME_MAX[osr]


def _bisect(function, target: float, low: int, high: int) -> int:  # type: ignore[no-untyped-def]
    """Smallest integer x in [low, high] with function(x) >= target (function non-decreasing); clamps."""
    if function(high) < target:
        return high
    while low < high:
        middle = (low + high) // 2
        if function(middle) >= target:
            high = middle
        else:
            low = middle + 1
    return low


def raw_codes(pressure_pa: float, temperature_c: float, calibration: Calibration,
              model: Model) -> Tuple[int, int]:
    """(D1, D2) that :func:`compensate` (second order) maps to ``pressure_pa`` / ``temperature_c``
    (within one count; saturated at the ADC's 1 .. 2^24-1), by bisection: the inverse the fake needs."""
    if not (math.isfinite(pressure_pa) and math.isfinite(temperature_c)):
        raise ValueError("pressure and temperature must be finite")
    d2 = _bisect(lambda code: compensate(1, code, calibration, model)[1], temperature_c, 1, ADC_MAX)
    d1 = _bisect(lambda code: compensate(code, d2, calibration, model)[0], pressure_pa, 1, ADC_MAX)
    return d1, d2


#: The data sheets' typical calibration ("Example / Typical" column); word 0 = version bits, CRC filled in.
TYPICAL_PROM: Dict[Model, Tuple[int, ...]] = {
    Model.BA30: with_crc((PRODUCT_VERSION_30BA26 << 5, 34982, 36352, 20328, 22354, 26646, 26146)),
    Model.BA02: with_crc((0x0000, 46372, 43981, 29059, 27842, 31553, 28165)),
}

__all__ = ["ADDRESS", "ADC_MAX", "CMD_ADC_READ", "CMD_CONVERT_D1", "CMD_CONVERT_D2", "CMD_PROM_READ", "CMD_RESET",
           "CONVERSION_TIME_MAX", "Calibration", "Compensation", "Model", "ModelSpec", "OSR_OFFSET",
           "PRODUCT_VERSION_30BA26", "PROM_WORDS", "PromCrcError", "RATED_TEMPERATURE_C", "RESET_WAIT", "SPECS",
           "TYPICAL_PROM", "compensate", "compensation", "crc4", "depth_m", "osr_commands", "raw_codes", "with_crc"]
