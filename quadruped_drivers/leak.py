"""The enclosure's leak probe on a GPIO pin: readings to ``health/leak``, no ROS.

:class:`LeakWatch` takes the pin's level at each read (None when the read failed) and says:

* ERROR ``leak``: the level was the wet one (``leak.active_high``) ``leak.confirm_readings`` times in a row. The
  report is latched: water inside does not leave by itself, and a probe that dries in a draught must not re-arm
  the robot. :meth:`LeakWatch.reset` clears it, only while the probe reads dry;
* ERROR ``no_reading`` (a measurement fault, not a hazard): no good read for ``leak.timeout_s``;
* WARN ``wet``: wet readings not yet confirmed; OK ``dry``; OK ``not_fitted`` without a probe.

:func:`open_gpio_probe` is the real pin through Jetson.GPIO.
"""
from __future__ import annotations

from typing import Callable, Optional, Tuple

from quadruped_common.health import ERROR, OK, WARN, Health
from quadruped_drivers.hardware_config import LeakProbeHardware


class GpioUnavailable(RuntimeError):
    """Jetson.GPIO cannot run on this machine (not a Jetson, or no permission): a configuration error."""


class LeakWatch:
    """The probe's state from its pin readings (module docstring)."""

    def __init__(self, config: LeakProbeHardware, now: float) -> None:
        self.config = config
        self.started = float(now)
        self.last_good: Optional[float] = None
        self.wet_count = 0
        self.leak_since: Optional[float] = None
        self.read_failures = 0
        self.dry = True

    def update(self, level: Optional[bool], now: float) -> Optional[str]:
        """Take one read of the pin (``level``; None: the read failed). Returns an event for the log, or None."""
        if level is None:
            self.read_failures += 1
            return None
        self.last_good = float(now)
        wet = bool(level) == self.config.active_high
        self.dry = not wet
        self.wet_count = self.wet_count + 1 if wet else 0
        if wet and self.leak_since is None and self.wet_count >= self.config.confirm_readings:
            self.leak_since = float(now)
            return "WATER INSIDE: the leak probe read wet %d times in a row" % self.wet_count
        return None

    def reset(self) -> Tuple[bool, str]:
        """Clear a latched leak report; refused while the probe still reads wet. (done, why)."""
        if self.leak_since is None:
            return True, "no leak reported"
        if not self.dry:
            return False, "the probe still reads wet"
        self.leak_since = None
        return True, "leak report cleared (the probe reads dry)"

    def health(self, now: float) -> Health:
        """``health/leak`` at ``now`` (module docstring)."""
        if not self.config.fitted:
            return Health(OK, "not_fitted", "no leak probe fitted (hardware.yaml leak.fitted false)")
        if self.leak_since is not None:
            return Health(ERROR, "leak", "WATER INSIDE the enclosure (probe wet since %.1f s ago)"
                          % (now - self.leak_since), (("pin", str(self.config.pin)),))
        since = self.started if self.last_good is None else self.last_good
        if now - since > self.config.timeout_s:
            return Health(ERROR, "no_reading", "leak probe pin %d unreadable for %.1f s"
                          % (self.config.pin, now - since))
        if self.last_good is None:
            return Health(WARN, "no_reading", "leak probe not read yet")
        if self.wet_count:
            return Health(WARN, "wet", "leak probe wet %d time(s), not confirmed" % self.wet_count)
        return Health(OK, "", "dry")

    def values(self) -> Tuple[Tuple[str, str], ...]:
        """Key/value pairs for the node's diagnostics."""
        return (("pin", str(self.config.pin)), ("active high", str(self.config.active_high)),
                ("wet readings in a row", str(self.wet_count)), ("failed reads", str(self.read_failures)),
                ("leak since", "-" if self.leak_since is None else "%.1f" % self.leak_since))


def open_gpio_probe(config: LeakProbeHardware) -> Callable[[], Optional[bool]]:
    """The pin's reader through Jetson.GPIO (BOARD numbering, input, the probe drives the level): returns the
    level, or None when the read raised. Raises :class:`GpioUnavailable` (one line) when the library cannot run here."""
    try:
        import Jetson.GPIO as GPIO  # only on the robot: it refuses to import off a Jetson
    except Exception as exc:  # noqa: BLE001 - RuntimeError (permissions) or Exception (not a Jetson)
        raise GpioUnavailable("leak probe: Jetson.GPIO cannot run here (%s); on a Jetson, add the user to the gpio "
                           "group" % exc) from None
    GPIO.setwarnings(False)
    GPIO.setmode(GPIO.BOARD)
    GPIO.setup(config.pin, GPIO.IN)

    def read() -> Optional[bool]:
        try:
            return bool(GPIO.input(config.pin))
        except (RuntimeError, OSError, ValueError):
            return None

    return read


__all__ = ["GpioUnavailable", "LeakWatch", "open_gpio_probe"]
