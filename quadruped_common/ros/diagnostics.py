"""diagnostic_updater's Updater without parameter-server traffic in the nodes' loops.

``diagnostic_updater.Updater.update`` (Debian 12 and Noetic) re-reads ``~diagnostic_period`` from the
parameter server every 0.25 s, from inside ``update()``, and catches only ``http.client``'s
``CannotSendRequest`` and ``ResponseNotReady``. Every node of the stack calls ``update()`` from its
control or I/O loop, so with the ROS master gone (killed, or its host unreachable) the refused connection
(``ConnectionRefusedError``) was raised inside the controller's IMU callback, pwm_node's timer and
sim_node's physics step: the fault campaign's master kill ended the simulated robot
(``benchmarks/fault_campaign.py``, kind ``kill_rosmaster``). A remote master that does not answer would
instead block the loop for the length of a TCP time-out.

:class:`Updater` reads ``~diagnostic_period`` once, when it is built, and never asks the master again; the
diagnostics keep their period whatever happens to the master. A changed ``~diagnostic_period`` takes
effect when the node restarts.
"""
from __future__ import annotations

import rospy
from diagnostic_updater import Updater as _LibraryUpdater

__all__ = ["Updater"]


class Updater(_LibraryUpdater):
    """``diagnostic_updater.Updater`` with ``~diagnostic_period`` read once (module docstring)."""

    def __init__(self) -> None:
        super().__init__()
        period = rospy.get_param("~diagnostic_period", 1.0)
        try:
            period = float(period)
        except (TypeError, ValueError):
            period = 1.0
        self.period = period if period > 0.0 else 1.0

    def _check_diagnostic_period(self) -> None:
        """No parameter-server query from the nodes' loops (module docstring)."""
