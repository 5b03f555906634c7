"""ROS glue of the VN-100 IMU driver: serial binary packets -> /imu/data (REP-145).

Publishes
  imu/data      sensor_msgs/Imu  orientation of base FLU relative to world ENU, angular velocity (FLU,
                rad/s), linear acceleration (FLU, m/s^2, specific force), covariances from parameters.
                header.stamp is the arrival time of the packet (earlier packets of a burst are dated
                back by the sensor's own time-since-startup), frame_id from ~frame_id.
  diagnostics   rate, CRC errors, resync bytes, disconnects, last serial error, samples dropped as
                implausible (per reason), sensor time anomalies, reader errors
Parameters
  ~port (/dev/vn100, the udev rule's link)  ~baud (921600: the sensor is looked for at the other standard
  rates too and switched to it)  ~save_baud (false: never write the sensor's flash)  ~rate (200 Hz; 800
  must be divisible by it)  ~frame_id (imu_link)  ~orientation_covariance_diagonal
  ~angular_velocity_covariance_diagonal  ~linear_acceleration_covariance_diagonal  ~read_timeout
  ~probe_timeout ~reconnect_initial_delay ~reconnect_max_delay ~command_timeout ~stale_timeout (s)
  ~max_angular_rate (rad/s)  ~max_acceleration (m/s^2)  ~quaternion_norm_tolerance
  ~config_yaml (package config/vn100.yaml supplies the defaults of all of the above)

The node reads in its own thread (the serial read blocks for at most the port timeout); framing, CRC,
configuration, reconnection and the NED/FRD -> ENU/FLU conversion are the driver's; the plausibility
check (sensor range), burst dating and per-sample isolation are :class:`SampleGate`'s. No exception of
one sample or one read stops the reader thread: it is counted, reported and the stream goes on.
"""
from __future__ import annotations

import threading
import time
from typing import List, Optional, Sequence

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from sensor_msgs.msg import Imu

from quadruped_common.monitoring import RateMonitor
from quadruped_common.ros.node_startup import stack_clock, start_node
from quadruped_common.ros.diagnostics import Updater
from quadruped_drivers.vn100.driver import Vn100Driver, serial_port_factory
from quadruped_drivers.vn100.sample_gate import DROP_REASONS, TIME_ANOMALY, SampleGate
from quadruped_drivers.vn100.settings import VN100_KEYS, load_vn100_settings, sensor_limits


def _diagonal(values: Sequence[float]) -> List[float]:
    """A checked covariance (3 variances or 9 values, see vn100/settings.py) as the message's 9 values."""
    values = [float(v) for v in values]
    if len(values) == 9:
        return values
    return [values[0], 0.0, 0.0, 0.0, values[1], 0.0, 0.0, 0.0, values[2]]


