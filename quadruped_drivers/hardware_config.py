"""Typed loader for ``config/hardware.yaml``: I2C bus, addresses, mux channels, servo channel order, and the
safety sensors: the MS5837 depth sensor (``depth``), the LiPo packs read on spare ADS1115 inputs
(``batteries``) and the leak probe on a Jetson GPIO pin (``leak``).

The paper (section "Electronics") reads twelve ADS1115 ADCs for the servo feedback and drives the
twelve servos through PWM at 100 Hz control rate; this file fixes how those parts sit on the Jetson's
I2C bus. Joints are listed in :data:`quadruped_common.robot.JOINT_NAMES` order
(``leg{1..4}_{motor1,motor2,hip}`` = theta1, theta2, theta3 of eq. ik_theta3 / ik_theta1245).

Every parameter is declared once, in :data:`HARDWARE_SCHEMA` (docs/configuration.md shows it). Loading
never returns a half-valid object: a missing or unknown key, a duplicate channel or address, an address
clash or a value out of range raises :class:`~quadruped_common.config.ParameterError` naming the key.
"""
from __future__ import annotations

import dataclasses

import math
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, load_config
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.schema import Param, Schema
from quadruped_drivers.ms5837_datasheet import ADDRESS as MS5837_ADDRESS, CONVERSION_TIME_MAX, OSR_OFFSET, Model

#: Failsafe actions of a PWM channel when the command watchdog trips.
FAILSAFE_ACTIONS: Tuple[str, ...] = ("hold", "neutral", "off")

#: ADS1115 programmable-gain full-scale ranges (V) and their PGA field values (config bits 11:9).
ADS1115_FSR_PGA: Dict[float, int] = {6.144: 0, 4.096: 1, 2.048: 2, 1.024: 3, 0.512: 4, 0.256: 5}
#: ADS1115 data rates (samples/s) and their DR field values (config bits 7:5).
ADS1115_RATES: Dict[int, int] = {8: 0, 16: 1, 32: 2, 64: 3, 128: 4, 250: 5, 475: 6, 860: 7}
#: ADS1115 addresses selectable by its ADDR pin (GND, VDD, SDA, SCL).
ADS1115_ADDRESSES: Tuple[int, ...] = (0x48, 0x49, 0x4A, 0x4B)
#: The PCA9685 answers its LED all-call address at power-up (MODE1.ALLCALL = 1).
PCA9685_ALLCALL_ADDRESS = 0x70
#: Servo pulse widths that no configuration may exceed (us).
ABSOLUTE_MIN_US = 400.0
ABSOLUTE_MAX_US = 2600.0


def _ads1115_range(value: float) -> Optional[str]:
    return None if value in ADS1115_FSR_PGA else "not an ADS1115 range %s" % sorted(ADS1115_FSR_PGA)


def _ads1115_rate(value: int) -> Optional[str]:
    return None if value in ADS1115_RATES else "not an ADS1115 rate %s" % sorted(ADS1115_RATES)


def _ms5837_osr(value: int) -> Optional[str]:
    return None if value in OSR_OFFSET else "not an MS5837 oversampling ratio %s" % sorted(OSR_OFFSET)


#: ``depth.model`` -> the MS5837 variant (Blue Robotics Bar30 = MS5837-30BA, Bar02 = MS5837-02BA).
DEPTH_MODELS: Dict[str, Model] = {"bar30": Model.BA30, "bar02": Model.BA02}
#: Highest OSR each variant has a conversion command for: the 30BA's command table ("COMMANDS", Figure 1 of
#: REV C2 12/2019) ends at OSR 4096; the 02BA's lists 8192.
DEPTH_MAX_OSR: Dict[str, int] = {"bar30": 4096, "bar02": 8192}
#: The two LiPo packs (``batteries.packs.<pack>``): servos (2S) and electronics (4S).
BATTERY_PACKS: Tuple[str, ...] = ("motors", "electronics")
#: A LiPo cell's highest voltage (fully charged 4.20 V, with margin): the divider must keep a full pack inside
#: the ADC's range, and a reading above it is implausible (wrong cell count or divider).
LIPO_MAX_CELL_V = 4.35

#: One joint's entry in ``joints``, in the order of :class:`JointHardware`.
_JOINT_FIELDS = ("pwm_channel", "mux_channel", "adc_address", "adc_input", "min_us", "max_us", "neutral_us",
                 "failsafe")
