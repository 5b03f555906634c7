"""``uq`` (``rosrun underwater_quadruped uq COMMAND``): the operator's commands over the tether, ROS side.

The commands, answers and exit codes are :mod:`quadruped_control.ros.operator_cli`'s; this module calls the services
and moves the messages. Names are relative, so under ROS_NAMESPACE=uq1 it commands that namespace's stack:
services ``attitude_controller/arm``, ``estop``, ``pwm_node/enable``; topics ``attitude_setpoint_rpy_deg`` (latched,
published until controller_state carries the setpoint), ``estop`` (the e-stop when its service does not answer),
``controller_state``, ``telemetry/*``, ``estop_state`` and ``/diagnostics`` (read).
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import rosgraph
import rospy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3, Vector3Stamped
from std_msgs.msg import Bool, Empty, Float64
from std_srvs.srv import SetBool

from quadruped_common.so3 import quat_to_rot
from quadruped_control.control.attitude_degrees import rpy_degrees
from quadruped_control.control.setpoint_sequence import PROTOCOLS, total_seconds
from quadruped_control.ros import operator_cli as cli
from quadruped_control.ros.maneuver_node import ManeuverNode
from underwater_quadruped.msg import ControllerState

CONTROLLER = "attitude_controller"


class Latest:
    """The latest message of each topic subscribed (under a key), waited for with :meth:`wait`."""

    def __init__(self) -> None:
        self.messages: Dict[str, Any] = {}
        self.arrived = threading.Condition()

    def subscribe(self, topic: str, kind: type, key: str = "", pick: Optional[Callable[[Any], Any]] = None) -> None:
        """Keep ``topic``'s messages under ``key`` (default the topic), or what ``pick`` makes of them (None: skip)."""
        def store(msg: Any) -> None:
            value = msg if pick is None else pick(msg)
            if value is not None:
                with self.arrived:
                    self.messages[key or topic] = value
                    self.arrived.notify_all()
        rospy.Subscriber(topic, kind, store, queue_size=5)

    def wait(self, done: Callable[[Dict[str, Any]], bool], timeout: float) -> bool:
        """Whether ``done(messages)`` came true within ``timeout`` s."""
        deadline = time.monotonic() + timeout
        with self.arrived:
            while not done(self.messages):
                left = deadline - time.monotonic()
                if left <= 0.0 or rospy.is_shutdown():
                    return False
                self.arrived.wait(min(left, 0.1))
        return True


def call(service: str, value: bool, timeout: float) -> Tuple[Optional[bool], str]:
    """A SetBool service's (success, message); (None, why) when it does not answer within ``timeout``."""
    name = rospy.resolve_name(service)
    try:
        rospy.wait_for_service(name, timeout)
        reply = rospy.ServiceProxy(name, SetBool)(value)
    except rospy.ROSException:
        return None, "no answer from %s within %.1f s (is its node running?)" % (name, timeout)
    except rospy.ServiceException as exc:
        return None, "%s failed: %s" % (name, exc)
    return bool(reply.success), reply.message


def answer(success: Optional[bool], message: str) -> int:
    """Print ``message``; the exit status: OK, REFUSED (success False) or NO_ANSWER (None)."""
    print(message, flush=True)
    return cli.NO_ANSWER if success is None else cli.OK if success else cli.REFUSED


