"""Fault campaigns of the servo electronics against the register-level fakes (no ROS).

The drivers under test are the real :class:`~quadruped_drivers.servo_feedback.ServoFeedbackArray` and
:class:`~quadruped_drivers.pwm_output.ServoPwmOutput`; only the fakes are instrumented (faults injected
on the fake bus and devices, the PCA9685's outputs checked after every write it takes, aborted ones
included). Used with small counts by the tests and with the full counts by
``benchmarks/fuzz_campaign.py --part i2c``.

:func:`faulty_cycles` runs 100 Hz cycles (feedback read, PWM command, PWM update) with at least one
fault per cycle (:data:`FAULTS`) and counts what must never happen: ``crashes`` (an exception out of
a driver), ``hangs`` (a cycle longer than ``hang_s``), ``nan_outputs`` (a valid joint with a
non-finite angle, a non-finite applied width), ``wrongly_fresh`` (a joint reported valid whose
voltage is not its own servo's), ``pulses_outside_limits`` (a channel of the fake chip with a pulse
outside its joint's limits, or a pulse on an unused channel, after any write).

:func:`failsafe_latency` is one watchdog trial: commands stop, the bus fails a fraction of all
transactions (aborted writes), and it returns how long after the last command the chip holds the
failsafe.
"""
from __future__ import annotations

import random
import time
from typing import Any, Callable, Dict, Optional

import numpy as np

from quadruped_drivers.hardware_config import HardwareConfig
from quadruped_drivers.i2c.fake_devices import FakeHardware, build_fake_hardware
from quadruped_drivers.node_support import with_failsafe
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray

#: Faults injected by :func:`faulty_cycles`.
FAULTS = ("adc_nack", "mux_error", "mux_ignored", "adc_brownout", "adc_garbage", "pca_abort", "pca_random",
          "pca_reset", "pca_nack", "command_nan", "command_gap")
PERIOD = 0.01
#: A valid joint's voltage may differ from its servo's by this much (ADC quantisation, 1 LSB at 4.096 V).
_LSB_TOLERANCE = 4.096 / 32768 * 1.01


class _Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class _ChipMonitor:
    """Checks the fake PCA9685's outputs after every write it receives (aborted prefixes included)."""

    def __init__(self, fake: FakeHardware, hardware: HardwareConfig) -> None:
        self.fake = fake
        self.violations = 0
        self.worst = ""
        channels = hardware.pwm_channels
        self._low = np.full(16, np.inf)
        self._high = np.full(16, -np.inf)
        self._low[channels] = hardware.min_us - 1e-6
        self._high[channels] = hardware.max_us + 1e-6
        write = fake.pca.write

        def checked(data: bytes) -> None:
            write(data)
            self.check()

        fake.pca.write = checked  # type: ignore[assignment]

    def check(self) -> None:
        widths = self.fake.pca.pulse_widths_us()
        on = widths > 0.0
        bad = on & ((widths < self._low) | (widths > self._high))
        if np.any(bad):
            self.violations += 1
            channel = int(np.flatnonzero(bad)[0])
            self.worst = "channel %d at %.1f us" % (channel, widths[channel])


def _plausible_volts(feedback: ServoFeedbackArray, calibration: Any, rng: random.Random) -> np.ndarray:
    low, high = feedback.plausible_range
    margin = np.radians(20.0)  # well inside: the servos stay within their pulse range
    angles = np.array([rng.uniform(lo + margin, hi - margin) for lo, hi in zip(low, high)])
    return calibration.angles_to_volts(angles)


def faulty_cycles(cycles: int, hardware: HardwareConfig, calibration: Any, seed: int = 0, hang_s: float = 1.0,
                  wall_clock: Callable[[], float] = time.perf_counter) -> Dict[str, Any]:
    """Run ``cycles`` faulty cycles; returns the counters (module docstring) and fault counts."""
    rng = random.Random(seed)
    fake = build_fake_hardware(hardware)
    monitor = _ChipMonitor(fake, hardware)
    clock = _Clock()
    feedback = ServoFeedbackArray(fake.bus, hardware, calibration, clock=clock)
    pwm = ServoPwmOutput(fake.bus, hardware, clock=clock, sleep=lambda s: None, update_period=PERIOD)
    volts = _plausible_volts(feedback, calibration, rng)
    fake.set_joint_voltages(volts)
    pwm.start()
    feedback.start()
    stats: Dict[str, Any] = {"cycles": 0, "crashes": 0, "hangs": 0, "nan_outputs": 0, "wrongly_fresh": 0,
                             "pulses_outside_limits": 0, "fresh_joint_samples": 0, "plausible_garbage_skipped": 0}
    for fault in FAULTS:
        stats["fault " + fault] = 0
    last_error = ""
    for _ in range(cycles):
        clock.t += PERIOD
        volts = np.clip(volts + np.array([rng.gauss(0, 0.01) for _ in range(12)]), *_volt_bounds(feedback, calibration))
        fake.set_joint_voltages(volts)
        command: Optional[np.ndarray] = np.array([rng.uniform(j.min_us - 300, j.max_us + 300) for j in hardware.joints])
        for _ in range(rng.randint(1, 2)):
            fault = rng.choice(FAULTS)
            stats["fault " + fault] += 1
            command = _inject(fault, rng, fake, hardware, feedback, calibration, volts, command, stats)
        started = wall_clock()
        try:
            reading = feedback.read()
            if command is not None:
                pwm.command(command)
            pwm.update()
        except Exception as exc:  # noqa: BLE001 - counted: a driver must never raise here
            stats["crashes"] += 1
            last_error = "%s: %s" % (type(exc).__name__, exc)
            continue
        finally:
            fake.bus.clear_faults()
            for channel in range(3):
                fake.mux.channel_bus(channel).clear_faults()
        if wall_clock() - started > hang_s:
            stats["hangs"] += 1
        stats["cycles"] += 1
        valid = reading.valid
        stats["fresh_joint_samples"] += int(valid.sum())
        if np.any(~np.isfinite(reading.angles[valid])) or np.any(~np.isfinite(pwm.applied_us)):
            stats["nan_outputs"] += 1
        wrong = valid & ~(np.abs(reading.volts - volts) <= _LSB_TOLERANCE)
        stats["wrongly_fresh"] += int(wrong.sum())
    stats["pulses_outside_limits"] = monitor.violations
    stats["worst_pulse"] = monitor.worst
    stats["last_crash"] = last_error
    stats.update(write_errors=pwm.write_errors, write_retries=pwm.write_retries, chip_resets_found=pwm.chip_resets,
                 mux_mismatches=feedback.mux_mismatches, adc_config_losses=int(feedback.config_losses.sum()),
                 implausible_codes=int(feedback.implausible_counts.sum()))
    return stats