_PULSE = dict(low=ABSOLUTE_MIN_US, high=ABSOLUTE_MAX_US)
#: ``config/hardware.yaml``: how the servo electronics sit on the Jetson's I2C bus (integers in decimal:
#: 0x40 = 64, 0x48..0x4B = 72..75, 0x70..0x77 = 112..119).
HARDWARE_SCHEMA = Schema("hardware.yaml", (
    Param("i2c.bus", "", "Linux I2C bus /dev/i2c-N of the servo electronics (Jetson Orin NX devkit header pins "
          "3/5 = 7, pins 27/28 = 1)", 0, 255, kind="integer", source="estimate"),
    Param("i2c.lock_timeout_s", "s", "longest wait for another user of the bus to release it before a cycle "
          "gives up", 0.0, 1.0),
    Param("mux.address", "", "TCA9548A address, 0x71..0x77 (0x70 is refused: the PCA9685 answers it as its "
          "all-call address at power-up)", 0x70, 0x77, kind="integer"),
    Param("mux.deselect_after_read", "", "true: deselect the mux channel after each read; false: leave it "
          "selected between cycles (one transaction less per cycle)", kind="boolean"),
    Param("pca9685.address", "", "PCA9685 address (not the mux's, an ADS1115's 0x48..0x4B or 0x70)", 0x40, 0x7F,
          kind="integer"),
    Param("pca9685.frequency_hz", "Hz", "servo PWM frame rate; PRE_SCALE = round(oscillator / (4096 f)) - 1 must "
          "lie in 3..255", 24.0, 400.0),
    Param("pca9685.oscillator_hz", "Hz", "PCA9685 internal oscillator (nominal 25 MHz; measure a pulse to "
          "correct it)", 20e6, 30e6, source="estimate"),
    Param("pca9685.stagger_outputs", "", "spread the 16 outputs' rising edges over the period (lower peak "
          "current; widths unchanged)", kind="boolean"),
    Param("pca9685.watchdog_timeout_s", "s", "no command for this long: each channel's failsafe is applied once "
          "(pwm_node watchdog)", 0.001, 10.0),
    Param("adc.full_scale_v", "V", "ADS1115 PGA full-scale range +-V, one of 0.256, 0.512, 1.024, 2.048, 4.096, "
          "6.144", 0.256, 6.144, check=_ads1115_range),
    Param("adc.data_rate_sps", "1/s", "ADS1115 continuous conversion rate, one of 8, 16, 32, 64, 128, 250, 475, "
          "860", 8, 860, kind="integer", check=_ads1115_rate),
    Param("adc.stale_after_s", "s", "a previous sample may stand in for a missing one this long", 0.0, 10.0),
    Param("adc.failed_after_s", "s", "a joint without a good sample this long is failed, not stale (> "
          "stale_after_s)", 0.0, 60.0),
    Param("adc.plausible_margin_deg", "deg", "a reading further than this outside the angles of the joint's "
          "min_us..max_us is stale, never fresh", 0.0, 90.0),
    Param("adc.jump_margin_deg", "deg", "a reading further from the last good angle than no-load speed x elapsed "
          "time + this is stale, never fresh", 0.0, 90.0, source="choice"),
    Param("adc.jump_confirm_readings", "", "... unless this many consecutive readings agree: then the new angle "
          "is accepted", 1, 100, kind="integer"),
    Param("joints.<joint>.pwm_channel", "", "PCA9685 output driving the joint's servo (each used once)", 0, 15,
          kind="integer"),
    Param("joints.<joint>.mux_channel", "", "TCA9548A channel of the joint's feedback ADS1115", 0, 7,
          kind="integer"),
    Param("joints.<joint>.adc_address", "", "address of the joint's ADS1115, 0x48..0x4B (one ADC per joint)",
          0x48, 0x4B, kind="integer"),
    Param("joints.<joint>.adc_input", "", "ADS1115 input the feedback potentiometer is wired to", 0, 3,
          kind="integer"),
    Param("joints.<joint>.min_us", "us", "hard lower pulse limit (every command is clamped into min_us..max_us)",
          source="estimate", **_PULSE),
    Param("joints.<joint>.max_us", "us", "hard upper pulse limit (> min_us, < the PWM period)", source="estimate",
          **_PULSE),
    Param("joints.<joint>.neutral_us", "us", "pulse of the 'neutral' failsafe (mid travel; within min_us..max_us)",
          **_PULSE),
    Param("joints.<joint>.failsafe", "", "on a command timeout: hold the last pulse, go to neutral_us, or off "
          "(servo limp)", kind="string", choices=FAILSAFE_ACTIONS),
    Param("depth.fitted", "", "an MS5837 depth sensor (Blue Robotics Bar30 / Bar02) is wired to the bus; false: "
          "ms5837_node reports it not fitted and sim_node puts no fake sensor on its bus", kind="boolean"),
    Param("depth.model", "", "bar30 (MS5837-30BA, 0..30 bar) or bar02 (MS5837-02BA, 0.3..1.2 bar: 10 m of water)",
          kind="string", choices=tuple(DEPTH_MODELS), default="bar30", source="estimate"),
    Param("depth.address", "", "7-bit I2C address (the data sheets' 1110110x = 0x76, the only one the chip has; "
          "not the mux's, the PCA9685's or 0x70)", 0x08, 0x77, kind="integer", default=MS5837_ADDRESS),
    Param("depth.mux_channel", "", "-1: on the Jetson's I2C bus directly; 0..7: behind the TCA9548A on that channel "
          "(refused while servo_feedback_node owns the mux: two processes switching one mux read each other's "
          "channels)", -1, 7, kind="integer", default=-1),
    Param("depth.rate_hz", "Hz", "readings per second (each is a D1 and a D2 conversion: 2 x the OSR's conversion "
          "time must fit in 0.9 / (2 rate))", 0.0, 50.0, low_open=True, default=10.0, source="choice"),
    Param("depth.osr", "", "oversampling ratio of both conversions, one of 256, 512, 1024, 2048, 4096, 8192 "
          "(bar02 only)", 256, 8192, kind="integer", default=4096, check=_ms5837_osr, source="choice"),
    Param("depth.fluid_density_kg_m3", "kg/m^3", "density of the water above the sensor: depth = (p - surface) / "
          "(rho g); fresh water 997 (the tank), sea water about 1025", 900.0, 1100.0, default=997.0,
          source="estimate"),
    Param("depth.surface_pa", "Pa", "absolute pressure at the water surface (standard atmosphere 101325; "
          "weather moves it by +-3 kPa = +-0.3 m)", 80000.0, 110000.0, default=101325.0, source="estimate"),
    Param("depth.zero_at_start", "", "true: the mean of the first fresh readings is the surface pressure (power "
          "the robot at the surface), kept on the parameter server for a restarted node; false: surface_pa",
          kind="boolean", default=False, source="choice"),
    Param("depth.zero_max_offset_pa", "Pa", "zero_at_start refuses a start pressure further than this from "
          "surface_pa (the robot already under water) and keeps surface_pa", 0.0, 20000.0, default=3000.0,
          source="choice"),
    Param("depth.pressure_stddev_pa", "Pa", "standard deviation of a pressure reading (the published variances; "
          "the 30BA data sheet's front page: 0.2 mbar = 20 Pa resolution at its best OSR)", 0.0, 10000.0,
          low_open=True, default=30.0, source="estimate"),
    Param("depth.timeout_s", "s", "no fresh reading for this long: health/depth ERROR (at least 2 / rate_hz)",
          0.0, 60.0, low_open=True, default=1.0, source="choice"),
    Param("depth.warn_window_s", "s", "a reading dropped (not fresh) this recently: health/depth WARN", 0.0, 600.0,
          default=2.0, source="choice"),
    Param("depth.max_rate_m_s", "m/s", "a depth change faster than this (+ 5 cm) since the last good reading is "
          "not fresh until 3 readings agree (the driver's rate check)", 0.0, 20.0, low_open=True, default=2.0,
          source="choice"),
    Param("batteries.rate_hz", "Hz", "each fitted pack is read this often; each read lends one feedback cycle of "
          "its ADS1115 (that joint then repeats its previous angle once)", 0.0, 10.0, low_open=True, default=2.0,
          source="choice"),
    Param("batteries.stale_after_s", "s", "a fitted pack without a reading for this long: health/battery ERROR "
          "(at least 2 / rate_hz)", 0.0, 60.0, low_open=True, default=2.0, source="choice"),
    Param("batteries.confirm_readings", "", "readings in a row below a threshold before the level gets worse (a "
          "single sag under a load peak is not a flat pack)", 1, 20, kind="integer", default=2, source="choice"),
    Param("batteries.packs.<pack>.fitted", "", "the pack's voltage divider is wired to the ADS1115 input below",
          kind="boolean"),
    Param("batteries.packs.<pack>.mux_channel", "", "TCA9548A channel of the ADS1115 (one of the joints' ADCs)",
          0, 7, kind="integer", source="estimate"),
    Param("batteries.packs.<pack>.adc_address", "", "address of that ADS1115, 0x48..0x4B", 0x48, 0x4B,
          kind="integer", source="estimate"),
    Param("batteries.packs.<pack>.adc_input", "", "its spare input (not the joint's, not the other pack's)", 0, 3,
          kind="integer", source="estimate"),
    Param("batteries.packs.<pack>.divider_ratio", "", "pack voltage / ADC input voltage; a full pack (cells x "
          "4.35 V) must stay inside adc.full_scale_v and below the ADS1115's supply", 1.0, 100.0,
          source="estimate"),
    Param("batteries.packs.<pack>.cells", "", "LiPo cells in series (2S motors, 4S electronics)", 1, 12,
          kind="integer"),
    Param("batteries.packs.<pack>.warn_cell_v", "V", "mean cell voltage below which the pack is WARN", 3.0, 4.2,
          default=3.6, source="choice"),
    Param("batteries.packs.<pack>.critical_cell_v", "V", "mean cell voltage below which the pack is ERROR (below "
          "warn_cell_v)", 2.8, 4.2, default=3.4, source="choice"),
    Param("batteries.packs.<pack>.hysteresis_v", "V", "a level is left only once the cell voltage is this far above "
          "its threshold", 0.0, 0.5, default=0.1, source="choice"),
    Param("leak.fitted", "", "a leak probe (e.g. Blue Robotics' SOS Leak Sensor) is wired to a Jetson header pin; "
          "false: leak_node publishes health/leak OK \"not fitted\"", kind="boolean", default=False),
    Param("leak.pin", "", "the probe's signal on the 40-pin header, BOARD numbering (Jetson.GPIO)", 1, 40,
          kind="integer", default=15, source="estimate"),
    Param("leak.active_high", "", "true: the signal is high when water bridges the probe (the SOS sensor's); false: "
          "low", kind="boolean", default=True, source="estimate"),
    Param("leak.rate_hz", "Hz", "the pin is read this often", 0.0, 100.0, low_open=True, default=10.0,
          source="choice"),
    Param("leak.confirm_readings", "", "wet readings in a row before water is reported (a splash on the pins while "
          "handling the robot); then the report is latched until leak_node's ~reset", 1, 50, kind="integer",
          default=3, source="choice"),
    Param("leak.timeout_s", "s", "no good reading of the pin for this long: health/leak ERROR no_reading (at least "
          "2 / rate_hz)", 0.0, 60.0, low_open=True, default=1.0, source="choice"),
), names={"joint": JOINT_NAMES, "pack": BATTERY_PACKS}, what="hardware parameter")


