"""ROS glue of :mod:`quadruped_common.health`: one ``health/<source>`` topic, as every hazard watcher publishes it."""
from __future__ import annotations

import rospy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from quadruped_common.health import ERROR, Health, HealthGate

#: Seconds between two health messages when nothing changes (2 Hz; the controller's health.max_age is 5 s).
HEALTH_PERIOD = 0.5


class HealthPublisher:
    """Publishes a ``health/<source>`` topic (``publisher``, of DiagnosticStatus) as
    ``diagnostic_msgs/DiagnosticStatus`` (the reason code first among its values) every :data:`HEALTH_PERIOD` and
    at once on a change (:class:`~quadruped_common.health.HealthGate`); an ERROR is also logged, at most every 5 s."""

    def __init__(self, publisher: rospy.Publisher, name: str, hardware_id: str) -> None:
        self.publisher, self.name, self.hardware_id = publisher, name, hardware_id
        self.gate = HealthGate(HEALTH_PERIOD)

    def publish(self, health: Health, now: float) -> None:
        """Publish ``health`` if it is due at ``now``."""
        if not self.gate.due(now, health):
            return
        if health.level == ERROR:
            rospy.logwarn_throttle(5.0, "%s: %s ERROR: %s" % (self.name.split(":")[0], self.publisher.resolved_name,
                                                               health.message))
        self.publisher.publish(DiagnosticStatus(
            level=health.level, name=self.name, message=health.message, hardware_id=self.hardware_id,
            values=[KeyValue(key, value) for key, value in ((("reason", health.reason),) + health.values)]))


__all__ = ["HEALTH_PERIOD", "HealthPublisher"]
