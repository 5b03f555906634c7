"""I2C plumbing shared by the drivers: the bus-object interface, bounded bus locking, fakes, real bus.

A *bus object* is anything with the adafruit bus-device subset that Blinka's ``busio.I2C`` offers:
``try_lock()``, ``unlock()``, ``writeto(addr, buf, *, start=0, end=None)``,
``readfrom_into(addr, buf, *, start=0, end=None)``,
``writeto_then_readfrom(addr, out, in_, *, out_start=0, out_end=None, in_start=0, in_end=None)`` and
``scan()``. A NACK or bus error raises ``OSError`` (errno ENXIO/EREMOTEIO/EIO as Linux i2c-dev does).
Implementations here: :class:`~quadruped_drivers.i2c.fake_bus.FakeI2CBus` (register-level fakes),
:class:`~quadruped_drivers.bus_bridge.BridgedI2CBus` (socket to a fake bus in another process) and
:func:`~quadruped_drivers.i2c.real_bus.open_i2c_bus` (``/dev/i2c-N`` through adafruit-extended-bus).

Nothing in this package imports Blinka (``busio``/``board``) at import time.
"""
from __future__ import annotations

import errno
import time
from contextlib import contextmanager
from typing import Any, Callable, Iterator

#: Default upper bound on waiting for another user of the same bus object to release it.
DEFAULT_LOCK_TIMEOUT = 0.02


class BusLockTimeout(OSError):
    """The bus object stayed locked by someone else for longer than the allowed wait."""


@contextmanager
def bus_locked(bus: Any, timeout: float = DEFAULT_LOCK_TIMEOUT,
               clock: Callable[[], float] = time.monotonic) -> Iterator[Any]:
    """Hold ``bus``'s lock for the body of a ``with`` block; always unlock, even on error.

    Unlike ``adafruit_bus_device.I2CDevice.__enter__`` (which spins on ``try_lock`` forever) the wait
    is bounded: after ``timeout`` seconds :class:`BusLockTimeout` (an ``OSError`` with errno EBUSY) is
    raised, so a bus left locked by a buggy user degrades one control cycle instead of hanging it.
    """
    deadline = clock() + timeout
    while not bus.try_lock():
        if clock() >= deadline:
            raise BusLockTimeout(errno.EBUSY, "I2C bus still locked after %.3f s" % timeout)
        time.sleep(0.0002)
    try:
        yield bus
    finally:
        bus.unlock()


__all__ = ["DEFAULT_LOCK_TIMEOUT", "BusLockTimeout", "bus_locked"]
