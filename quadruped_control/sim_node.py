"""The simulated robot behind fake buses: the paper's floating-base model closing the loop at byte level.

Owns the register-level fake devices (PCA9685, 12 ADS1115 behind a TCA9548A on one fake I2C bus) and a
fake VN-100 byte stream, and serves them to the unchanged driver nodes:

* the fake I2C bus on a Unix socket (:class:`quadruped_drivers.bus_bridge.BusBridgeServer`); the
  pwm and servo feedback nodes use ``backend: sim`` with ``bus_socket`` pointing at it;
* the fake VN-100 behind a pseudo-terminal whose slave is linked at ``~imu_port`` (vn100_node opens it
  with pyserial like the real USB adapter and configures it with the same ASCII commands).

Every ``1 / ~physics_rate`` s (wall clock) it reads the pulse width each PCA9685 channel currently
produces, maps it back to a commanded joint angle through the servo calibration (a channel that is off
leaves its servo limp where it is), advances the plant (servo model + eq. trans, rot with RK4), writes
the servo feedback volts of the simulated joint angles into the fake ADCs and the simulated attitude,
body rate and specific force into the fake VN-100.

Publishes (ground truth, for tests and reports; nothing in the control path subscribes to these)
  sim/pose          geometry_msgs/PoseStamped  world ENU <- base_link, true attitude
  sim/servo_output  quadruped_msgs/ServoCommand  pulse widths the fake PCA9685 really produces and
                                                       the joint angles they command
Parameters
  ~robot_yaml ~hardware_yaml ~calibration_yaml ~simulation_yaml (package config/)
  ~servo_model (rate-limited | ideal)  ~initial_rpy_deg ([0, 0, 0])  ~restoring_offset ([]: off)
  ~physics_rate (100 Hz)  ~bus_socket (/tmp/uq_sim_i2c.sock)  ~imu_port (/tmp/uq_sim_vn100)
  ~imu_pump_period (0.0005 s: how often the fake VN-100's byte stream is pumped into the pty; packets
  leave at most this late, which shows up as IMU timing jitter downstream)
Services
  ~imu_streaming    std_srvs/SetBool  stop / resume the fake VN-100's output (stale-IMU tests)
"""
from __future__ import annotations

import math
import time
from typing import List, Optional

import numpy as np
import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper, Updater
from geometry_msgs.msg import PoseStamped
from std_srvs.srv import SetBool, SetBoolResponse

from quadruped_control.params import JOINT_NAMES, ParameterError, load_robot_params
from quadruped_control.servo_model import make_servo_model
from quadruped_control.simulation import PlantSimulator, SimulationError, load_simulation_settings
from quadruped_control.so3 import rot_to_quat, rpy_to_rot
from quadruped_drivers.bus_bridge import BusBridgeServer
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.i2c.fake_devices import build_fake_hardware
from quadruped_drivers.vn100.fake import FakeVn100, PtyFakeVn100
from quadruped_msgs.msg import ServoCommand

GRAVITY_UP = np.array([0.0, 0.0, 9.81])


