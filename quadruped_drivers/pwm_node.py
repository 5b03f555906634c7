"""ROS glue of the PCA9685 servo output: /servo_command -> pulse widths on the chip.

Subscribes
  servo_command   underwater_quadruped/ServoCommand  12 pulse widths (us) by joint name
  estop           std_msgs/Empty    e-stop: every output off at once, latched (works with the controller dead)
Services
  ~enable         std_srvs/SetBool  outputs on / off (off = every channel full-off); on is refused while the
                                    e-stop is latched
  estop           std_srvs/SetBool  true: e-stop (as the topic); false: reset it (the outputs stay off until
                                    ~enable true)
Publishes
  estop_state     std_msgs/Bool (latched)  true while the e-stop is latched
  outputs_state   diagnostic_msgs/DiagnosticStatus  5 Hz and on a change: OK when the outputs take commands,
                                    else ERROR with why (e-stop, disabled, chip not answering); the
                                    controller's arming check
  diagnostics     watchdog state, clamp, write-error and retry counters, chip resets, command latency
Parameters
  ~backend (real | sim)  ~bus_socket (sim: the simulated robot's bus bridge)  ~hardware_yaml
  ~update_rate (100 Hz: watchdog checks)  ~enable_on_start (true)
  ~failsafe ("": per channel from hardware_yaml; hold | neutral | off: the same for every channel)

Clamping, the command watchdog (checked every update period, so it fires within its timeout) and its
per-channel failsafe, writes that cannot tear a pulse out of its limits, bounded retries, the MODE1
check that finds and restores a reset chip, and ALL_LED full-off on shutdown are the driver's (:class:`quadruped_drivers.pwm_output.ServoPwmOutput`); this node only wires them. The
latency measured here is from the IMU sample that caused a command (its header stamp) to the end of the
I2C write, the end-to-end latency of the control path.
"""
from __future__ import annotations

import threading
import time
from typing import List, Optional

import numpy as np
import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from std_msgs.msg import Bool, Empty
from std_srvs.srv import SetBool, SetBoolResponse

from quadruped_common.monitoring import RateMonitor, WindowStatistics
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.ros.node_startup import stack_clock, start_node
from quadruped_common.ros.diagnostics import Updater
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.node_support import open_bus, with_failsafe
from quadruped_drivers.pwm_output import ServoPwmOutput
from underwater_quadruped.msg import ServoCommand


