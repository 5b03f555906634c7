"""ROS glue of the enclosure's leak probe (a Jetson GPIO pin; the simulated robot's pin in simulation).

Publishes
  health/leak   diagnostic_msgs/DiagnosticStatus  2 Hz and at once on a change (:class:`~quadruped_drivers.leak.
                LeakWatch`): ERROR ``leak`` (latched), ERROR ``no_reading``, WARN ``wet`` (not yet confirmed), OK
  diagnostics   the pin, its last readings, failed reads
Services
  ~reset        std_srvs/Trigger  clear a latched leak report (refused while the probe reads wet)
Parameters
  ~backend (real: Jetson.GPIO | sim: the level sim_node publishes on sim/leak_probe, std_msgs/Bool)
  ~hardware_yaml (the leak section)  ~fitted (false: hardware_yaml decides; true: fitted whatever it says, the
  simulated robot's probe)
"""
from __future__ import annotations

from typing import Callable, List, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from std_msgs.msg import Bool
from std_srvs.srv import Trigger, TriggerResponse

from quadruped_common.ros.diagnostics import Updater
from quadruped_common.ros.health import HEALTH_PERIOD, HealthPublisher
from quadruped_common.ros.node_startup import stack_clock, start_node
from quadruped_drivers.hardware_config import load_hardware_config, with_leak_fitted
from quadruped_drivers.leak import GpioUnavailable, LeakWatch, open_gpio_probe
from quadruped_drivers.node_support import BACKENDS


class SimulatedPin:
    """The simulated robot's pin: the last level on ``sim/leak_probe``; None (a failed read) once it is older than
    ``max_age`` seconds (sim_node gone)."""

    def __init__(self, clock: Callable[[], float], max_age: float) -> None:
        self.clock, self.max_age = clock, max_age
        self.level: Optional[bool] = None
        self.stamp = -float("inf")
        rospy.Subscriber("sim/leak_probe", Bool, self._on_level, queue_size=1)

    def _on_level(self, msg: Bool) -> None:
        self.level, self.stamp = bool(msg.data), self.clock()

    def read(self) -> Optional[bool]:
        return self.level if self.clock() - self.stamp <= self.max_age else None


class LeakNode:
    def __init__(self) -> None:
        hardware = load_hardware_config(rospy.get_param("~hardware_yaml", "") or None)
        if rospy.get_param("~fitted", False):
            hardware = with_leak_fitted(hardware)
        self.config = hardware.leak
        self.clock = stack_clock()
        backend = rospy.get_param("~backend", "real")
        if backend not in BACKENDS:
            raise ValueError("~backend must be one of %s, got %r" % (", ".join(BACKENDS), backend))
        self.read: Optional[Callable[[], Optional[bool]]] = None
        if self.config.fitted:
            self.read = (open_gpio_probe(self.config) if backend == "real"
                         else SimulatedPin(self.clock, 2.0 / self.config.rate_hz).read)
        self.watch = LeakWatch(self.config, self.clock())
        self.health_pub = HealthPublisher(
            rospy.Publisher("health/leak", DiagnosticStatus, queue_size=2), "leak_node: leak",
            "leak probe on header pin %d" % self.config.pin)
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("leak probe on header pin %d" % self.config.pin)
        self.diagnostics.add("leak probe", self._diagnose)
        rospy.Service("~reset", Trigger, self._on_reset)
        period = 1.0 / self.config.rate_hz if self.config.fitted else HEALTH_PERIOD / 5.0
        self.timer = rospy.Timer(rospy.Duration(period), self._on_timer)
        rospy.loginfo("leak_node: %s", "probe on header pin %d (%s), %.0f Hz" % (
            self.config.pin, backend, self.config.rate_hz) if self.config.fitted else
            "no leak probe fitted (hardware.yaml leak.fitted false); health/leak says so")

    def _on_timer(self, _event) -> None:
        now = self.clock()
        if self.read is not None:
            event = self.watch.update(self.read(), now)
            if event:
                rospy.logerr("leak_node: %s", event)
        try:
            self.health_pub.publish(self.watch.health(now), now)
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise
            return
        self.diagnostics.update()

    def _on_reset(self, _request) -> TriggerResponse:
        done, why = self.watch.reset()
        rospy.loginfo("leak_node: ~reset: %s", why)
        return TriggerResponse(success=done, message=why)

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        health = self.watch.health(self.clock())
        stat.summary(health.level, health.message)
        for key, value in self.watch.values():
            stat.add(key, value)
        return stat


def main(argv: Optional[List[str]] = None) -> None:
    start_node("leak_node", LeakNode, errors=(GpioUnavailable,))
    rospy.spin()


__all__ = ["LeakNode", "main"]
