"""Typed loader for ``config/hardware.yaml``: I2C bus, addresses, mux channels, servo channel order.

The paper (section "Electronics") reads twelve ADS1115 ADCs for the servo feedback and drives the
twelve servos through PWM at 100 Hz control rate; this file fixes how those parts sit on the Jetson's
I2C bus. Joints are listed in :data:`quadruped_common.robot.JOINT_NAMES` order
(``leg{1..4}_{motor1,motor2,hip}`` = theta1, theta2, theta3 of eq. ik_theta3 / ik_theta1245).

Loading never returns a half-valid object: a missing key, a duplicate channel or address, an address
clash or a value out of range raises :class:`~quadruped_common.config.ParameterError` naming the key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Tuple

import numpy as np

from quadruped_common.config import ParameterError, boolean, integer, load_config, lookup, number
from quadruped_common.robot import JOINT_NAMES

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


def _get(tree: Mapping[str, Any], dotted: str) -> Any:
    return lookup(tree, dotted, "hardware parameter")


def _int(tree: Mapping[str, Any], dotted: str, low: int, high: int) -> int:
    return integer(_get(tree, dotted), dotted, low, high, what="hardware parameter")


def _float(tree: Mapping[str, Any], dotted: str, low: float, high: float) -> float:
    return number(_get(tree, dotted), dotted, low, high, what="hardware parameter")


def _bool(tree: Mapping[str, Any], dotted: str) -> bool:
    return boolean(_get(tree, dotted), dotted, what="hardware parameter")


def hardware_config_from_dict(tree: Mapping[str, Any]) -> HardwareConfig:
    """Validate a parsed ``hardware.yaml`` tree and build the :class:`HardwareConfig`."""
    mux_address = _int(tree, "mux.address", 0x70, 0x77)
    if mux_address == PCA9685_ALLCALL_ADDRESS:
        raise ParameterError("hardware parameter 'mux.address' = 0x70 collides with the PCA9685 LED all-call "
                             "address it answers at power-up; strap the TCA9548A to 0x71..0x77")
    pca_address = _int(tree, "pca9685.address", 0x40, 0x7F)
    if pca_address == mux_address or pca_address in ADS1115_ADDRESSES or pca_address == PCA9685_ALLCALL_ADDRESS:
        raise ParameterError("hardware parameter 'pca9685.address' = 0x%02x clashes with another device"
                             % pca_address)
    frequency = _float(tree, "pca9685.frequency_hz", 24.0, 400.0)
    oscillator = _float(tree, "pca9685.oscillator_hz", 20e6, 30e6)
    try:
        pca9685_prescale(frequency, oscillator)
    except ValueError as exc:
        raise ParameterError("hardware parameter 'pca9685.frequency_hz': %s" % exc) from exc
    period_us = 1e6 / frequency
    fsr = _float(tree, "adc.full_scale_v", 0.0, 10.0)
    if fsr not in ADS1115_FSR_PGA:
        raise ParameterError("hardware parameter 'adc.full_scale_v' = %g is not an ADS1115 range %s"
                             % (fsr, sorted(ADS1115_FSR_PGA)))
    rate = _int(tree, "adc.data_rate_sps", 8, 860)
    if rate not in ADS1115_RATES:
        raise ParameterError("hardware parameter 'adc.data_rate_sps' = %d is not an ADS1115 rate %s"
                             % (rate, sorted(ADS1115_RATES)))
    stale_after = _float(tree, "adc.stale_after_s", 0.0, 10.0)
    failed_after = _float(tree, "adc.failed_after_s", 0.0, 60.0)
    if failed_after <= stale_after:
        raise ParameterError("hardware parameter 'adc.failed_after_s' (%g) must exceed 'adc.stale_after_s' (%g)"
                             % (failed_after, stale_after))

    joints_tree = _get(tree, "joints")
    if not isinstance(joints_tree, Mapping):
        raise ParameterError("hardware parameter 'joints' must map joint names to their wiring")
    unknown = sorted(set(joints_tree) - set(JOINT_NAMES))
    if unknown:
        raise ParameterError("hardware parameter 'joints' has unknown joints %s; expected %s"
                             % (unknown, list(JOINT_NAMES)))
    joints = []
    pwm_used: Dict[int, str] = {}
    adc_used: Dict[Tuple[int, int], str] = {}
    for index, name in enumerate(JOINT_NAMES):
        key = "joints.%s" % name
        pwm_channel = _int(tree, key + ".pwm_channel", 0, 15)
        mux_channel = _int(tree, key + ".mux_channel", 0, 7)
        adc_address = _int(tree, key + ".adc_address", 0x48, 0x4B)
        adc_input = _int(tree, key + ".adc_input", 0, 3)
        min_us = _float(tree, key + ".min_us", ABSOLUTE_MIN_US, ABSOLUTE_MAX_US)
        max_us = _float(tree, key + ".max_us", ABSOLUTE_MIN_US, ABSOLUTE_MAX_US)
        if min_us >= max_us:
            raise ParameterError("hardware parameter '%s.min_us' (%g) must be below max_us (%g)"
                                 % (key, min_us, max_us))
        if max_us >= period_us:
            raise ParameterError("hardware parameter '%s.max_us' (%g) must be shorter than the PWM period %g us"
                                 % (key, max_us, period_us))
        neutral_us = _float(tree, key + ".neutral_us", min_us, max_us)
        failsafe = _get(tree, key + ".failsafe")
        if failsafe not in FAILSAFE_ACTIONS:
            raise ParameterError("hardware parameter '%s.failsafe' must be one of %s, got %r"
                                 % (key, FAILSAFE_ACTIONS, failsafe))
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
    return HardwareConfig(
        i2c_bus=_int(tree, "i2c.bus", 0, 255),
        bus_lock_timeout=_float(tree, "i2c.lock_timeout_s", 0.0, 1.0),
        mux_address=mux_address,
        mux_deselect_after_read=_bool(tree, "mux.deselect_after_read"),
        pca_address=pca_address,
        pwm_frequency_hz=frequency,
        pca_oscillator_hz=oscillator,
        pwm_stagger=_bool(tree, "pca9685.stagger_outputs"),
        watchdog_timeout=_float(tree, "pca9685.watchdog_timeout_s", 0.001, 10.0),
        adc_full_scale_v=fsr,
        adc_data_rate=rate,
        stale_after=stale_after,
        failed_after=failed_after,
        joints=tuple(joints),
        adc_plausible_margin_deg=_float(tree, "adc.plausible_margin_deg", 0.0, 90.0),
        adc_jump_margin_deg=_float(tree, "adc.jump_margin_deg", 0.0, 90.0),
        adc_jump_confirm_readings=_int(tree, "adc.jump_confirm_readings", 1, 100),
    )


def load_hardware_config(path: Optional[str] = None) -> HardwareConfig:
    """Load and validate ``config/hardware.yaml`` (or ``path``); ParameterError on any problem."""
    return load_config(path, "hardware.yaml", hardware_config_from_dict)


__all__ = ["FAILSAFE_ACTIONS", "ADS1115_FSR_PGA", "ADS1115_RATES", "ADS1115_ADDRESSES", "PCA9685_ALLCALL_ADDRESS",
           "JointHardware", "HardwareConfig", "pca9685_prescale", "hardware_config_from_dict",
           "load_hardware_config"]