class PwmNode:
    def __init__(self) -> None:
        self.hardware = with_failsafe(load_hardware_config(rospy.get_param("~hardware_yaml", "") or None),
                                      rospy.get_param("~failsafe", ""))
        backend = rospy.get_param("~backend", "real")
        bus = open_bus(backend, self.hardware.i2c_bus, rospy.get_param("~bus_socket", "/tmp/uq_sim_i2c.sock"),
                       role="pwm")
        self.lock = threading.Lock()  # one thread at a time owns the bus (docs/hardware_libraries.md: PCA9685 library)
        period = 1.0 / float(rospy.get_param("~update_rate", 100.0))
        # The command watchdog judges a command's age on the clock its timer runs on: in lock-step a slow
        # step on a loaded machine must not trip it (on wall time it could, and the chip would go to its
        # failsafe at a moment that differs from run to run).
        self.output = ServoPwmOutput(bus, self.hardware, update_period=period, clock=stack_clock())
        self._start_output()
        if not rospy.get_param("~enable_on_start", True):
            self.output.disable()
        self.index = {name: i for i, name in enumerate(JOINT_NAMES)}
        self.latency = WindowStatistics(2000)
        self.commands = RateMonitor(2.0)
        self.rejected = 0
        self.reported_write_errors = 0
        self.reported_chip_resets = 0
        self.closed = False
        self.last_rejection = ""
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("pca9685@0x%02x" % self.hardware.pca_address)
        self.diagnostics.add("servo output", self._diagnose)
        rospy.on_shutdown(self._shutdown)
        rospy.Service("~enable", SetBool, self._on_enable)
        # The e-stop acts here, on the chip, so it works with the controller dead.
        self.estop_pub = rospy.Publisher("estop_state", Bool, queue_size=1, latch=True)
        self.estop_pub.publish(Bool(False))
        rospy.Subscriber("estop", Empty, lambda _msg: self._trip("estop topic"), queue_size=10, tcp_nodelay=True)
        rospy.Service("estop", SetBool, self._on_estop)
        self.state_pub = rospy.Publisher("outputs_state", DiagnosticStatus, queue_size=1)
        self.state_period = 0.2
        self.last_state: Optional[str] = None
        self.last_state_time = -1e9
        rospy.Subscriber("servo_command", ServoCommand, self._on_command, queue_size=1, tcp_nodelay=True)
        self.timer = rospy.Timer(rospy.Duration(period), self._on_timer)
        rospy.loginfo("pwm_node: PCA9685 at 0x%02x on %s bus, %.0f Hz PWM, watchdog %.0f ms",
                      self.hardware.pca_address, backend, self.hardware.pwm_frequency_hz,
                      self.hardware.watchdog_timeout * 1e3)

    def _start_output(self) -> None:
        """Initialise the chip, retrying: the servos stay unpowered (no PWM) until it answers."""
        while not rospy.is_shutdown():
            try:
                with self.lock:
                    self.output.start()
                return
            except OSError as exc:
                rospy.logerr_throttle(2.0, "pwm_node: PCA9685 does not answer (%s), retrying" % exc)
                rospy.sleep(0.2)

    def _on_command(self, msg: ServoCommand) -> None:
        if len(msg.name) != len(msg.pulse_width_us):
            self._reject("servo_command has %d names but %d pulse widths" % (len(msg.name), len(msg.pulse_width_us)))
            return
        widths = np.full(len(JOINT_NAMES), np.nan)
        for name, width in zip(msg.name, msg.pulse_width_us):
            i = self.index.get(name)
            if i is None:
                self._reject("servo_command names unknown joint %r" % name)
                return
            widths[i] = width
        if not np.all(np.isfinite(widths)):
            # The driver keeps the last value for a non-finite channel; say so, once per second.
            rospy.logwarn_throttle(1.0, "pwm_node: servo_command without a finite width for every joint")
        with self.lock:
            if self.closed:
                return
            self.output.command(widths)
        now = rospy.get_time()
        self.commands.tick(time.monotonic())
        if not msg.header.stamp.is_zero():
            self.latency.add(now - msg.header.stamp.to_sec())

    def _reject(self, reason: str) -> None:
        self.rejected += 1
        self.last_rejection = reason
        rospy.logerr_throttle(1.0, "pwm_node: command rejected: %s" % reason)

    def _on_timer(self, _event) -> None:
        with self.lock:
            # Checked under the lock: a shutdown between a check outside it and the update would have
            # the timer update an output that is already off (it raised "used before start()").
            if self.closed:
                return
            was_tripped = self.output.watchdog_tripped
            self.output.update()
            tripped = self.output.watchdog_tripped
        if tripped and not was_tripped:
            rospy.logwarn("pwm_node: no servo_command for %.0f ms, outputs in failsafe",
                          self.hardware.watchdog_timeout * 1e3)
        self._publish_state()
        self.diagnostics.update()

    def _publish_state(self) -> None:
        """outputs_state at 5 Hz, and at once when it changes."""
        problem = self.output.not_ready
        now = time.monotonic()
        if problem == self.last_state and now - self.last_state_time < self.state_period:
            return
        self.last_state, self.last_state_time = problem, now
        self.state_pub.publish(DiagnosticStatus(
            level=DiagnosticStatus.ERROR if problem else DiagnosticStatus.OK, name="pwm_node: outputs",
            message=problem or "outputs enabled, the PCA9685 answering",
            hardware_id="pca9685@0x%02x" % self.hardware.pca_address))

    def _trip(self, source: str) -> None:
        with self.lock:
            if self.closed:
                return
            first = not self.output.estop_reason
            off = self.output.estop("%s at %.3f s" % (source, rospy.get_time())) if first else True
        if first:
            self.estop_pub.publish(Bool(True))
            (rospy.logerr if off else rospy.logfatal)(
                "pwm_node: E-STOP (%s): every output %s; latched until %s false", source,
                "off" if off else "off-write FAILED, retrying every update", rospy.resolve_name("estop"))

    def _on_estop(self, request) -> SetBoolResponse:
        if request.data:
            self._trip("estop service")
            return SetBoolResponse(success=True, message="e-stop latched: every output off")
        with self.lock:
            was = self.output.estop_reason
            self.output.reset_estop()
        if was:
            self.estop_pub.publish(Bool(False))
            rospy.logwarn("pwm_node: e-stop reset (was: %s); outputs stay off until %s true", was,
                          rospy.resolve_name("~enable"))
        return SetBoolResponse(success=True, message="e-stop reset; outputs off until enabled" if was
                               else "e-stop was not latched")

    def _on_enable(self, request) -> SetBoolResponse:
        with self.lock:
            if request.data and self.output.estop_reason:
                return SetBoolResponse(success=False, message="refused: e-stop latched (%s); reset it with %s false"
                                       % (self.output.estop_reason, rospy.resolve_name("estop")))
            if request.data:
                self.output.enable()
            else:
                self.output.disable()
        message = "outputs %s" % ("enabled" if request.data else "disabled (all channels off)")
        rospy.logwarn("pwm_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        latency = self.latency.summary(1e3)
        new_errors = self.output.write_errors - self.reported_write_errors
        self.reported_write_errors = self.output.write_errors
        new_resets = self.output.chip_resets - self.reported_chip_resets
        self.reported_chip_resets = self.output.chip_resets
        if self.output.estop_reason:
            stat.summary(DiagnosticStatus.ERROR, "E-STOP latched: every output off (%s)" % self.output.estop_reason)
        elif new_resets:
            stat.summary(DiagnosticStatus.ERROR, "PCA9685 reset %d time(s) since the last report: set up again (%s)"
                         % (new_resets, self.output.last_fault))
        elif new_errors:
            stat.summary(DiagnosticStatus.ERROR, "%d I2C write errors since the last report" % new_errors)
        elif self.output.watchdog_tripped:
            stat.summary(DiagnosticStatus.WARN, "command watchdog tripped: outputs in failsafe")
        elif not self.output.enabled:
            stat.summary(DiagnosticStatus.WARN, "outputs disabled")
        else:
            stat.summary(DiagnosticStatus.OK, "driving servos")
        stat.add("enabled", str(self.output.enabled))
        stat.add("e-stop", self.output.estop_reason or "not latched")
        stat.add("watchdog tripped", str(self.output.watchdog_tripped))
        stat.add("command rate [Hz]", "%.1f" % self.commands.rate(time.monotonic()))
        stat.add("latency p50 [ms]", "%.3f" % latency["p50"])
        stat.add("latency p99 [ms]", "%.3f" % latency["p99"])
        stat.add("latency max [ms]", "%.3f" % latency["max"])
        stat.add("clamped channels", str(self.output.clamp_count))
        stat.add("write errors", str(self.output.write_errors))
        stat.add("write retries", str(self.output.write_retries))
        stat.add("chip resets", str(self.output.chip_resets))
        stat.add("MODE1 read errors", str(self.output.mode_read_errors))
        stat.add("last fault", self.output.last_fault)
        stat.add("rejected commands", str(self.rejected))
        stat.add("last rejection", self.last_rejection)
        stat.add("applied pulse widths [us]", " ".join("%.0f" % v for v in self.output.applied_us))
        return stat

    def _shutdown(self) -> None:
        with self.lock:
            self.closed = True
            try:
                self.output.shutdown()
                rospy.loginfo("pwm_node: outputs off (ALL_LED full-off)")
            except OSError as exc:
                rospy.logerr("pwm_node: could not switch the outputs off on shutdown: %s", exc)


def main(argv: Optional[List[str]] = None) -> None:
    start_node("pwm_node", PwmNode)
    rospy.spin()
