"""ROS glue of the servo feedback ADCs: 12 x ADS1115 behind a TCA9548A -> /joint_states.

Publishes
  joint_states   sensor_msgs/JointState  names from the URDF (JOINT_NAMES), positions in rad (the paper's
                 joint angles; NaN for a joint whose ADC did not answer this cycle), velocities from a
                 low-pass filtered finite difference
  diagnostics    stale / failed / implausible joints, per-joint I2C error, implausible-code, implausible-jump
                 and lost-config counters, mux errors and mux read-back mismatches, read time
Parameters
  ~backend (real | sim)  ~bus_socket  ~hardware_yaml  ~calibration_yaml  ~rate (100 Hz)
  ~velocity_time_constant (0.03 s)  ~frame_id ("")
  ~robot_yaml (the servos' no-load speed)  ~joint_rate_check (true: a reading further from the last good
  angle than the servo can move is stale; false for servos without that limit, e.g. simulated instant ones)

Reading, mux handling and read-back, ADC config checks, plausibility, stale/failed bookkeeping and
the volts-to-angle map are the driver's
(:class:`quadruped_drivers.servo_feedback.ServoFeedbackArray`).
"""
from __future__ import annotations

import time
from typing import List, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from sensor_msgs.msg import JointState

from quadruped_common.config import ParameterError
from quadruped_common.monitoring import LowPassDifferentiator, RateMonitor, WindowStatistics
from quadruped_common.robot import JOINT_NAMES, load_servo_no_load_speed
from quadruped_common.ros.node_startup import stack_clock, start_node
from quadruped_common.ros.diagnostics import Updater
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.node_support import open_bus
from quadruped_drivers.servo_feedback import ServoFeedbackArray


class ServoFeedbackNode:
    def __init__(self) -> None:
        hardware = load_hardware_config(rospy.get_param("~hardware_yaml", "") or None)
        calibration = load_servo_calibration(rospy.get_param("~calibration_yaml", "") or None)
        backend = rospy.get_param("~backend", "real")
        bus = open_bus(backend, hardware.i2c_bus, rospy.get_param("~bus_socket", "/tmp/uq_sim_i2c.sock"),
                       role="feedback")
        max_speed = None
        if bool(rospy.get_param("~joint_rate_check", True)):
            max_speed = load_servo_no_load_speed(rospy.get_param("~robot_yaml", "") or None)
        # The array's ages (stale, failed) and the joint-rate check run on the clock the servos move on:
        # simulated time in lock-step (it may run faster or slower than the wall), the monotonic clock
        # otherwise (wall time can jump).
        self.array = ServoFeedbackArray(bus, hardware, calibration, clock=stack_clock(), max_joint_speed=max_speed)
        self.frame_id = rospy.get_param("~frame_id", "")
        self.differentiator = LowPassDifferentiator(len(JOINT_NAMES),
                                                    float(rospy.get_param("~velocity_time_constant", 0.03)))
        self.read_time = WindowStatistics(2000)
        self.rate = RateMonitor(2.0)
        self.last_reading = None
        self._start_array()
        self.publisher = rospy.Publisher("joint_states", JointState, queue_size=5)
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("ads1115 x12 behind tca9548a")
        self.diagnostics.add("servo feedback", self._diagnose)
        rate = float(rospy.get_param("~rate", 100.0))
        if not rate > 0:
            raise ParameterError("~rate must be positive, got %r" % rate)
        self.timer = rospy.Timer(rospy.Duration(1.0 / rate), self._on_timer)
        rospy.loginfo("servo_feedback_node: 12 ADCs on %s bus at %.0f Hz", backend, rate)

    def _start_array(self) -> None:
        """Configure the ADCs. A device that does not answer now is retried by the driver later."""
        try:
            self.array.start()
        except OSError as exc:
            rospy.logerr("servo_feedback_node: ADC configuration incomplete (%s); retrying while running", exc)

    def _on_timer(self, _event) -> None:
        started = time.monotonic()
        reading = self.array.read()
        self.read_time.add(time.monotonic() - started)
        self.rate.tick(started)
        self.last_reading = reading
        stamp = rospy.Time.now()
        velocities = self.differentiator.update(stamp.to_sec(), reading.angles)
        msg = JointState()
        msg.header.stamp = stamp
        msg.header.frame_id = self.frame_id
        msg.name = list(JOINT_NAMES)
        msg.position = [float(v) for v in reading.angles]
        msg.velocity = [float(v) for v in velocities]
        try:
            self.publisher.publish(msg)
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise
            return  # shutting down: publisher closed
        self.diagnostics.update()

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        reading = self.last_reading
        if reading is None:
            stat.summary(DiagnosticStatus.STALE, "no reading yet")
            return stat
        names = lambda indices: ", ".join(JOINT_NAMES[i] for i in indices)  # noqa: E731
        if reading.failed:
            stat.summary(DiagnosticStatus.ERROR, "failed joints: %s" % names(reading.failed))
        elif reading.stale:
            stat.summary(DiagnosticStatus.WARN, "stale joints: %s" % names(reading.stale))
        else:
            stat.summary(DiagnosticStatus.OK, "all 12 joints fresh")
        if reading.implausible:
            stat.mergeSummary(DiagnosticStatus.WARN, "implausible readings: %s" % names(reading.implausible))
        timing = self.read_time.summary(1e3)
        stat.add("rate [Hz]", "%.1f" % self.rate.rate(time.monotonic()))
        stat.add("read time p50 [ms]", "%.3f" % timing["p50"])
        stat.add("read time p99 [ms]", "%.3f" % timing["p99"])
        stat.add("mux errors", str(reading.mux_errors))
        stat.add("mux read-back mismatches", str(self.array.mux_mismatches))
        implausible = self.array.implausible_counts
        jumps, accepted = self.array.jump_counts, self.array.jumps_accepted
        losses = self.array.config_losses
        for i, name in enumerate(JOINT_NAMES):
            stat.add("%s I2C errors" % name, str(int(reading.error_counts[i])))
            stat.add("%s implausible codes" % name, str(int(implausible[i])))
            stat.add("%s implausible jumps" % name, str(int(jumps[i])))
            stat.add("%s jumps accepted" % name, str(int(accepted[i])))
            stat.add("%s ADC config lost" % name, str(int(losses[i])))
        return stat


def main(argv: Optional[List[str]] = None) -> None:
    start_node("servo_feedback_node", ServoFeedbackNode)
    rospy.spin()