class SimNode:
    def __init__(self) -> None:
        optional = lambda name: rospy.get_param(name, "") or None  # noqa: E731
        self.robot = load_robot_params(optional("~robot_yaml"))
        self.hardware = load_hardware_config(optional("~hardware_yaml"))
        self.calibration = load_servo_calibration(optional("~calibration_yaml"))
        rate = float(rospy.get_param("~physics_rate", 100.0))
        if not rate > 0:
            raise ParameterError("~physics_rate must be positive, got %r" % rate)
        self.dt = 1.0 / rate
        roll, pitch, yaw = [math.radians(v) for v in rospy.get_param("~initial_rpy_deg", [0.0, 0.0, 0.0])]
        offset = rospy.get_param("~restoring_offset", [])
        settings = load_simulation_settings(optional("~simulation_yaml"))
        servo = make_servo_model(rospy.get_param("~servo_model", "rate-limited"), settings.servo)
        self.plant = PlantSimulator(self.robot, servo,
                                    initial_rotation=rpy_to_rot(roll, pitch, yaw),
                                    restoring_offset=offset if offset else None)
        self.commanded = self.plant.joint_positions.reshape(12).copy()
        self.previous_velocity = self.plant.state.velocity.copy()

        self.fake = build_fake_hardware(self.hardware)
        # The bus's own lock: bridged transactions and the physics updates of the fake registers
        # never interleave mid-transaction.
        self.lock = self.fake.lock
        self.bridge = BusBridgeServer(self.fake.bus, rospy.get_param("~bus_socket", "/tmp/uq_sim_i2c.sock"),
                                      self.lock)
        self.vn100 = FakeVn100()
        self._write_sensors(np.zeros(3))
        self.imu_pty = PtyFakeVn100(self.vn100, symlink_path=rospy.get_param("~imu_port", "/tmp/uq_sim_vn100"),
                                    period=float(rospy.get_param("~imu_pump_period", 0.0005)))
        self.imu_pty.start()

        self.pose_pub = rospy.Publisher("sim/pose", PoseStamped, queue_size=10)
        self.output_pub = rospy.Publisher("sim/servo_output", ServoCommand, queue_size=10)
        rospy.Service("~imu_streaming", SetBool, self._on_imu_streaming)
        rospy.on_shutdown(self._shutdown)
        self.steps = 0
        self.overruns = 0
        self.step_errors = 0
        self.started = time.monotonic()
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("simulated robot")
        self.diagnostics.add("simulation", self._diagnose)
        rospy.loginfo("sim_node: fake I2C bus on %s, fake VN-100 on %s, %.0f Hz physics, %s servos",
                      self.bridge.path, self.imu_pty.path, rate,
                      rospy.get_param("~servo_model", "rate-limited"))

    def run(self) -> None:
        """Physics loop on absolute wall-clock deadlines (no drift, overruns counted not accumulated)."""
        deadline = time.monotonic()
        while not rospy.is_shutdown():
            try:
                self.step()
            except rospy.ROSException:
                if rospy.core.is_shutdown_requested():
                    break  # publishers closed by the shutdown
                raise
            deadline += self.dt
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                self.overruns += 1
                deadline = time.monotonic()

    def step(self) -> None:
        with self.lock:
            widths = np.asarray(self.fake.pulse_widths_us(), dtype=float)
        driven = widths > 0.0
        if np.any(driven):
            angles = np.asarray(self.calibration.pulses_to_angles(np.where(driven, widths, 1500.0)))
            self.commanded = np.where(driven, angles, self.plant.joint_positions.reshape(12))
        else:
            self.commanded = self.plant.joint_positions.reshape(12).copy()
        try:
            state = self.plant.step(self.commanded.reshape(4, 3), self.dt)
        except (SimulationError, ValueError) as exc:
            # A command the model cannot follow: the plant stays where it was; say so, keep serving.
            self.step_errors += 1
            rospy.logerr_throttle(1.0, "sim_node: plant step rejected: %s" % exc)
            state = self.plant.state
        acceleration_world = (state.velocity - self.previous_velocity) / self.dt
        self.previous_velocity = state.velocity.copy()
        self._write_sensors(acceleration_world)
        self.steps += 1
        stamp = rospy.Time.now()
        pose = PoseStamped()
        pose.header.stamp = stamp
        pose.header.frame_id = "world"
        (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
         pose.pose.orientation.w) = [float(v) for v in rot_to_quat(state.rotation)]
        self.pose_pub.publish(pose)
        output = ServoCommand()
        output.header.stamp = stamp
        output.name = list(JOINT_NAMES)
        output.pulse_width_us = widths.tolist()
        output.joint_target = self.commanded.tolist()
        self.output_pub.publish(output)
        self.diagnostics.update()

    def _write_sensors(self, acceleration_world: np.ndarray) -> None:
        state = self.plant.state
        R = state.rotation
        volts = self.calibration.angles_to_volts(self.plant.joint_positions.reshape(12))
        with self.lock:
            self.fake.set_joint_voltages(volts)
        # Specific force in the body frame, what an accelerometer measures (REP-145: +g up when level).
        specific_force = R.T @ (acceleration_world + GRAVITY_UP)
        self.vn100.set_state(rot_to_quat(R), state.omega, specific_force)

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        elapsed = time.monotonic() - self.started
        real_time = self.steps * self.dt / elapsed if elapsed > 0 else 0.0
        if self.step_errors:
            stat.summary(DiagnosticStatus.WARN, "%d plant steps rejected" % self.step_errors)
        elif real_time < 0.95 and elapsed > 5.0:
            stat.summary(DiagnosticStatus.WARN, "physics behind real time (%.2fx)" % real_time)
        else:
            stat.summary(DiagnosticStatus.OK, "running")
        stat.add("steps", str(self.steps))
        stat.add("real-time factor", "%.3f" % real_time)
        stat.add("overruns", str(self.overruns))
        stat.add("rejected steps", str(self.step_errors))
        stat.add("clamped joint commands", str(self.plant.clamped_joints))
        stat.add("IMU streaming", str(self.vn100.connected))
        stat.add("fake VN-100 packets", str(self.vn100.packets_sent))
        return stat

    def _on_imu_streaming(self, request) -> SetBoolResponse:
        # "Unplugging" the fake sensor silences the stream while the pty stays open, exactly what a
        # stalled sensor looks like to the driver; plugging back in keeps its configuration.
        if request.data:
            self.vn100.reconnect(power_cycle=False)
        else:
            self.vn100.disconnect()
        message = "fake VN-100 output %s" % ("resumed" if request.data else "stopped")
        rospy.logwarn("sim_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _shutdown(self) -> None:
        self.imu_pty.stop()
        self.bridge.close()


def main(argv: Optional[List[str]] = None) -> None:
    rospy.init_node("sim_node")
    try:
        node = SimNode()
    except (ParameterError, ValueError, OSError) as exc:
        rospy.logfatal("sim_node cannot start: %s", exc)
        raise SystemExit(1)
    node.run()
