"""Who may use an I2C bus: the stack's driver nodes together, or one tool alone.

Every process that opens a bus (the real ``/dev/i2c-N`` or the simulated robot's) takes its lock first:

* a driver node takes a *role* (``pwm``, ``feedback``, ``depth``): the bus shared with the other roles (the kernel
  keeps each transaction whole, the chips do not overlap), but one process per role;
* a tool (calibration, jog, pre-dive check) takes the bus alone.

A second taker is refused with :class:`BusBusyError` naming the process that holds it (pid and command
line). Locks are ``flock`` on files in :func:`lock_dir`: the kernel drops them when the holder exits, however
it exits, so a crash never leaves the bus locked. Each lock file holds its holder's pid and command line.
"""
from __future__ import annotations

import errno
import fcntl
import os
import re
import sys
import tempfile
from typing import Dict, List, Optional, Tuple

from quadruped_common.startup_errors import FIX_BUSY

__all__ = ["BusBusyError", "BusLock", "lock_bus", "lock_dir"]

#: The roles the driver nodes take; any other name is refused.
ROLES = ("pwm", "feedback", "depth")
_held: Dict[Tuple[str, Optional[str]], "BusLock"] = {}


class BusBusyError(OSError):
    """The bus is held by another process (the message names it)."""


def lock_dir() -> str:
    """Where the lock files live: ``$UQ_LOCK_DIR``, else ``/run/lock`` if writable, else the temp folder."""
    chosen = os.environ.get("UQ_LOCK_DIR")
    if chosen:
        return chosen
    return "/run/lock" if os.access("/run/lock", os.W_OK) else tempfile.gettempdir()


def _name(bus: str) -> str:
    return "underwater_quadruped-%s" % re.sub(r"[^A-Za-z0-9_.-]", "_", bus)


def _holder(path: str) -> str:
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read().strip() or "unknown process"
    except OSError:
        return "unknown process"


def _me() -> str:
    return "pid %d: %s" % (os.getpid(), " ".join(sys.argv) or sys.executable)


class BusLock:
    """The lock of one bus (``bus``, e.g. ``i2c-7``) for one ``role`` (None: a tool, alone). Take it with
    :meth:`acquire`; it holds until :meth:`release` or the process ends."""

    def __init__(self, bus: str, role: Optional[str] = None, directory: Optional[str] = None) -> None:
        if role is not None and role not in ROLES:
            raise ValueError("bus lock role must be one of %s or None, got %r" % (", ".join(ROLES), role))
        self.bus = bus
        self.role = role
        base = os.path.join(directory or lock_dir(), _name(bus))
        self._bus_path = base + ".lock"
        self._role_path = None if role is None else "%s.%s.lock" % (base, role)
        self._fds: List[int] = []

    def acquire(self) -> "BusLock":
        """Take the lock, or raise :class:`BusBusyError` naming the holder (nothing held then)."""
        try:
            if self._role_path is not None:
                self._take(self._role_path, fcntl.LOCK_EX, write=True)
                self._take(self._bus_path, fcntl.LOCK_SH, write=False)
            else:
                self._take(self._bus_path, fcntl.LOCK_EX, write=True)
        except BusBusyError:
            self.release()
            raise
        return self

    def _take(self, path: str, mode: int, write: bool) -> None:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, mode | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            holders = self._holders(path)
            busy = BusBusyError("the I2C bus %s is in use by %s: stop it first" % (self.bus, holders))
            busy.errno = errno.EBUSY
            busy.cause = "the I2C bus %s is in use by %s" % (self.bus, holders)  # a node's one start-up line
            busy.fix = FIX_BUSY
            raise busy from None
        self._fds.append(fd)
        if write:
            os.ftruncate(fd, 0)
            os.pwrite(fd, _me().encode("utf-8", "replace"), 0)

    def _holders(self, path: str) -> str:
        if path != self._bus_path:
            return _holder(path)  # the other process of this role
        # the bus file: held alone by a tool (its name is in the file) or shared by the roles (theirs are)
        roles = [p for p in ("%s.%s.lock" % (self._bus_path[:-5], r) for r in ROLES)
                 if p != self._role_path and _is_held(p)]
        return "; ".join(_holder(p) for p in roles) if roles else _holder(path)

    def release(self) -> None:
        """Drop the lock (closing the files drops the flocks)."""
        for fd in self._fds:
            os.close(fd)
        self._fds = []


def _is_held(path: str) -> bool:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except OSError:
        return True
    finally:
        os.close(fd)


def lock_bus(bus: str, role: Optional[str] = None) -> BusLock:
    """Take ``bus``'s lock for this process's lifetime (again: the same lock); :class:`BusBusyError` if held."""
    key = (bus, role)
    if key not in _held:
        _held[key] = BusLock(bus, role).acquire()
    return _held[key]