class Vn100Node:
    def __init__(self) -> None:
        # Every value checked against the vn100.yaml schema (quadruped_drivers/vn100/settings.py); a
        # ~param overrides the file's value of the same name (~rate overrides rate_hz).
        overrides = {name: rospy.get_param("~" + name) for name in VN100_KEYS if rospy.has_param("~" + name)}
        names = {}
        if rospy.has_param("~rate"):
            overrides["rate_hz"] = rospy.get_param("~rate")
            names["rate_hz"] = "~rate"
        settings = load_vn100_settings(rospy.get_param("~config_yaml", "") or None, overrides, names)

        def param(name: str):
            return settings[name]

        self.port = param("port")
        self.baud = int(param("baud"))
        self.rate_hz = float(param("rate_hz"))
        self.frame_id = param("frame_id")
        self.covariances = {
            key: _diagonal(param(key + "_covariance_diagonal"))
            for key in ("orientation", "angular_velocity", "linear_acceleration")}
        self.driver = Vn100Driver(serial_port_factory(self.port, self.baud, float(param("read_timeout"))),
                                  rate_hz=self.rate_hz, baud=self.baud, save_baud=bool(param("save_baud")),
                                  probe_timeout=float(param("probe_timeout")),
                                  reconnect_initial_delay=float(param("reconnect_initial_delay")),
                                  reconnect_max_delay=float(param("reconnect_max_delay")),
                                  command_timeout=float(param("command_timeout")),
                                  stale_timeout=float(param("stale_timeout")),
                                  link_clock=stack_clock(),  # silence on simulated time in lock-step
                                  port_name=self.port,
                                  log=lambda line: rospy.logwarn("vn100_node: %s", line))
        self.gate = SampleGate(sensor_limits(settings), max_backdate=float(param("stale_timeout")))
        self.publisher = rospy.Publisher("imu/data", Imu, queue_size=10, tcp_nodelay=True)
        self.monitor = RateMonitor(2.0)
        self.published = 0
        self.reported_drops = 0
        self.reader_errors = 0
        self.last_reader_error = ""
        self.last_stamp: Optional[rospy.Time] = None
        self.logged_connects = 0
        self.logged_disconnects = 0
        self.logged_failures = 0
        self.diagnostics = Updater()
        # The hardware ID is the sensor's serial number (register 3), set once the sensor has answered
        # (diagnostic_updater's convention: "wait until the device is open before calling setHardwareID").
        self.diagnostics.add("imu", self._diagnose)
        self.diag_timer = rospy.Timer(rospy.Duration(1.0), lambda _e: self.diagnostics.update())
        self.thread = threading.Thread(target=self._run, name="vn100_reader", daemon=True)
        self.thread.start()
        rospy.loginfo("vn100_node: %s at %d baud, %.0f Hz, frame %s", self.port, self.baud, self.rate_hz,
                      self.frame_id)

    def _run(self) -> None:
        while not rospy.is_shutdown():
            try:
                self._read_once()
            except rospy.ROSException as exc:
                # The publisher closes during shutdown (rospy closes topics in its pre-shutdown hooks, before
                # rospy.is_shutdown() turns true); outside a shutdown it cannot recover: stop the node.
                if not rospy.core.is_shutdown_requested():
                    rospy.logerr("vn100_node: cannot publish (%s), shutting down", exc)
                    rospy.signal_shutdown("imu publisher closed")
                break
            except Exception as exc:  # noqa: BLE001 - the reader thread must never die
                self.reader_errors += 1
                self.last_reader_error = "%s: %s" % (type(exc).__name__, exc)
                rospy.logerr_throttle(1.0, "vn100_node: reader error (%s), carrying on" % self.last_reader_error)
                time.sleep(0.001)
        self.driver.close()

    def _read_once(self) -> None:
        samples = self.driver.read_samples()
        self._log_link_changes()
        if not samples:
            if not self.driver.connected:
                time.sleep(0.01)  # the driver reconnects on its own schedule; do not spin
            return
        arrival = rospy.Time.now()
        dropped = self.gate.dropped
        for reading, age in self.gate.process(samples, arrival.to_sec()):
            self._publish(reading, arrival - rospy.Duration.from_sec(age))
        if self.gate.dropped != dropped:
            rospy.logwarn_throttle(1.0, "vn100_node: sample dropped: %s" % self.gate.last_drop)

    def _log_link_changes(self) -> None:
        """One log line per connection and per loss of the link (the diagnostics count them); failed
        attempts to connect (sensor absent, not found at any rate) at most every 10 s."""
        connects, disconnects = self.driver.connects, self.driver.disconnects
        failures = self.driver.connect_failures
        if connects != self.logged_connects:
            rospy.loginfo("vn100_node: sensor configured on %s (connection %d)", self.port, connects)
        if disconnects != self.logged_disconnects:
            rospy.logwarn("vn100_node: link lost (%s); reconnecting at once, then backing off up to %.3g s",
                          self.driver.last_error, self.driver.reconnect_max_delay)
        if failures != self.logged_failures and not self.driver.connected:
            rospy.logerr_throttle(10.0, "vn100_node: %s" % self.driver.last_error)
        self.logged_connects, self.logged_disconnects = connects, disconnects
        self.logged_failures = failures

    def _publish(self, reading, stamp: rospy.Time) -> None:
        # Dating a burst back can land before the previous sample when the transport delay varied:
        # keep the stamps strictly increasing (consumers and bag analysis rely on it).
        if self.last_stamp is not None and stamp <= self.last_stamp:
            stamp = self.last_stamp + rospy.Duration(0, 1000)
        self.last_stamp = stamp
        msg = Imu()
        msg.header.stamp = stamp
        msg.header.frame_id = self.frame_id
        (msg.orientation.x, msg.orientation.y, msg.orientation.z,
         msg.orientation.w) = [float(v) for v in reading.orientation_xyzw]
        (msg.angular_velocity.x, msg.angular_velocity.y,
         msg.angular_velocity.z) = [float(v) for v in reading.angular_velocity]
        (msg.linear_acceleration.x, msg.linear_acceleration.y,
         msg.linear_acceleration.z) = [float(v) for v in reading.linear_acceleration]
        msg.orientation_covariance = self.covariances["orientation"]
        msg.angular_velocity_covariance = self.covariances["angular_velocity"]
        msg.linear_acceleration_covariance = self.covariances["linear_acceleration"]
        self.publisher.publish(msg)
        self.published += 1
        self.monitor.tick(time.monotonic())

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        rate = self.monitor.rate(time.monotonic())
        parser = self.driver.parser
        if self.driver.serial_number:
            stat.hardware_id = "VN-100 SN %s" % self.driver.serial_number
            self.diagnostics.setHardwareID(stat.hardware_id)
        if not self.driver.connected:
            stat.summary(DiagnosticStatus.ERROR, "disconnected: %s" % (self.driver.last_error or "opening port"))
        elif rate < 0.9 * self.rate_hz:
            stat.summary(DiagnosticStatus.WARN, "%.1f Hz, expected %.0f Hz" % (rate, self.rate_hz))
        else:
            stat.summary(DiagnosticStatus.OK, "streaming")
        stat.add("rate [Hz]", "%.1f" % rate)
        drops = self.gate.dropped
        new_drops, self.reported_drops = drops - self.reported_drops, drops
        if new_drops and stat.level == DiagnosticStatus.OK:
            stat.summary(DiagnosticStatus.WARN, "%d implausible samples dropped (%s)" % (new_drops, self.gate.last_drop))
        stat.add("published", str(self.published))
        stat.add("dropped samples", str(drops))
        for reason in DROP_REASONS:
            stat.add("dropped: %s" % reason, str(self.gate.counts[reason]))
        stat.add("last dropped sample", self.gate.last_drop)
        stat.add("sensor time anomalies", str(self.gate.counts[TIME_ANOMALY]))
        stat.add("reader errors", str(self.reader_errors))
        stat.add("last reader error", self.last_reader_error)
        stat.add("packets", str(parser.packets))
        stat.add("CRC errors", str(parser.crc_errors))
        stat.add("sensor errors", str(self.driver.sensor_errors))
        stat.add("resync bytes", str(parser.resync_bytes))
        stat.add("disconnects", str(self.driver.disconnects))
        stat.add("model", str(self.driver.model))
        stat.add("last error", str(self.driver.last_error))
        return stat


def main(argv: Optional[List[str]] = None) -> None:
    start_node("vn100_node", Vn100Node)
    rospy.spin()
