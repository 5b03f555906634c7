"""The servos on a calibration bench: a simulated rig, and the primitives a procedure drives them with.

:class:`SimulatedServoRig` is the fake hardware with twelve servos behind it, built right or wrong
(:mod:`quadruped_drivers.hardware_faults`); :class:`PoseDriver` holds and ramps poses through the real driver
objects and reads the feedback. The procedures (calibration against the reference poses, the channel check)
are :mod:`quadruped_control.bringup`, which knows the five-bar's safe set.
"""
from __future__ import annotations

import math
import time
from typing import Callable, List, Sequence

import numpy as np

from quadruped_drivers.calibration import ServoCalibration
from quadruped_drivers.hardware_config import HardwareConfig
from quadruped_drivers.hardware_faults import BuiltRobot, HardwareFaults
from quadruped_drivers.i2c.fake_devices import FakeHardware, build_fake_hardware
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray

#: Command period while holding or ramping (s): well inside the PWM watchdog timeout.
COMMAND_PERIOD = 0.02


class SimulatedServoRig:
    """Fake hardware plus twelve servos that follow the pulse widths the fake PCA9685 holds.

    The servos as bought differ from ``calibration``'s estimate (feedback slope x ``slope_scale``, offset
    + ``offset_shift_deg``), and the robot may be built wrong (``faults``,
    :class:`~quadruped_drivers.hardware_faults.BuiltRobot`). Each joint moves toward its servo's target at
    ``speed`` rad/s times its ``faults.servo_speed_scale`` (a servo without pulses is limp and stays put, or goes
    where :meth:`place` puts it); feedback carries Gaussian noise of ``noise_v``. Time is virtual: :meth:`sleep`
    advances it in 1 ms steps.
    """

    def __init__(self, hardware_config: HardwareConfig, calibration: ServoCalibration, slope_scale: float = 1.04,
                 offset_shift_deg: float = 3.0, noise_v: float = 0.002, speed: float = math.radians(570.0),
                 seed: int = 0, faults: HardwareFaults = HardwareFaults()) -> None:
        self.hardware: FakeHardware = build_fake_hardware(hardware_config)
        self.calibration = calibration
        bought = calibration
        for index, joint in enumerate(calibration.joints):
            bought = bought.with_feedback(index, joint.feedback_slope * slope_scale,
                                          joint.feedback_offset + math.radians(offset_shift_deg))
        self.built = BuiltRobot(bought, faults)
        self.noise_v = noise_v
        self.speed = speed
        self.rng = np.random.default_rng(seed)
        self.time = 0.0
        self.angles = np.array([j.neutral_angle_rad for j in calibration.joints])
        self._feed()

    @property
    def bus(self):
        """The fake bus the drivers talk to."""
        return self.hardware.bus

    def clock(self) -> float:
        """Virtual time (s)."""
        return self.time

    def place(self, angles: Sequence[float]) -> None:
        """The operator puts the limp joints at ``angles`` (rad) by hand; ValueError if a servo is driven."""
        if np.any(self.hardware.pulse_widths_us() > 0.0):
            raise ValueError("joints can be placed by hand only with the PWM outputs off")
        self.angles = np.array(angles, dtype=float)
        self._feed()

    def _feed(self) -> None:
        volts = self.built.feedback_volts(self.angles)
        volts = volts + self.rng.normal(0.0, self.noise_v, volts.shape) if self.noise_v > 0 else volts
        self.hardware.set_joint_voltages(np.clip(volts, -0.3, 5.3))

    def sleep(self, seconds: float) -> None:
        """Advance virtual time by ``seconds``, moving the servos and updating the feedback voltages."""
        steps = max(1, int(math.ceil(seconds / 0.001)))
        dt = seconds / steps
        target = self.built.joint_targets(self.hardware.pulse_widths_us())  # only commands change them
        on = ~np.isnan(target)
        target = np.where(on, target, self.angles)
        limit = self.speed * self.built.speed_scale * dt
        for _ in range(steps):
            step = np.clip(target - self.angles, -limit, limit)
            self.angles = self.angles + step
        self.time += seconds
        self._feed()


class PoseDriver:
    """Holds and ramps poses (joint angles through the calibration's command map) through the real driver
    objects ``pwm`` and ``feedback`` (which the procedures read), feeding the PWM watchdog."""

    def __init__(self, pwm: ServoPwmOutput, feedback: ServoFeedbackArray, calibration: ServoCalibration,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, speed: float = math.radians(90.0)) -> None:
        self.pwm = pwm
        self.feedback = feedback
        self.calibration = calibration
        self.clock = clock
        self.sleep = sleep
        self.speed = speed
        self.neutral = np.array([j.neutral_angle_rad for j in calibration.joints])
        self.current = self.neutral.copy()

    def hold(self, angles: np.ndarray, duration: float) -> None:
        """Command ``angles`` for ``duration`` s, re-sending every COMMAND_PERIOD (feeds the watchdog)."""
        pulses = self.calibration.angles_to_pulses(angles)
        end = self.clock() + duration
        while True:
            self.pwm.command(pulses)
            self.pwm.update()
            remaining = end - self.clock()
            if remaining <= 0:
                break
            self.sleep(min(COMMAND_PERIOD, remaining))
        self.current = np.array(angles, dtype=float)

    def move_to(self, angles: np.ndarray) -> None:
        """Ramp from the current pose to ``angles`` at ``speed`` rad/s."""
        for pose in ramp(self.current, angles, self.speed):
            self.hold(pose, COMMAND_PERIOD)


def ramp(start: np.ndarray, target: np.ndarray, speed: float) -> List[np.ndarray]:
    """The poses, one per :data:`COMMAND_PERIOD`, that take every joint from ``start`` to ``target`` (rad) at
    most ``speed`` rad/s, ending at ``target``."""
    start, target = np.array(start, dtype=float), np.asarray(target, dtype=float)
    steps = max(1, int(math.ceil(float(np.max(np.abs(target - start))) / (speed * COMMAND_PERIOD))))
    return [start + (target - start) * step / steps for step in range(1, steps + 1)]
