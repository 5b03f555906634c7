"""Bus opening shared by the I2C driver nodes (no rospy here, so it is testable without ROS).

``backend: real`` opens the Jetson's I2C device by bus number (lazily importing the real backend);
``backend: sim`` connects to the simulated robot's fake bus through the bus bridge socket, waiting for
``sim_node`` to create it. The driver code above the bus object is identical in both cases.
"""
from __future__ import annotations

import dataclasses
import os
import time
from typing import Callable, Optional

from quadruped_drivers.i2c.bus_lock import lock_bus

#: Failsafes a PWM channel can take when the command watchdog trips.
FAILSAFES = ("hold", "neutral", "off")

BACKENDS = ("real", "sim")


def bus_name(backend: str, bus_number: int, socket_path: str) -> str:
    """The name of the bus a backend opens, for its lock: ``i2c-7``, or ``sim-<socket file>``."""
    return "i2c-%d" % bus_number if backend == "real" else "sim-" + os.path.basename(socket_path)


def open_bus(backend: str, bus_number: int, socket_path: str, role: Optional[str] = None, wait: float = 15.0,
             sleep: Callable[[float], None] = time.sleep, clock: Callable[[], float] = time.monotonic):
    """Return a bus object with the adafruit bus-device interface for ``backend``, holding the bus's lock
    (:mod:`quadruped_drivers.i2c.bus_lock`) for ``role`` (a driver node's; None: a tool, alone).

    Raises ``ValueError`` for an unknown backend, :class:`~quadruped_drivers.i2c.bus_lock.BusBusyError` when
    another process holds the bus, and ``OSError`` when the bus cannot be opened (for ``sim``: the socket did
    not appear within ``wait`` seconds).
    """
    if backend not in BACKENDS:
        raise ValueError("unknown bus backend %r, expected one of %s" % (backend, ", ".join(BACKENDS)))
    lock_bus(bus_name(backend, bus_number, socket_path), role)
    if backend == "real":
        from quadruped_drivers.i2c.real_bus import open_i2c_bus
        return open_i2c_bus(bus_number)
    if backend == "sim":
        from quadruped_drivers.bus_bridge import BridgedI2CBus
        deadline = clock() + wait
        while not os.path.exists(socket_path):
            if clock() > deadline:
                raise OSError("simulated I2C bus socket %s did not appear within %.0f s (is sim_node "
                              "running?)" % (socket_path, wait))
            sleep(0.05)
        return BridgedI2CBus(socket_path)
    raise ValueError("unknown bus backend %r, expected one of %s" % (backend, ", ".join(BACKENDS)))


def with_failsafe(hardware, failsafe: str):
    """``hardware`` with every channel's watchdog failsafe set to ``failsafe`` ("" keeps the file's)."""
    if not failsafe:
        return hardware
    if failsafe not in FAILSAFES:
        raise ValueError("failsafe must be one of %s, got %r" % (", ".join(FAILSAFES), failsafe))
    joints = tuple(dataclasses.replace(joint, failsafe=failsafe) for joint in hardware.joints)
    return dataclasses.replace(hardware, joints=joints)