@dataclass(frozen=True)
class JointHardware:
    """Wiring of one joint: PCA9685 output, TCA9548A channel, ADS1115 address and input, pulse limits."""

    name: str
    index: int
    pwm_channel: int
    mux_channel: int
    adc_address: int
    adc_input: int
    min_us: float
    max_us: float
    neutral_us: float
    failsafe: str


@dataclass(frozen=True)
class DepthSensorHardware:
    """The MS5837 depth sensor: where it sits, how it is read, how pressure becomes depth (``depth.*``)."""

    fitted: bool = False
    model: str = "bar30"
    address: int = MS5837_ADDRESS
    mux_channel: int = -1
    rate_hz: float = 10.0
    osr: int = 4096
    fluid_density: float = 997.0
    surface_pa: float = 101325.0
    zero_at_start: bool = False
    zero_max_offset_pa: float = 3000.0
    pressure_stddev_pa: float = 30.0
    timeout_s: float = 1.0
    warn_window_s: float = 2.0
    max_rate_m_s: float = 2.0

    @property
    def ms5837_model(self) -> Model:
        """The MS5837 variant of :attr:`model`."""
        return DEPTH_MODELS[self.model]


@dataclass(frozen=True)
class BatteryPackHardware:
    """One LiPo pack read through a divider on a spare ADS1115 input (``batteries.packs.<pack>``)."""

    name: str
    fitted: bool
    mux_channel: int
    adc_address: int
    adc_input: int
    divider_ratio: float
    cells: int
    warn_cell_v: float = 3.6
    critical_cell_v: float = 3.4
    hysteresis_v: float = 0.1


