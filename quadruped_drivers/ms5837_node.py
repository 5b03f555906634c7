"""ROS glue of the MS5837 depth sensor (Blue Robotics Bar30 / Bar02) on the I2C bus.

Publishes (only fresh readings: a reading the driver did not call fresh is never published)
  depth/pressure     sensor_msgs/FluidPressure  absolute pressure (Pa) and its variance
  depth/temperature  sensor_msgs/Temperature  degC (variance 0: unknown)
  depth/pose         geometry_msgs/PoseWithCovarianceStamped  in ~world_frame (odom, REP-105): position.z =
                     -depth (REP-103 z up), its variance from the pressure's; x, y and the attitude unmeasured
                     (variance 1e6), for robot_localization to fuse z alone
  health/depth       diagnostic_msgs/DiagnosticStatus  2 Hz and at once on a change: OK (fresh and plausible),
                     WARN (a reading dropped within depth.warn_window_s), ERROR (no fresh reading for
                     depth.timeout_s, or the PROM failed its CRC); OK "not fitted" without a sensor
  diagnostics        every rejection reason's counter, restarts, rate, the last reading
Parameters
  ~backend (real | sim)  ~bus_socket  ~hardware_yaml (the depth section: model, address, rate, OSR, density,
  surface)  ~frame_id (base_link)  ~world_frame (odom)  ~surface_pa_found: written by the node when it zeroed
  at start (depth.zero_at_start), read back after a restart

Starting, polling, restarting after bus errors, zeroing and health are the pure
:class:`quadruped_drivers.depth_sensor.DepthSensorRunner`; the driver is :class:`quadruped_drivers.ms5837.Ms5837`.
"""
from __future__ import annotations

import time
from typing import List, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from geometry_msgs.msg import PoseWithCovarianceStamped
from sensor_msgs.msg import FluidPressure, Temperature

from quadruped_common.monitoring import RateMonitor
from quadruped_common.ros.diagnostics import Updater
from quadruped_common.ros.health import HEALTH_PERIOD, HealthPublisher
from quadruped_common.ros.node_startup import stack_clock, start_node
from quadruped_drivers.depth_sensor import (DepthSensorRunner, SurfaceReference, make_driver, poll_period,
                                            pose_covariance)
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.node_support import open_bus


class Ms5837Node:
    def __init__(self) -> None:
        hardware = load_hardware_config(rospy.get_param("~hardware_yaml", "") or None)
        self.depth = hardware.depth
        self.frame_id = rospy.get_param("~frame_id", "base_link")
        self.world_frame = rospy.get_param("~world_frame", "odom")
        clock = stack_clock()
        self.clock = clock
        driver = None
        if self.depth.fitted:
            backend = rospy.get_param("~backend", "real")
            bus = open_bus(backend, hardware.i2c_bus, rospy.get_param("~bus_socket", "/tmp/uq_sim_i2c.sock"),
                           role="depth")
            driver = make_driver(bus, self.depth, clock=clock)
        known = rospy.get_param("~surface_pa_found", None)
        surface = SurfaceReference(self.depth.surface_pa, self.depth.zero_at_start, self.depth.zero_max_offset_pa,
                                   known=float(known) if isinstance(known, (int, float)) else None)
        self.runner = DepthSensorRunner(driver, self.depth, clock=clock, surface=surface)
        self.covariance = pose_covariance(self.depth)
        self.variance_pa2 = self.depth.pressure_stddev_pa ** 2
        self.rate = RateMonitor(2.0)
        self.pressure_pub = rospy.Publisher("depth/pressure", FluidPressure, queue_size=5)
        self.temperature_pub = rospy.Publisher("depth/temperature", Temperature, queue_size=5)
        self.pose_pub = rospy.Publisher("depth/pose", PoseWithCovarianceStamped, queue_size=5)
        self.hardware_id = "ms5837-%s@0x%02x" % (self.depth.model, self.depth.address)
        self.health_pub = HealthPublisher(
            rospy.Publisher("health/depth", DiagnosticStatus, queue_size=2), "ms5837_node: depth", self.hardware_id)
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID(self.hardware_id)
        self.diagnostics.add("depth sensor", self._diagnose)
        if self.depth.fitted:
            self.timer = rospy.Timer(rospy.Duration(poll_period(self.depth)), self._on_timer)
            rospy.loginfo("ms5837_node: %s at 0x%02x, %.0f Hz, OSR %d, density %.0f kg/m^3", self.depth.model,
                          self.depth.address, self.depth.rate_hz, self.depth.osr, self.depth.fluid_density)
        else:
            self.timer = rospy.Timer(rospy.Duration(HEALTH_PERIOD / 5.0), self._on_timer)
            rospy.loginfo("ms5837_node: no depth sensor fitted (hardware.yaml depth.fitted false); "
                          "health/depth says so")

    def _on_timer(self, _event) -> None:
        step = self.runner.step()
        if step.problem:
            rospy.logwarn_throttle(5.0, "ms5837_node: %s" % step.problem)
        if step.event:
            rospy.loginfo("ms5837_node: %s", step.event)
            if self.runner.surface.zeroed:
                rospy.set_param("~surface_pa_found", float(self.runner.surface.surface_pa))
        reading = step.reading
        try:
            if reading is not None and step.publish_pressure:
                self.rate.tick(time.monotonic())
                self._publish(reading, step.publish_depth)
            self._publish_health()
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise
            return  # shutting down: publishers closed
        self.diagnostics.update()

    def _publish(self, reading, with_depth: bool) -> None:
        stamp = rospy.Time.now()
        pressure = FluidPressure()
        pressure.header.stamp, pressure.header.frame_id = stamp, self.frame_id
        pressure.fluid_pressure, pressure.variance = reading.pressure_pa, self.variance_pa2
        self.pressure_pub.publish(pressure)
        temperature = Temperature()
        temperature.header.stamp, temperature.header.frame_id = stamp, self.frame_id
        temperature.temperature, temperature.variance = reading.temperature_c, 0.0
        self.temperature_pub.publish(temperature)
        if not with_depth:
            return
        pose = PoseWithCovarianceStamped()
        pose.header.stamp, pose.header.frame_id = stamp, self.world_frame
        pose.pose.pose.position.z = -reading.depth_m
        pose.pose.pose.orientation.w = 1.0
        pose.pose.covariance = self.covariance
        self.pose_pub.publish(pose)

    def _publish_health(self) -> None:
        now = self.clock()
        self.health_pub.publish(self.runner.health(now), now)

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        now = self.clock()
        health = self.runner.health(now)
        stat.summary(health.level, health.message)
        stat.add("rate [Hz]", "%.1f" % self.rate.rate(time.monotonic()))
        for key, value in self.runner.values(now):
            stat.add(key, value)
        return stat


def main(argv: Optional[List[str]] = None) -> None:
    start_node("ms5837_node", Ms5837Node)
    rospy.spin()
