"""The robot's real I2C bus: ``/dev/i2c-N`` through adafruit-extended-bus (Blinka), imported lazily.

Only this function touches Blinka, and only when called, so the rest of the package (and the
simulator) imports on machines without Blinka or a supported board.
"""
from __future__ import annotations

import os
from typing import Any


class I2CBackendError(RuntimeError):
    """The real I2C bus cannot be opened (library missing, device file missing or not permitted)."""


def open_i2c_bus(bus_number: int, frequency: int = 400000) -> Any:
    """Open ``/dev/i2c-<bus_number>`` as a bus object with the busio.I2C interface.

    ``frequency`` is informational on Linux (the bus clock comes from the device tree; set it to
    400 kHz there: the 100 Hz cycle needs it, see ``benchmarks/bench_bus_budget.py``).
    Raises :class:`I2CBackendError` with the fix when the backend or the device is unavailable.
    """
    if isinstance(bus_number, bool) or not isinstance(bus_number, int) or bus_number < 0:
        raise ValueError("I2C bus number must be a non-negative integer, got %r" % (bus_number,))
    device = "/dev/i2c-%d" % bus_number
    try:
        from adafruit_extended_bus import ExtendedI2C  # pylint: disable=import-outside-toplevel
    except Exception as exc:  # ImportError, or Blinka's board detection failing on this machine
        raise I2CBackendError(
            "cannot use the real I2C bus: importing adafruit_extended_bus failed (%s: %s). Install the "
            "pinned requirements (pip install -r requirements-jetson.txt: adafruit-extended-bus, "
            "Adafruit-Blinka), or run against the fake hardware (--fake / sim.launch)."
            % (type(exc).__name__, exc)) from exc
    if not os.path.exists(device):
        raise I2CBackendError("%s does not exist: enable the I2C controller (Jetson: sudo /opt/nvidia/jetson-io/"
                              "jetson-io.py) or pick the right bus in config/hardware.yaml (i2c.bus)" % device)
    if not os.access(device, os.R_OK | os.W_OK):
        raise I2CBackendError("no permission to open %s: add the user to the 'i2c' group "
                              "(sudo usermod -aG i2c $USER) and log in again" % device)
    try:
        return ExtendedI2C(bus_number, frequency=frequency)
    except (OSError, ValueError) as exc:
        raise I2CBackendError("opening %s failed: %s" % (device, exc)) from exc


__all__ = ["I2CBackendError", "open_i2c_bus"]