@dataclass(frozen=True)
class BatteryHardware:
    """The packs (fitted or not, in :data:`BATTERY_PACKS` order) and how often they are read (``batteries.*``)."""

    packs: Tuple[BatteryPackHardware, ...] = ()
    rate_hz: float = 2.0
    stale_after_s: float = 2.0
    confirm_readings: int = 2

    @property
    def fitted(self) -> Tuple[BatteryPackHardware, ...]:
        """The packs that are wired."""
        return tuple(pack for pack in self.packs if pack.fitted)


@dataclass(frozen=True)
class LeakProbeHardware:
    """The enclosure's leak probe on a Jetson GPIO pin (``leak.*``)."""

    fitted: bool = False
    pin: int = 15
    active_high: bool = True
    rate_hz: float = 10.0
    confirm_readings: int = 3
    timeout_s: float = 1.0


@dataclass(frozen=True)
class HardwareConfig:
    """Everything the servo drivers need to know about the wiring. Build with :func:`load_hardware_config`."""

    i2c_bus: int
    bus_lock_timeout: float
    mux_address: int
    mux_deselect_after_read: bool
    pca_address: int
    pwm_frequency_hz: float
    pca_oscillator_hz: float
    pwm_stagger: bool
    watchdog_timeout: float
    adc_full_scale_v: float
    adc_data_rate: int
    stale_after: float
    failed_after: float
    joints: Tuple[JointHardware, ...]
    #: Feedback outside the angles of a joint's pulse limits by more than this (deg) is not plausible.
    adc_plausible_margin_deg: float = 15.0
    #: Feedback further from the joint's last good angle than no-load speed x elapsed time + this (deg)
    #: is not plausible (a servo cannot move faster), unless ``adc_jump_confirm_readings`` readings agree.
    adc_jump_margin_deg: float = 3.0
    adc_jump_confirm_readings: int = 3
    depth: DepthSensorHardware = DepthSensorHardware()
    batteries: BatteryHardware = BatteryHardware()
    leak: LeakProbeHardware = LeakProbeHardware()

    @property
    def pwm_channels(self) -> np.ndarray:
        """PCA9685 channel of each joint (12 ints, JOINT_NAMES order)."""
        return np.array([joint.pwm_channel for joint in self.joints], dtype=int)

    @property
    def min_us(self) -> np.ndarray:
        """Lower pulse limit per joint (us)."""
        return np.array([joint.min_us for joint in self.joints])

    @property
    def max_us(self) -> np.ndarray:
        """Upper pulse limit per joint (us)."""
        return np.array([joint.max_us for joint in self.joints])

    @property
    def neutral_us(self) -> np.ndarray:
        """Pulse per joint used by the 'neutral' failsafe (us)."""
        return np.array([joint.neutral_us for joint in self.joints])

    @property
    def prescale(self) -> int:
        """PCA9685 PRE_SCALE value for the configured frequency: round(osc / (4096 f)) - 1."""
        return pca9685_prescale(self.pwm_frequency_hz, self.pca_oscillator_hz)

    @property
    def actual_pwm_frequency_hz(self) -> float:
        """The frequency the PCA9685 really produces with :attr:`prescale`: osc / (4096 (prescale + 1))."""
        return self.pca_oscillator_hz / (4096.0 * (self.prescale + 1))

    def joint(self, name: str) -> JointHardware:
        """The joint called ``name`` (ValueError if unknown)."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise ValueError("unknown joint %r; known: %s" % (name, ", ".join(JOINT_NAMES)))


def pca9685_prescale(frequency_hz: float, oscillator_hz: float = 25e6) -> int:
    """PRE_SCALE register value (datasheet eq. 1): round(osc / (4096 * f)) - 1, valid 3..255."""
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        raise ValueError("PWM frequency must be a positive number, got %r" % frequency_hz)
    prescale = int(math.floor(oscillator_hz / (4096.0 * frequency_hz) + 0.5)) - 1
    if not 3 <= prescale <= 255:
        raise ValueError("PWM frequency %g Hz needs PRE_SCALE %d outside 3..255 (about 24..1526 Hz)"
                         % (frequency_hz, prescale))
    return prescale


def hardware_config_from_dict(tree: Mapping[str, Any]) -> HardwareConfig:
    """Validate a parsed ``hardware.yaml`` tree against :data:`HARDWARE_SCHEMA` and build the
    :class:`HardwareConfig` (the checks that tie several values together are here)."""
    v = HARDWARE_SCHEMA.read(tree)
    mux_address = v["mux.address"]
    if mux_address == PCA9685_ALLCALL_ADDRESS:
        raise ParameterError("hardware parameter 'mux.address' = 0x70 collides with the PCA9685 LED all-call "
                             "address it answers at power-up; strap the TCA9548A to 0x71..0x77")
    pca_address = v["pca9685.address"]
    if pca_address == mux_address or pca_address in ADS1115_ADDRESSES or pca_address == PCA9685_ALLCALL_ADDRESS:
        raise ParameterError("hardware parameter 'pca9685.address' = 0x%02x clashes with another device"
                             % pca_address)
    frequency = v["pca9685.frequency_hz"]
    oscillator = v["pca9685.oscillator_hz"]
    try:
        pca9685_prescale(frequency, oscillator)
    except ValueError as exc:
        raise ParameterError("hardware parameter 'pca9685.frequency_hz': %s" % exc) from exc
    period_us = 1e6 / frequency
    stale_after = v["adc.stale_after_s"]
    failed_after = v["adc.failed_after_s"]
    if failed_after <= stale_after:
        raise ParameterError("hardware parameter 'adc.failed_after_s' (%g) must exceed 'adc.stale_after_s' (%g)"
                             % (failed_after, stale_after))

    joints = []
    pwm_used: Dict[int, str] = {}
    adc_used: Dict[Tuple[int, int], str] = {}
    for index, name in enumerate(JOINT_NAMES):
        key = "joints.%s" % name
        pwm_channel, mux_channel, adc_address, adc_input, min_us, max_us, neutral_us, failsafe = (
            v["%s.%s" % (key, field)] for field in _JOINT_FIELDS)
        if min_us >= max_us:
            raise ParameterError("hardware parameter '%s.min_us' (%g) must be below max_us (%g)"
                                 % (key, min_us, max_us))
        if max_us >= period_us:
            raise ParameterError("hardware parameter '%s.max_us' (%g) must be shorter than the PWM period %g us"
                                 % (key, max_us, period_us))
        if not min_us <= neutral_us <= max_us:
            raise ParameterError("hardware parameter '%s.neutral_us' = %g is outside [%g, %g]"
                                 % (key, neutral_us, min_us, max_us))
        if pwm_channel in pwm_used:
            raise ParameterError("hardware parameter '%s.pwm_channel' = %d is already used by %s"
                                 % (key, pwm_channel, pwm_used[pwm_channel]))
        pwm_used[pwm_channel] = name
        # One ADS1115 per joint: each converts continuously on its own input, so a cycle only reads
        # results (sharing an ADC would need a MUX switch and a conversion period per read).
        adc_key = (mux_channel, adc_address)
        if adc_key in adc_used:
            raise ParameterError("hardware parameter '%s': the ADS1115 at 0x%02x on mux channel %d is already "
                                 "used by %s (one ADC per joint)" % (key, adc_address, mux_channel, adc_used[adc_key]))
        adc_used[adc_key] = name
        joints.append(JointHardware(name=name, index=index, pwm_channel=pwm_channel, mux_channel=mux_channel,
                                    adc_address=adc_address, adc_input=adc_input, min_us=min_us, max_us=max_us,
                                    neutral_us=neutral_us, failsafe=failsafe))
    depth = _depth_sensor(v, mux_address, pca_address)
    batteries = _batteries(v, joints, v["adc.full_scale_v"])
    return HardwareConfig(
        i2c_bus=v["i2c.bus"],
        bus_lock_timeout=v["i2c.lock_timeout_s"],
        mux_address=mux_address,
        mux_deselect_after_read=v["mux.deselect_after_read"],
        pca_address=pca_address,
        pwm_frequency_hz=frequency,
        pca_oscillator_hz=oscillator,
        pwm_stagger=v["pca9685.stagger_outputs"],
        watchdog_timeout=v["pca9685.watchdog_timeout_s"],
        adc_full_scale_v=v["adc.full_scale_v"],
        adc_data_rate=v["adc.data_rate_sps"],
        stale_after=stale_after,
        failed_after=failed_after,
        joints=tuple(joints),
        adc_plausible_margin_deg=v["adc.plausible_margin_deg"],
        adc_jump_margin_deg=v["adc.jump_margin_deg"],
        adc_jump_confirm_readings=v["adc.jump_confirm_readings"],
        depth=depth,
        batteries=batteries,
        leak=_leak_probe(v),
    )


def _depth_sensor(v: Mapping[str, Any], mux_address: int, pca_address: int) -> DepthSensorHardware:
    """``depth.*`` checked against each other and the bus (ParameterError naming the key)."""
    depth = DepthSensorHardware(
        fitted=v["depth.fitted"], model=v["depth.model"], address=v["depth.address"],
        mux_channel=v["depth.mux_channel"], rate_hz=v["depth.rate_hz"], osr=v["depth.osr"],
        fluid_density=v["depth.fluid_density_kg_m3"], surface_pa=v["depth.surface_pa"],
        zero_at_start=v["depth.zero_at_start"], zero_max_offset_pa=v["depth.zero_max_offset_pa"],
        pressure_stddev_pa=v["depth.pressure_stddev_pa"], timeout_s=v["depth.timeout_s"],
        warn_window_s=v["depth.warn_window_s"], max_rate_m_s=v["depth.max_rate_m_s"])
    if depth.osr > DEPTH_MAX_OSR[depth.model]:
        raise ParameterError("hardware parameter 'depth.osr' = %d: the %s has no conversion command above OSR %d"
                             % (depth.osr, depth.model, DEPTH_MAX_OSR[depth.model]))
    busy = 2.0 * depth.rate_hz * CONVERSION_TIME_MAX[depth.osr]
    if busy > 0.9:
        raise ParameterError("hardware parameter 'depth.rate_hz' = %g: two conversions at OSR %d take %.1f ms, "
                             "more than 0.9 / (2 rate) = %.1f ms; lower the rate or the OSR"
                             % (depth.rate_hz, depth.osr, 2e3 * CONVERSION_TIME_MAX[depth.osr],
                                450.0 / depth.rate_hz))
    if depth.timeout_s < 2.0 / depth.rate_hz:
        raise ParameterError("hardware parameter 'depth.timeout_s' = %g must be at least 2 / depth.rate_hz = %g s"
                             % (depth.timeout_s, 2.0 / depth.rate_hz))
    if depth.mux_channel >= 0:
        raise ParameterError("hardware parameter 'depth.mux_channel' = %d: behind the TCA9548A is not supported: "
                             "ms5837_node and servo_feedback_node would both switch the mux, each reading between "
                             "the other's select and read; wire the sensor to the Jetson's bus (-1)"
                             % depth.mux_channel)
    if depth.address in (mux_address, pca_address, PCA9685_ALLCALL_ADDRESS):
        raise ParameterError("hardware parameter 'depth.address' = 0x%02x clashes with the mux, the PCA9685 or its "
                             "all-call address 0x70 on the Jetson's bus" % depth.address)
    return depth


def _batteries(v: Mapping[str, Any], joints: Sequence[JointHardware], full_scale_v: float) -> BatteryHardware:
    """``batteries.*``: each pack on a spare input of one of the joints' ADS1115s, inside its range."""
    host = {(joint.mux_channel, joint.adc_address): joint for joint in joints}
    used: Dict[Tuple[int, int, int], str] = {}
    packs = []
    for name in BATTERY_PACKS:
        key = "batteries.packs.%s" % name
        pack = BatteryPackHardware(name=name, **{field: v["%s.%s" % (key, field)] for field in (
            "fitted", "mux_channel", "adc_address", "adc_input", "divider_ratio", "cells", "warn_cell_v",
            "critical_cell_v", "hysteresis_v")})
        if pack.critical_cell_v >= pack.warn_cell_v:
            raise ParameterError("hardware parameter '%s.critical_cell_v' (%g) must be below warn_cell_v (%g)"
                                 % (key, pack.critical_cell_v, pack.warn_cell_v))
        # checked fitted or not: the simulated robot fits every declared pack (with_batteries_fitted)
        joint = host.get((pack.mux_channel, pack.adc_address))
        if joint is None:
            raise ParameterError("hardware parameter '%s.adc_address': no joint's ADS1115 at 0x%02x on mux channel "
                                 "%d (a pack is read on a spare input of one)" % (key, pack.adc_address,
                                                                                 pack.mux_channel))
        if pack.adc_input == joint.adc_input:
            raise ParameterError("hardware parameter '%s.adc_input' = %d is %s's feedback input"
                                 % (key, pack.adc_input, joint.name))
        place = (pack.mux_channel, pack.adc_address, pack.adc_input)
        if place in used:
            raise ParameterError("hardware parameter '%s.adc_input': input %d of the ADS1115 at 0x%02x on mux "
                                 "channel %d is already the %s pack's" % (key, pack.adc_input, pack.adc_address,
                                                                          pack.mux_channel, used[place]))
        used[place] = name
        full = pack.cells * LIPO_MAX_CELL_V / pack.divider_ratio
        if full >= full_scale_v:
            raise ParameterError("hardware parameter '%s.divider_ratio' = %g: a full %dS pack (%.2f V) gives "
                                 "%.2f V at the ADC, beyond adc.full_scale_v %g V"
                                 % (key, pack.divider_ratio, pack.cells, pack.cells * LIPO_MAX_CELL_V, full,
                                    full_scale_v))
        packs.append(pack)
    batteries = BatteryHardware(packs=tuple(packs), rate_hz=v["batteries.rate_hz"],
                                stale_after_s=v["batteries.stale_after_s"],
                                confirm_readings=v["batteries.confirm_readings"])
    if batteries.stale_after_s < 2.0 / batteries.rate_hz:
        raise ParameterError("hardware parameter 'batteries.stale_after_s' = %g must be at least 2 / "
                             "batteries.rate_hz = %g s" % (batteries.stale_after_s, 2.0 / batteries.rate_hz))
    return batteries