def connected(publisher: rospy.Publisher, timeout: float) -> bool:
    """Whether a subscriber connects to ``publisher`` within ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while publisher.get_num_connections() == 0:
        if time.monotonic() > deadline or rospy.is_shutdown():
            return False
        time.sleep(0.02)
    return True


def arm(value: bool, timeout: float) -> int:
    return answer(*call(CONTROLLER + "/arm", value, timeout))


def stop(timeout: float) -> int:
    """The estop service; when it does not answer, the estop topic, confirmed by estop_state."""
    success, message = call("estop", True, timeout)
    if success is not None:
        return answer(success, message)
    latest = Latest()
    latest.subscribe("estop_state", Bool)
    publisher = rospy.Publisher("estop", Empty, queue_size=1, latch=True)
    publisher.publish(Empty())
    latched = connected(publisher, timeout) and latest.wait(
        lambda m: "estop_state" in m and m["estop_state"].data, timeout)
    return answer(True if latched else None, "%s; e-stop sent on %s: %s" % (
        message, publisher.resolved_name, "latched (estop_state)" if latched else "NOT confirmed by estop_state"))


def reset(timeout: float) -> int:
    """estop false, then pwm_node/enable true."""
    success, message = call("estop", False, timeout)
    if not success:
        return answer(success, message)
    enabled, enable_message = call("pwm_node/enable", True, timeout)
    return answer(enabled, "%s; %s" % (message, enable_message))


def _world_setpoint(state: ControllerState) -> Any:
    q = state.setpoint
    return quat_to_rot([q.x, q.y, q.z, q.w])


def _heading(messages: Dict[str, Any]) -> Optional[float]:
    heading = messages.get("heading")
    return None if heading is None else heading.data


def setpoint(rpy: Tuple[float, float, float], frame: str, timeout: float) -> int:
    """Publish the setpoint (latched) and wait until controller_state carries it."""
    mode = frame or str(rospy.get_param(CONTROLLER + "/yaw_reference", "relative"))
    latest = Latest()
    latest.subscribe("controller_state", ControllerState)
    latest.subscribe("telemetry/heading_at_arming_deg", Float64, key="heading")
    publisher = rospy.Publisher("attitude_setpoint_rpy_deg", Vector3Stamped, queue_size=1, latch=True)
    msg = Vector3Stamped(vector=Vector3(*rpy))
    msg.header.stamp, msg.header.frame_id = rospy.Time.now(), frame
    publisher.publish(msg)
    if not connected(publisher, timeout):
        return answer(None, "nothing subscribes to %s within %.1f s (is the controller running?)"
                      % (publisher.resolved_name, timeout))

    def taken(messages: Dict[str, Any]) -> bool:
        state = messages.get("controller_state")
        if state is None or "heading" not in messages:
            return False
        return cli.setpoint_taken(_world_setpoint(state), cli.expected_setpoint(rpy, mode, _heading(messages)))

    taken_in_time = latest.wait(taken, timeout)
    state = latest.messages.get("controller_state")
    if state is None:
        return answer(None, "no controller_state within %.1f s (is the controller running?)" % timeout)
    world = rpy_degrees(_world_setpoint(state))
    if taken_in_time:
        return answer(True, cli.setpoint_answer(rpy, mode, world, _heading(latest.messages)))
    return answer(False, "setpoint NOT taken within %.1f s: the controller's is world %s (its log says why)"
                  % (timeout, cli.format_rpy(world)))


def status(timeout: float) -> int:
    """One line from controller_state, telemetry, estop_state and, disarmed, the arming diagnostic."""
    arming = rospy.resolve_name(CONTROLLER)[1:] + ": arming"
    latest = Latest()
    for topic, kind, key in (("controller_state", ControllerState, ""), ("telemetry/rpy_deg", Vector3Stamped, "rpy"),
                             ("telemetry/setpoint_rpy_deg", Vector3Stamped, "setpoint"),
                             ("telemetry/heading_at_arming_deg", Float64, "heading"), ("estop_state", Bool, "")):
        latest.subscribe(topic, kind, key)
    latest.subscribe("/diagnostics", DiagnosticArray, "arming",
                     lambda msg: next((s.message for s in msg.status if s.name == arming), None))

    def heard(messages: Dict[str, Any]) -> bool:
        state = messages.get("controller_state")
        return (state is not None and {"rpy", "setpoint", "heading", "estop_state"} <= set(messages)
                and (state.armed or "arming" in messages))

    latest.wait(heard, timeout)
    messages = dict(latest.messages)
    state = messages.get("controller_state")
    if state is None:
        return answer(None, "no controller_state within %.1f s (is the controller running?)" % timeout)

    def rpy(key: str) -> Optional[Tuple[float, float, float]]:
        v = messages[key].vector if key in messages else None
        return None if v is None else (v.x, v.y, v.z)

    estop = messages.get("estop_state")
    return answer(True, cli.format_status(cli.Status(
        armed=state.armed, holding=state.holding, hold_reason=state.hold_reason, rpy=rpy("rpy"),
        setpoint=rpy("setpoint"), heading=_heading(messages), estop=None if estop is None else estop.data,
        arming=messages.get("arming", ""))))


def sequence(name: str, timeout: float) -> int:
    """The maneuver node's code runs PROTOCOLS[name] from this process, in the foreground."""
    holds = PROTOCOLS[name]
    print("sequence %s: %d setpoints, %.0f s, once the controller is armed and stroking (Ctrl-C stops it)"
          % (name, len(holds), total_seconds(holds)), flush=True)
    node = ManeuverNode(holds, delay=0.0, timeout=timeout)
    interrupted = False
    try:
        completed = node.run()
    except KeyboardInterrupt:  # Ctrl-C, at once (rospy's own handler would wait for the maneuver's sleep)
        completed, interrupted = False, True
    if completed:
        return answer(True, "sequence %s complete" % name)
    if node.index < 0 and not interrupted:
        return answer(False, "sequence %s refused: the controller was not armed and stroking within %.1f s (uq arm "
                      "first; uq status says why not)" % (name, timeout))
    return answer(False, "sequence %s stopped %s" % (name, "before its first setpoint" if node.index < 0 else
                  "at setpoint %d of %d; the controller keeps that setpoint" % (node.index + 1, len(holds))))


def run(args: Any) -> int:
    """The command ``args`` names (operator_cli.parse_args), on a node of this process; its exit status."""
    if not rosgraph.is_master_online():
        return answer(None, "no ROS master at %s" % rosgraph.get_master_uri())
    rospy.init_node("uq", anonymous=True, disable_signals=True)  # Ctrl-C: KeyboardInterrupt, at once
    try:
        if args.command in ("arm", "disarm"):
            return arm(args.command == "arm", args.timeout)
        if args.command == "setpoint":
            return setpoint((args.roll, args.pitch, args.yaw), args.frame, args.timeout)
        if args.command == "sequence":
            return sequence(args.name, args.timeout)
        return {"stop": stop, "reset": reset, "status": status}[args.command](args.timeout)
    except KeyboardInterrupt:
        return answer(False, "uq %s interrupted" % args.command)
    finally:
        rospy.signal_shutdown("uq %s done" % args.command)


def main(argv: Optional[List[str]] = None) -> None:
    sys.exit(run(cli.parse_args(rospy.myargv(sys.argv if argv is None else argv)[1:])))
