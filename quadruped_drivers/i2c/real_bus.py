"""The robot's real I2C bus: ``/dev/i2c-N`` through adafruit-extended-bus (Blinka), imported lazily.

Only this function touches Blinka, and only when called, so the rest of the package (and the
simulator) imports on machines without Blinka or a supported board.
"""
from __future__ import annotations

import os
from typing import Any, Optional


class I2CBackendError(RuntimeError):
    """The real I2C bus cannot be opened (library missing, device file missing or not permitted).

    ``cause`` says what is wrong, ``fix`` what the operator does about it (the message is both). A
    ``fix`` marks the error as one a restart cannot fix (:mod:`quadruped_common.startup_errors`: the node
    ends with one line and is not started again); None (the adapter refused to open an existing,
    permitted device) leaves it to the restart."""

    def __init__(self, cause: str, fix: Optional[str] = None) -> None:
        super().__init__(cause if fix is None else "%s: %s" % (cause, fix))
        self.cause = cause
        self.fix = fix


def open_i2c_bus(bus_number: int, frequency: int = 400000) -> Any:
    """Open ``/dev/i2c-<bus_number>`` as a bus object with the busio.I2C interface.

    ``frequency`` is informational on Linux (the bus clock comes from the device tree; set it to
    400 kHz there: the 100 Hz cycle needs it, see ``benchmarks/bench_bus_budget.py``).
    Raises :class:`I2CBackendError` with the fix when the device or the backend is unavailable (the
    device first: without it the library cannot help).
    """
    if isinstance(bus_number, bool) or not isinstance(bus_number, int) or bus_number < 0:
        raise ValueError("I2C bus number must be a non-negative integer, got %r" % (bus_number,))
    device = "/dev/i2c-%d" % bus_number
    if not os.path.exists(device):
        raise I2CBackendError("%s does not exist" % device,
                              "enable the I2C controller (Jetson: sudo /opt/nvidia/jetson-io/jetson-io.py) or "
                              "pick the right bus in the hardware file (i2c.bus of config/hardware.yaml, "
                              "launch argument hardware_yaml)")
    if not os.access(device, os.R_OK | os.W_OK):
        raise I2CBackendError("no permission to open %s" % device,
                              "add the user to the 'i2c' group (sudo usermod -aG i2c $USER) and log in again")
    try:
        from adafruit_extended_bus import ExtendedI2C  # pylint: disable=import-outside-toplevel
    except Exception as exc:  # ImportError, or Blinka's board detection failing on this machine
        raise I2CBackendError(
            "cannot use the real I2C bus: importing adafruit_extended_bus failed (%s: %s)" % (type(exc).__name__, exc),
            "install the pinned requirements (pip install -r requirements-jetson.txt: adafruit-extended-bus, "
            "Adafruit-Blinka), or run against the fake hardware (--fake / sim.launch)") from exc
    try:
        return ExtendedI2C(bus_number, frequency=frequency)
    except (OSError, ValueError) as exc:
        raise I2CBackendError("opening %s failed: %s" % (device, exc)) from exc


__all__ = ["I2CBackendError", "open_i2c_bus"]