def _leak_probe(v: Mapping[str, Any]) -> LeakProbeHardware:
    """``leak.*`` checked against each other (ParameterError naming the key)."""
    leak = LeakProbeHardware(fitted=v["leak.fitted"], pin=v["leak.pin"], active_high=v["leak.active_high"],
                             rate_hz=v["leak.rate_hz"], confirm_readings=v["leak.confirm_readings"],
                             timeout_s=v["leak.timeout_s"])
    if leak.timeout_s < 2.0 / leak.rate_hz:
        raise ParameterError("hardware parameter 'leak.timeout_s' = %g must be at least 2 / leak.rate_hz = %g s"
                             % (leak.timeout_s, 2.0 / leak.rate_hz))
    return leak


def with_leak_fitted(config: HardwareConfig) -> HardwareConfig:
    """``config`` with its leak probe fitted: the simulated robot's, whatever the robot's file says."""
    return dataclasses.replace(config, leak=dataclasses.replace(config.leak, fitted=True))


def with_batteries_fitted(config: HardwareConfig) -> HardwareConfig:
    """``config`` with every declared pack fitted: the simulated robot's packs, whatever the robot's file says."""
    packs = tuple(dataclasses.replace(pack, fitted=True) for pack in config.batteries.packs)
    return dataclasses.replace(config, batteries=dataclasses.replace(config.batteries, packs=packs))


def load_hardware_config(path: Optional[str] = None) -> HardwareConfig:
    """Load and validate ``config/hardware.yaml`` (or ``path``); ParameterError on any problem."""
    return load_config(path, "hardware.yaml", hardware_config_from_dict)


__all__ = ["HARDWARE_SCHEMA", "FAILSAFE_ACTIONS", "ADS1115_FSR_PGA", "ADS1115_RATES", "ADS1115_ADDRESSES",
           "PCA9685_ALLCALL_ADDRESS", "BATTERY_PACKS", "DEPTH_MODELS", "DEPTH_MAX_OSR", "LIPO_MAX_CELL_V",
           "BatteryHardware", "BatteryPackHardware", "DepthSensorHardware", "JointHardware", "HardwareConfig",
           "LeakProbeHardware", "pca9685_prescale", "hardware_config_from_dict", "load_hardware_config",
           "with_batteries_fitted", "with_leak_fitted"]
