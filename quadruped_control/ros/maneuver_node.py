"""Commands one attitude maneuver on a running stack and ends the launch when it is over.

Used by the main job (launch/sim_maneuver.launch): waits until the controller is armed and streaming,
holds the initial setpoint for ~delay seconds, publishes the maneuver setpoint on
``attitude_setpoint_rpy_deg``, prints the geodesic error every 10 s and shuts down after
~duration seconds (it is a required node, so roslaunch then stops the whole graph and rosbag closes
its bag cleanly).

Parameters: ~roll ~pitch ~yaw (deg, default 45 0 0), ~delay (5 s), ~duration (120 s), ~timeout (60 s
to wait for the armed controller).
"""
from __future__ import annotations

import math
import threading
from typing import List, Optional

import rospy
from geometry_msgs.msg import Vector3Stamped

from underwater_quadruped.msg import ControllerState


class ManeuverNode:
    def __init__(self) -> None:
        self.setpoint = [float(rospy.get_param("~" + axis, default)) for axis, default in
                         (("roll", 45.0), ("pitch", 0.0), ("yaw", 0.0))]
        self.delay = float(rospy.get_param("~delay", 5.0))
        self.duration = float(rospy.get_param("~duration", 120.0))
        self.timeout = float(rospy.get_param("~timeout", 60.0))
        self.armed = threading.Event()
        self.last_error = math.nan
        self.publisher = rospy.Publisher("attitude_setpoint_rpy_deg", Vector3Stamped, queue_size=1, latch=True)
        rospy.Subscriber("controller_state", ControllerState, self._on_state, queue_size=1)

    def _on_state(self, msg: ControllerState) -> None:
        self.last_error = msg.geodesic_error
        if msg.armed and not msg.holding:
            self.armed.set()

    def run(self) -> None:
        if not self.armed.wait(self.timeout):
            rospy.logfatal("maneuver: the controller did not report armed and stroking within %.0f s", self.timeout)
            rospy.signal_shutdown("controller not ready")
            return
        rospy.sleep(self.delay)
        msg = Vector3Stamped()
        msg.header.stamp = rospy.Time.now()
        msg.vector.x, msg.vector.y, msg.vector.z = self.setpoint
        self.publisher.publish(msg)
        rospy.loginfo("maneuver: setpoint roll %.1f pitch %.1f yaw %.1f deg, running %.0f s", *(self.setpoint + [self.duration]))
        end = rospy.get_time() + self.duration
        while not rospy.is_shutdown() and rospy.get_time() < end:
            rospy.sleep(min(10.0, max(0.0, end - rospy.get_time())))
            rospy.loginfo("maneuver: %3.0f s left, geodesic error %.1f deg", max(0.0, end - rospy.get_time()),
                          math.degrees(self.last_error))
        rospy.signal_shutdown("maneuver complete")


def main(argv: Optional[List[str]] = None) -> None:
    rospy.init_node("maneuver")
    ManeuverNode().run()
