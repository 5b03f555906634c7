"""How every long-running node of the stack starts and stops (ROS glue shared by drivers and controller).

:func:`start_node` is each node's ``main`` up to ``rospy.spin()``:

* ``rospy.init_node``, then the node object. A start-up error a restart cannot fix (a configuration
  refused, a device file missing, no permission, a library missing, the bus held by another process:
  :mod:`quadruped_common.startup_errors`) is one FATAL line ``"<node> cannot start: <cause>. Fix: <fix>"``
  and exit status :data:`~quadruped_common.startup_errors.EX_CONFIG` (78), not a traceback: the node's
  supervisor (:mod:`quadruped_common.supervise`) does not start it again. Any other error raised there
  keeps its traceback and exit status 1: the supervisor starts the node again after its back-off;
* the start-up heap frozen (:mod:`quadruped_common.heap`): no full garbage collection walks it again;
* :func:`stop_xmlrpc_server_on_shutdown`, the work-around for ros/ros_comm#2238 below.

:func:`stack_clock` is the clock a driver judges ages and timeouts on (command watchdog, link silence,
stale readings): the one its ROS timers run on.

ros/ros_comm#2238 (open in Noetic, which is end-of-life): ``rosgraph.xmlrpc.XmlRpcNode.shutdown``
closes the listening socket but never asks ``socketserver``'s ``serve_forever`` loop to stop. The
loop's ``poll`` then reports the closed descriptor as ready at once, forever: one thread per node
spins at 100 % of a core. The stack's control path runs SCHED_FIFO, so after Ctrl-C those spinning
threads held both cores of the development machine, the nodes missed roslaunch's 15 s SIGINT grace
period and were killed with SIGKILL. The work-around stops the loop the documented way
(``BaseServer.shutdown``) from a client shutdown hook, before rospy closes the socket.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Tuple, Type, TypeVar

import rospy
import rosgraph.xmlrpc

from quadruped_common.heap import frozen_startup_heap
from quadruped_common.startup_errors import EX_CONFIG, cannot_start_line, permanent_cause

NodeT = TypeVar("NodeT")


def stop_xmlrpc_server(node: rosgraph.xmlrpc.XmlRpcNode, timeout: float = 2.0) -> bool:
    """End ``node``'s XML-RPC serving thread (ros/ros_comm#2238); True when it ended within ``timeout``.

    ``is_shutdown`` first, so that ``XmlRpcNode._run`` does not call ``serve_forever`` again once it
    returns; ``BaseServer.shutdown`` then ends ``serve_forever`` within its 0.5 s poll interval. It is
    called from a helper thread because it blocks until the loop ends, and would block for ever if the
    loop was not running.
    """
    server = node.server
    if server is None:
        return True  # never started, or already shut down by rospy
    node.is_shutdown = True
    stopper = threading.Thread(target=server.shutdown, name="xmlrpc-stop", daemon=True)
    stopper.start()
    stopper.join(timeout)
    return not stopper.is_alive()


def _this_process_xmlrpc_node() -> rosgraph.xmlrpc.XmlRpcNode:
    # rospy.init_node keeps its XmlRpcNode only as the bound method node.shutdown in rospy's internal
    # shutdown hooks; there is no public accessor.
    for hook in rospy.core._shutdown_hooks:  # noqa: SLF001 (see above)
        owner = getattr(hook, "__self__", None)
        if isinstance(owner, rosgraph.xmlrpc.XmlRpcNode):
            return owner
    raise RuntimeError("rospy.init_node has not started an XML-RPC server in this process")


def stop_xmlrpc_server_on_shutdown() -> None:
    """Register :func:`stop_xmlrpc_server` for this process's node (after ``rospy.init_node``)."""
    node = _this_process_xmlrpc_node()
    rospy.on_shutdown(lambda: stop_xmlrpc_server(node))


def stack_clock() -> Callable[[], float]:
    """The clock of the node's timers as a function of seconds: ROS time under ``/use_sim_time``
    (simulated time in lock-step: a slow step on a loaded machine is no timeout there, and the
    watchdogs act at the same simulated moments in every run), ``time.monotonic`` otherwise (wall time
    can jump). Read it after ``init_node``."""
    return rospy.get_time if rospy.get_param("/use_sim_time", False) else time.monotonic


def start_node(name: str, build: Callable[[], NodeT], errors: Tuple[Type[BaseException], ...] = ()) -> NodeT:
    """``rospy.init_node(name)`` and ``build()`` (module docstring); returns the node object.

    ``errors``: more exception types that mean "this configuration cannot run" (exit 78, one line), beyond
    those of :func:`quadruped_common.startup_errors.permanent_cause`.

    Call ``rospy.spin()`` (or the node's own loop) after it. The XML-RPC hook is registered after the
    node object: rospy runs client hooks in registration order, so the node's own ``rospy.on_shutdown``
    hooks (pwm_node: outputs off) run first and are not delayed by the up to 0.5 s the server takes
    to stop.
    """
    with frozen_startup_heap():
        rospy.init_node(name)
        try:
            node = build()
        except Exception as exc:  # noqa: BLE001 - sorted into permanent (one line, 78) and the rest (re-raised)
            cause = permanent_cause(exc, errors)
            if cause is None:
                raise  # a restart may fix it: traceback, exit status 1
            rospy.logfatal(cannot_start_line(name, cause))
            raise SystemExit(EX_CONFIG) from None
        stop_xmlrpc_server_on_shutdown()
    return node


__all__ = ["stack_clock", "start_node", "stop_xmlrpc_server", "stop_xmlrpc_server_on_shutdown"]
