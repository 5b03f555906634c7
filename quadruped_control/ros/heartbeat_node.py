"""The tether heartbeat, from the laptop: ``tether/heartbeat`` (std_msgs/Header, stamped) at ``~rate`` (5 Hz).

The controller on the robot watches it (``~heartbeat_timeout``): arming needs it, and armed, its loss disarms
(the tether failsafe, docs/faults.md). ``monitor.launch`` starts it; any tool on the tether can run it instead.
"""
from __future__ import annotations

from typing import List, Optional

import rospy
from std_msgs.msg import Header

from quadruped_common.config import ParameterError
from quadruped_common.ros.node_startup import start_node


class HeartbeatNode:
    def __init__(self) -> None:
        rate = float(rospy.get_param("~rate", 5.0))
        if not 0.5 <= rate <= 100.0:
            raise ParameterError("~rate must be within [0.5, 100] Hz, got %r" % rate)
        self.pub = rospy.Publisher("tether/heartbeat", Header, queue_size=1)
        self.seq = 0
        self.timer = rospy.Timer(rospy.Duration(1.0 / rate), self._beat)
        rospy.loginfo("heartbeat_node: %s at %.1f Hz", rospy.resolve_name("tether/heartbeat"), rate)

    def _beat(self, _event) -> None:
        self.seq += 1
        self.pub.publish(Header(seq=self.seq, stamp=rospy.Time.now(), frame_id=rospy.get_name()))


def main(argv: Optional[List[str]] = None) -> None:
    start_node("heartbeat_node", HeartbeatNode)
    rospy.spin()
