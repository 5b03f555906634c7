"""Commands one attitude maneuver, or a sequence of setpoints held in turn, on a running stack and ends the
launch when it is over.

Used by the main job (launch/sim_maneuver.launch) and the step test (launch/step_test.launch): waits until the
controller is armed and streaming, holds the initial setpoint for ~delay seconds, then publishes on
``attitude_setpoint_rpy_deg`` either the one maneuver setpoint for ~duration seconds or each setpoint of the
sequence for its own time (:mod:`quadruped_control.control.setpoint_sequence`), prints the geodesic error every
10 s and shuts down at the end (it is a required node, so roslaunch then stops the whole graph and rosbag
closes its bag cleanly).

Parameters: ~roll ~pitch ~yaw (deg, default 45 0 0) and ~duration (120 s) for one maneuver; ~protocol (a name
of setpoint_sequence.PROTOCOLS, e.g. step_test) or ~sequence (a list of [roll, pitch, yaw, seconds]) for a
sequence, which then replaces them; ~delay (5 s), ~timeout (60 s to wait for the armed controller). A bad
protocol or sequence ends the launch at once with the reason, before anything is published. A controller that
stops acting (disarmed, or holding its safe pose) once the maneuver has begun is logged as a warning, and again
when it acts again; the setpoints keep their schedule.
"""
from __future__ import annotations

import math
import threading
from typing import List, Optional, Tuple

import rospy
from geometry_msgs.msg import Vector3Stamped

from quadruped_common.config import ParameterError
from quadruped_control.control.setpoint_sequence import SetpointHold, command_sequence, total_seconds
from underwater_quadruped.msg import ControllerState


class ManeuverNode:
    """The sequence, ~delay and ~timeout from the node's parameters (module docstring), or given (the operator tool's
    ``uq sequence``, the tank day's runs); :meth:`run` commands it and ends the node, :meth:`command` only commands
    it. ``frame_id``: the setpoints' yaw reference (header.frame_id; empty: the controller's ~yaw_reference). Setting
    ``stop`` ends a sequence early, within 10 s, and silences the warning of a controller that stops acting."""

    def __init__(self, sequence: Optional[Tuple[SetpointHold, ...]] = None, delay: Optional[float] = None,
                 timeout: Optional[float] = None, frame_id: str = "") -> None:
        if sequence is None:
            maneuver = tuple(float(rospy.get_param("~" + axis, default)) for axis, default in
                             (("roll", 45.0), ("pitch", 0.0), ("yaw", 0.0)))
            sequence = command_sequence(str(rospy.get_param("~protocol", "") or ""),
                                        rospy.get_param("~sequence", []), maneuver,  # type: ignore[arg-type]
                                        float(rospy.get_param("~duration", 120.0)))
        self.sequence = sequence
        self.delay = float(rospy.get_param("~delay", 5.0)) if delay is None else delay
        self.timeout = float(rospy.get_param("~timeout", 60.0)) if timeout is None else timeout
        self.armed = threading.Event()
        self.last_error = math.nan
        self.acting = False
        self.index = -1  # the setpoint being published, from 0; -1 before the first
        self.frame_id = frame_id
        self.stop = threading.Event()
        self.publisher = rospy.Publisher("attitude_setpoint_rpy_deg", Vector3Stamped, queue_size=1, latch=True)
        rospy.Subscriber("controller_state", ControllerState, self._on_state, queue_size=1)

    def _on_state(self, msg: ControllerState) -> None:
        self.last_error = msg.geodesic_error
        acting = bool(msg.armed and not msg.holding)
        if not acting and self.acting and self.armed.is_set() and not self.stop.is_set():
            # the sequence keeps its schedule (a disarmed or holding controller ignores the setpoint); say so, as
            # the step test's reading cuts the response here and leaves out a step taken soon after
            rospy.logwarn("maneuver: the controller stopped acting %s (%s); the sequence goes on", self._where(),
                          (msg.hold_reason or "holding") if msg.armed else "disarmed")
        elif acting and not self.acting and self.armed.is_set():
            rospy.loginfo("maneuver: the controller acts again %s", self._where())
        self.acting = acting
        if acting:
            self.armed.set()

    def _where(self) -> str:
        return "before the first setpoint" if self.index < 0 else "during setpoint %d" % (self.index + 1)

    def publish(self, hold: SetpointHold, index: int) -> None:
        """Publish the ``index``-th setpoint of the sequence (latched) and log it."""
        msg = Vector3Stamped()
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = self.frame_id
        msg.vector.x, msg.vector.y, msg.vector.z = hold.rpy_deg
        self.publisher.publish(msg)
        rospy.loginfo("maneuver: setpoint %d of %d: roll %.1f pitch %.1f yaw %.1f deg, for %.0f s",
                      index + 1, len(self.sequence), *(hold.rpy_deg + (hold.seconds,)))

    def run(self) -> bool:
        """Wait for the armed controller, command the sequence, shut the node down; True when it ran to its end."""
        completed = self.command()
        rospy.signal_shutdown("maneuver complete" if completed else "maneuver not completed")
        return completed

    def command(self) -> bool:
        """Wait for the armed controller and command the sequence; True when it ran to its end."""
        if not self.armed.wait(self.timeout):
            rospy.logfatal("maneuver: the controller did not report armed and stroking within %.0f s", self.timeout)
            return False
        rospy.sleep(self.delay)
        end = rospy.get_time() + total_seconds(self.sequence)
        hold_end = rospy.get_time()
        for index, hold in enumerate(self.sequence):
            if rospy.is_shutdown() or self.stop.is_set():
                return False
            self.index = index
            self.publish(hold, index)
            hold_end += hold.seconds  # from the sequence's start: no drift from the publishing's own time
            while not rospy.is_shutdown() and not self.stop.is_set() and rospy.get_time() < hold_end:
                rospy.sleep(min(10.0, max(0.0, hold_end - rospy.get_time())))
                rospy.loginfo("maneuver: %3.0f s left, geodesic error %.1f deg", max(0.0, end - rospy.get_time()),
                              math.degrees(self.last_error))
        return not (rospy.is_shutdown() or self.stop.is_set())


def main(argv: Optional[List[str]] = None) -> None:
    rospy.init_node("maneuver")
    try:
        node = ManeuverNode()
    except ParameterError as exc:
        rospy.logfatal("maneuver: %s", exc)
        rospy.signal_shutdown(str(exc))
        return
    node.run()
