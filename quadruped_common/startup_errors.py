"""Which start-up errors a restart cannot fix, and the one line a node ends with for them (no rospy).

A node that fails while it starts (:func:`quadruped_common.ros.node_startup.start_node`: the node object
raised) ends in one of two ways:

* **permanent**: a restart would fail the same way until someone changes the machine or the
  configuration. One FATAL line ``"<node> cannot start: <cause>. Fix: <fix>"``, no traceback, exit status
  :data:`EX_CONFIG`; the node's supervisor (:mod:`quadruped_common.supervise`) does not start it again;
* **anything else** (a crash, a timeout, a link that is not up yet): the traceback and exit status 1; the
  supervisor starts the node again after its back-off.

Permanent (:func:`permanent_cause`), in this order:

* an exception that names its own fix: a non-empty ``fix`` attribute (and ``cause``, default its
  message), e.g. :class:`quadruped_drivers.i2c.real_bus.I2CBackendError` for a missing device file, no
  permission or the library missing;
* ``ImportError``: a library missing;
* ``ValueError``, hence :class:`~quadruped_common.config.ParameterError`: a configuration refused (the
  message names the file and the key, or the parameter);
* ``OSError`` with errno ``EBUSY`` (:class:`quadruped_drivers.i2c.bus_lock.BusBusyError`: another process
  holds the bus), ``EACCES`` / ``EPERM`` (no permission), or ``ENOENT`` / ``ENODEV`` / ``ENXIO`` naming a
  file (a device file or a file missing). An ``OSError`` without a file name or with another errno
  (connection refused, a time-out, the simulated bus's socket not there yet) is not permanent.
"""
from __future__ import annotations

import errno
from typing import NamedTuple, Optional, Tuple, Type

#: Exit status of a node that cannot start and must not be started again (sysexits.h EX_CONFIG).
EX_CONFIG = 78

_MISSING = (errno.ENOENT, errno.ENODEV, errno.ENXIO)
_NOT_PERMITTED = (errno.EACCES, errno.EPERM)

FIX_CONFIGURATION = ("correct the value named above (in the configuration file or the launch argument) and start "
                     "the launch again")
FIX_LIBRARY = ("install the pinned requirements (on the robot: pip install -r requirements-jetson.txt; "
               "elsewhere: bash scripts/setup.sh)")
FIX_BUSY = "stop that process (a tool, or a second launch of the stack), then start the launch again"
FIX_PERMISSION = ("give the user access (group of the device, udev rule: docs/on_the_robot.md), log in "
                  "again and start the launch again")
FIX_MISSING = "connect the device or correct the path in the configuration, then start the launch again"


class PermanentCause(NamedTuple):
    """Why a node cannot start (``cause``) and what the operator does about it (``fix``)."""
    cause: str
    fix: str


def _one_line(text: str) -> str:
    return " ".join(str(text).split()).rstrip(" .:;")


def permanent_cause(exc: BaseException, extra: Tuple[Type[BaseException], ...] = ()) -> Optional[PermanentCause]:
    """The cause and fix when ``exc``, raised while a node starts, is permanent (module docstring);
    None when a restart may fix it. ``extra``: more exception types to take as a configuration refused."""
    fix = getattr(exc, "fix", None)
    if isinstance(fix, str) and fix.strip():
        cause = getattr(exc, "cause", None)
        return PermanentCause(_one_line(cause if isinstance(cause, str) and cause.strip() else exc), _one_line(fix))
    message = _one_line(exc) or type(exc).__name__
    if isinstance(exc, ImportError):
        return PermanentCause("%s: %s" % (type(exc).__name__, message), FIX_LIBRARY)
    if isinstance(exc, ValueError) or (extra and isinstance(exc, extra)):
        return PermanentCause(message, FIX_CONFIGURATION)
    if isinstance(exc, OSError):
        if exc.errno == errno.EBUSY:
            return PermanentCause(message, FIX_BUSY)
        if exc.errno in _NOT_PERMITTED:
            return PermanentCause(message, FIX_PERMISSION)
        if exc.errno in _MISSING and exc.filename is not None:
            return PermanentCause(message, FIX_MISSING)
    return None


def cannot_start_line(node: str, cause: PermanentCause) -> str:
    """The one line a node that cannot start ends with: ``"<node> cannot start: <cause>. Fix: <fix>"``."""
    return "%s cannot start: %s. Fix: %s" % (node, _one_line(cause.cause), _one_line(cause.fix))


__all__ = ["EX_CONFIG", "PermanentCause", "cannot_start_line", "permanent_cause"]