def _volt_bounds(feedback: ServoFeedbackArray, calibration: Any):
    low, high = feedback.plausible_range
    margin = np.radians(20.0)
    a = calibration.angles_to_volts(low + margin)
    b = calibration.angles_to_volts(high - margin)
    return np.minimum(a, b), np.maximum(a, b)


def _inject(fault: str, rng: random.Random, fake: FakeHardware, hardware: HardwareConfig,
            feedback: ServoFeedbackArray, calibration: Any, volts: np.ndarray, command: Optional[np.ndarray],
            stats: Dict[str, Any]) -> Optional[np.ndarray]:
    joint = hardware.joints[rng.randrange(len(hardware.joints))]
    if fault == "adc_nack":
        fake.mux.channel_bus(joint.mux_channel).inject_fault(joint.adc_address, "nack", count=rng.randint(1, 3))
    elif fault == "mux_error":
        fake.bus.inject_fault(hardware.mux_address, "oserror", count=1)
    elif fault == "mux_ignored":
        fake.mux.inject_ignored_writes(1)
    elif fault == "adc_brownout":
        fake.adcs[joint.index].power_cycle()
    elif fault == "adc_garbage":
        code = rng.randrange(-32768, 32768)
        seen = volts.copy()
        seen[joint.index] = code * hardware.adc_full_scale_v / 32768.0
        angle = calibration.volts_to_angles(seen)[joint.index]
        low, high = feedback.plausible_range
        if low[joint.index] - 1e-3 <= angle <= high[joint.index] + 1e-3:
            stats["plausible_garbage_skipped"] += 1  # indistinguishable from a real reading: not injected
        else:
            fake.adcs[joint.index].inject_codes([code])
    elif fault == "pca_abort":
        fake.bus.inject_fault(hardware.pca_address, "abort", count=rng.randint(1, 6), rng=rng)
    elif fault == "pca_random":
        fake.bus.inject_fault(hardware.pca_address, "abort", count=None, probability=rng.uniform(0.1, 0.5), rng=rng)
    elif fault == "pca_reset":
        fake.pca.power_cycle()
    elif fault == "pca_nack":
        fake.bus.inject_fault(hardware.pca_address, "nack", count=rng.randint(1, 3))
    elif fault == "command_nan" and command is not None:
        command = command.copy()
        command[rng.randrange(len(command))] = rng.choice([float("nan"), float("inf"), -float("inf")])
    elif fault == "command_gap":
        command = None
    return command


def failsafe_latency(hardware: HardwareConfig, failsafe: str, failure_rate: float, seed: int,
                     period: float = PERIOD, horizon: float = 0.5) -> float:
    """Seconds from the last command until the fake chip holds the failsafe (inf: not within ``horizon``).

    The PWM runs 40 command periods with ``failure_rate`` of all its transactions aborted at a random
    byte (commands at a random phase of the ``period`` update timer), then the commands stop while
    :meth:`ServoPwmOutput.update` keeps running every ``period``.
    """
    hw = with_failsafe(hardware, failsafe)
    fake = build_fake_hardware(hw)
    clock = _Clock()
    pwm = ServoPwmOutput(fake.bus, hw, clock=clock, sleep=lambda s: None, update_period=period)
    pwm.start()
    rng = random.Random(seed)
    phase = rng.random() * period  # commands arrive at a random phase of the update timer
    if failure_rate > 0:
        fake.bus.inject_fault(hw.pca_address, "abort", count=None, probability=failure_rate, rng=rng)
    last = clock.t
    for _ in range(40):
        pwm.update()
        clock.t += phase
        pwm.command(np.array([rng.uniform(j.min_us, j.max_us) for j in hw.joints]))
        last = clock.t
        clock.t += period - phase
    tick = 1e6 / (hw.actual_pwm_frequency_hz * 4096)
    while clock.t - last <= horizon:
        pwm.update()
        widths = fake.pulse_widths_us()
        if failsafe == "off":
            reached = bool(np.all(widths == 0.0))
        elif failsafe == "neutral":
            reached = bool(np.allclose(widths, np.round(hw.neutral_us / tick) * tick, atol=1e-6))
        else:
            reached = pwm.watchdog_tripped and bool(np.allclose(widths, pwm.applied_us, atol=1e-6))
        if reached:
            return clock.t - last
        clock.t += period
    return float("inf")


__all__ = ["FAULTS", "PERIOD", "faulty_cycles", "failsafe_latency"]
