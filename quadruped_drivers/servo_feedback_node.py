"""ROS glue of the servo feedback ADCs: 12 x ADS1115 behind a TCA9548A -> /joint_states, and the LiPo packs
read on their spare inputs -> battery/<pack>, health/battery.

Publishes
  joint_states   sensor_msgs/JointState  names from the URDF (JOINT_NAMES), positions in rad (the paper's
                 joint angles; NaN for a joint whose ADC did not answer this cycle; for a joint whose ADC read
                 a battery this cycle, its previous angle, 10 ms old), velocities from a low-pass filtered
                 finite difference
  battery/motors, battery/electronics  sensor_msgs/BatteryState  each fitted pack at batteries.rate_hz (2 Hz):
                 voltage, cell_voltage (NaN per cell: only the pack is measured), percentage from a resting
                 LiPo curve (NaN when absent), power_supply_status, health, present
  health/battery diagnostic_msgs/DiagnosticStatus  2 Hz and at once on a change: the worst fitted pack, OK,
                 WARN below warn_cell_v, ERROR below critical_cell_v (with hysteresis), stale, absent or
                 implausible (quadruped_drivers.battery); OK "not fitted" without a fitted pack
  diagnostics    stale / failed / implausible joints, per-joint I2C error, implausible-code, implausible-jump
                 and lost-config counters, mux errors and mux read-back mismatches, read time, battery reads
Parameters
  ~backend (real | sim)  ~bus_socket  ~hardware_yaml  ~calibration_yaml  ~rate (100 Hz)
  ~velocity_time_constant (0.03 s)  ~frame_id ("")
  ~batteries_fitted (false: hardware.yaml decides; true: every declared pack, the simulated robot's)
  ~robot_yaml (the servos' no-load speed)  ~joint_rate_check (true: a reading further from the last good
  angle than the servo can move is stale; false for servos without that limit, e.g. simulated instant ones)

Reading, mux handling and read-back, ADC config checks, plausibility, stale/failed bookkeeping, the
volts-to-angle map and the interleaved battery reads are the driver's
(:class:`quadruped_drivers.servo_feedback.ServoFeedbackArray`); battery levels are
:class:`quadruped_drivers.battery.BatteryMonitor`'s.
"""
from __future__ import annotations

import time
from typing import List, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from sensor_msgs.msg import BatteryState, JointState

from quadruped_common.config import ParameterError
from quadruped_common.monitoring import LowPassDifferentiator, RateMonitor, WindowStatistics
from quadruped_common.robot import JOINT_NAMES, load_servo_no_load_speed
from quadruped_common.ros.health import HealthPublisher
from quadruped_common.ros.node_startup import stack_clock, start_node
from quadruped_common.ros.diagnostics import Updater
from quadruped_drivers.battery import BatteryMonitor, PackStatus
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config, with_batteries_fitted
from quadruped_drivers.node_support import open_bus
from quadruped_drivers.servo_feedback import ServoFeedbackArray, SpareInput


class ServoFeedbackNode:
    def __init__(self) -> None:
        hardware = load_hardware_config(rospy.get_param("~hardware_yaml", "") or None)
        if rospy.get_param("~batteries_fitted", False):  # the simulated robot's packs
            hardware = with_batteries_fitted(hardware)
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
        self.clock = stack_clock()
        packs = hardware.batteries.fitted
        spares = [SpareInput(pack.name, pack.mux_channel, pack.adc_address, pack.adc_input) for pack in packs]
        self.array = ServoFeedbackArray(bus, hardware, calibration, clock=self.clock, max_joint_speed=max_speed,
                                        spare_inputs=spares, spare_period=1.0 / hardware.batteries.rate_hz)
        self.batteries = BatteryMonitor(hardware.batteries, hardware.adc_full_scale_v)
        self.cells = {pack.name: pack.cells for pack in packs}
        self.frame_id = rospy.get_param("~frame_id", "")
        self.differentiator = LowPassDifferentiator(len(JOINT_NAMES),
                                                    float(rospy.get_param("~velocity_time_constant", 0.03)))
        self.read_time = WindowStatistics(2000)
        self.rate = RateMonitor(2.0)
        self.last_reading = None
        self._start_array()
        self.publisher = rospy.Publisher("joint_states", JointState, queue_size=5)
        battery_publishers = {"motors": lambda: rospy.Publisher("battery/motors", BatteryState, queue_size=5),
                              "electronics": lambda: rospy.Publisher("battery/electronics", BatteryState,
                                                                     queue_size=5)}
        self.battery_pubs = {name: battery_publishers[name]() for name in self.cells}
        self.health_pub = HealthPublisher(
            rospy.Publisher("health/battery", DiagnosticStatus, queue_size=2), "servo_feedback_node: battery",
            "lipo packs on ads1115 spare inputs")
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("ads1115 x12 behind tca9548a")
        self.diagnostics.add("servo feedback", self._diagnose)
        self.diagnostics.add("battery", self._diagnose_battery)
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
        positions = reading.angles
        if reading.lent:  # the ADC read a battery: the joint's previous angle stands in for one cycle (a NaN
            positions = positions.copy()  # would make the controller's arming check and the pre-dive check's
            positions[reading.lent] = reading.held_angles[reading.lent]  # strokes refuse a healthy joint)
        velocities = self.differentiator.update(stamp.to_sec(), positions)
        msg = JointState()
        msg.header.stamp = stamp
        msg.header.frame_id = self.frame_id
        msg.name = list(JOINT_NAMES)
        msg.position = [float(v) for v in positions]
        msg.velocity = [float(v) for v in velocities]
        try:
            self.publisher.publish(msg)
            for sample in self.array.take_spare_samples():
                status = self.batteries.update(sample.name, sample.stamp, sample.volts)
                if status is not None:
                    self.battery_pubs[sample.name].publish(self._battery_state(status, stamp))
            self._publish_health()
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise
            return  # shutting down: publisher closed
        self.diagnostics.update()

    def _battery_state(self, status: PackStatus, stamp) -> BatteryState:
        msg = BatteryState()
        msg.header.stamp = stamp
        msg.voltage = status.voltage
        msg.temperature = msg.current = msg.charge = msg.capacity = msg.design_capacity = float("nan")
        msg.percentage = status.charge
        msg.cell_voltage = [float("nan")] * self.cells[status.name]  # only the pack's voltage is measured
        msg.present = status.present
        msg.power_supply_status = (BatteryState.POWER_SUPPLY_STATUS_DISCHARGING if status.present
                                   else BatteryState.POWER_SUPPLY_STATUS_UNKNOWN)
        msg.power_supply_health = {"": BatteryState.POWER_SUPPLY_HEALTH_GOOD,
                                   "low": BatteryState.POWER_SUPPLY_HEALTH_GOOD,
                                   "critical": BatteryState.POWER_SUPPLY_HEALTH_DEAD,
                                   "implausible": BatteryState.POWER_SUPPLY_HEALTH_OVERVOLTAGE,
                                   }.get(status.reason, BatteryState.POWER_SUPPLY_HEALTH_UNKNOWN)
        msg.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO
        msg.location = status.name
        return msg

    def _publish_health(self) -> None:
        now = self.clock()
        self.health_pub.publish(self.batteries.health(now), now)

    def _diagnose_battery(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        health = self.batteries.health(self.clock())
        stat.summary(health.level, health.message)
        for key, value in health.values:
            stat.add(key, value)
        return stat

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
        stat.add("ADCs lent to a battery read this cycle", str(len(reading.lent)))
        for name, count in sorted(self.array.spare_errors.items()):
            stat.add("battery %s read errors" % name, str(count))
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
