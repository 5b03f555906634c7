"""The simulated robot behind fake buses: the paper's floating-base model closing the loop at byte level.

Owns the register-level fake devices (PCA9685, 12 ADS1115 behind a TCA9548A and the MS5837 depth sensor on
one fake I2C bus, as config/hardware.yaml wires them) and a fake VN-100 byte stream, and serves them to the
unchanged driver nodes:

* the fake I2C bus on a Unix socket (:class:`quadruped_drivers.bus_bridge.BusBridgeServer`); the
  pwm and servo feedback nodes use ``backend: sim`` with ``bus_socket`` pointing at it;
* the fake VN-100 behind a pseudo-terminal whose slave is linked at ``~imu_port`` (vn100_node opens it
  with pyserial like the real USB adapter and configures it with the same ASCII commands).

Every ``1 / ~physics_rate`` s it reads the pulse width each PCA9685 channel currently
produces, maps it back to a commanded joint angle through the servo calibration (a channel that is off
leaves its servo limp where it is), advances the plant (servo model + eq. trans, rot with RK4), writes
the servo feedback volts of the simulated joint angles into the fake ADCs and the simulated attitude,
body rate and specific force into the fake VN-100. The safety sensors (:mod:`quadruped_control.sim.safety_sensors`,
config/simulation.yaml ``simulated_robot``): the fake MS5837 measures the water pressure at the body's depth
(a mean depth minus its world z; updated every 50 ms) and the water temperature, with a few counts of noise;
the two LiPo packs discharge with time and with the joints' speed, and their voltages reach the spare inputs
of the fake ADS1115s through the dividers hardware.yaml declares.

Two clocks (``~lockstep``):

* real time (default): the physics runs on wall-clock deadlines and the fake VN-100 emits its packets
  when they are due on the wall clock. The stack must keep up; this mode gives the timing figures.
* lock-step (``~lockstep: true``, needs ``/use_sim_time``): sim_node owns ``/clock`` and advances
  simulated time by one physics step only when the stack has answered the IMU samples of the current
  step (:mod:`quadruped_control.sim.lockstep`): deterministic results, independent of the machine's load,
  as fast as the machine allows. The drivers run their real byte-level code on the simulated clock.

Subscribes
  sim/stand_rpy_deg geometry_msgs/Vector3Stamped  the body held at rest at this roll, pitch, yaw (deg): the robot
                                                  on its stand (the pre-dive check's guided poses); NaN: floating
Publishes (ground truth, for tests and reports; nothing in the control path subscribes to these)
  sim/pose          geometry_msgs/PoseStamped  odom (ENU, REP-105) <- base_link, true attitude and position
                                               (the body's start at the origin, simulated_robot.depth_sensor.
                                               mean_depth_m under water)
  sim/servo_output  underwater_quadruped/ServoCommand  pulse widths the fake PCA9685 really produces and
                                                       the joint angles they command
Parameters
  ~robot_yaml ~hardware_yaml ~calibration_yaml ~simulation_yaml (package config/)
  ~servo_model (rate-limited | ideal)  ~initial_rpy_deg ([0, 0, 0])  ~restoring_offset ([]: off)
  ~plant (paper | tank: the robot on its rope in the test tank, ~tank_yaml default config/tank.yaml;
    a ~tank_yaml with ~plant paper is refused)  ~tank_disturbance ([]: the tank.yaml's; [SIGMA, TAU]: a tank that
    pushes, N m and s, as the studies' --tank-disturbance)
  ~hardware_faults ("": none; a file or an inline YAML mapping of quadruped_drivers.hardware_faults: a
    robot built wrong, its faults unknown to the stack's configuration)
  ~physics_rate (100 Hz)  ~bus_socket (/tmp/uq_sim_i2c.sock)  ~imu_port (/tmp/uq_sim_vn100)
  ~imu_pump_period (0.05 s: longest sleep of the fake VN-100's pty pump; it wakes when the next packet
  is due, when the driver writes, or when the simulated clock moves)
  ~lockstep (false)  ~lockstep_start (1.0 s: simulated time of the first step)
  ~lockstep_timeout (2.0 s wall: a step not answered by then advances anyway and is counted; the run is
  then no longer deterministic)
  ~lockstep_graph (["imu/data attitude_controller", "servo_command pwm_node"]: "topic node" pairs that
  must be connected, at the publishers' end too, before simulated time starts)
  ~i2c_stuck_timeout (0.025 s: how long each transaction on a stuck bus takes before ETIMEDOUT)
  ~battery_capacity_ah (0: simulation.yaml's) ~battery_start_charge (-1: simulation.yaml's): both packs' capacity
  and start charge, for a test that drains them in seconds
Services (fault injection: tests and benchmarks/fault_campaign.py)
  ~imu_streaming    std_srvs/SetBool  stop / resume the fake VN-100's output: the serial link lost and
                                      back (the sensor keeps its configuration)
  ~i2c_bus_stuck    std_srvs/SetBool  true: the I2C bus is held (every transaction times out), false: free
  ~pca9685_power    std_srvs/SetBool  false: the PCA9685 loses its supply (off the bus, no pulses), true:
                                      powered again from its power-on reset state
  ~depth_sensor_fault std_srvs/SetBool  true: the MS5837 stops answering (off the bus: "depth sensor lost"),
                                      false: back from its power-on state
  ~water_inside     std_srvs/SetBool  true: water bridges the leak probe, false: dry again
  ~battery_flat     std_srvs/SetBool  true: every fitted pack at charge 0 (below its critical voltage), false:
                                      back at its start charge (a fresh pack)
The leak probe's pin: sim/leak_probe (std_msgs/Bool, the level hardware.yaml leak.active_high gives wet or dry,
10 Hz of simulated time), what leak_node reads with ~backend sim.
"""
from __future__ import annotations

import math
import time
import xmlrpc.client
from typing import List, Optional

import numpy as np
import rosgraph
import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, SetBoolResponse

from quadruped_common.ros.node_startup import start_node
from quadruped_control.sim.lockstep import AnswerTracker, SimClock, missing_links

from quadruped_common.config import ParameterError
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_common.ros.diagnostics import Updater
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants import VALIDITY_NOTE, load_tank_params, make_plant
from quadruped_control.sim.safety_sensors import DepthModel, SimulatedPack, with_overrides
from quadruped_control.sim.servo_model import make_servo_model, tank_servo_params
from quadruped_control.sim.simulation import PlantSimulator, SimulationError, load_simulation_settings
from quadruped_drivers.bus_bridge import BusBridgeServer
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config, with_batteries_fitted
from quadruped_drivers.hardware_faults import BuiltRobot, load_hardware_faults
from quadruped_drivers.i2c.fake_devices import build_fake_hardware
from quadruped_drivers.vn100.fake import FakeVn100, PtyFakeVn100
from underwater_quadruped.msg import ControllerState, ServoCommand

GRAVITY_UP = np.array([0.0, 0.0, 9.81])


def _ros_time(t: float) -> rospy.Time:
    """Simulated time as a ROS time, rounded to the nanosecond (from_sec truncates: 1.03 s would become
    1.029999999 s)."""
    return rospy.Time(0, int(round(t * 1e9)))


class SimNode:
    def __init__(self) -> None:
        optional = lambda name: rospy.get_param(name, "") or None  # noqa: E731
        self.robot = load_robot_params(optional("~robot_yaml"))
        self.hardware = load_hardware_config(optional("~hardware_yaml"))
        if rospy.get_param("~batteries_fitted", False):  # packs on the simulated robot, whatever the robot's file says
            self.hardware = with_batteries_fitted(self.hardware)
        self.calibration = load_servo_calibration(optional("~calibration_yaml"))
        faults = load_hardware_faults(optional("~hardware_faults"))
        self.built = BuiltRobot(self.calibration, faults)  # the robot as built: its wires and mounts
        self.slowed_targets: Optional[np.ndarray] = None
        self.servo_speed = self.robot.servo_no_load_speed
        for line in faults.describe():
            rospy.logwarn("sim_node: hardware fault (unknown to the stack's configuration): %s", line)
        rate = float(rospy.get_param("~physics_rate", 100.0))
        if not rate > 0:
            raise ParameterError("~physics_rate must be positive, got %r" % rate)
        self.dt = 1.0 / rate
        roll, pitch, yaw = [math.radians(v) for v in rospy.get_param("~initial_rpy_deg", [0.0, 0.0, 0.0])]
        offset = rospy.get_param("~restoring_offset", [])
        settings = load_simulation_settings(optional("~simulation_yaml"))
        plant = str(rospy.get_param("~plant", "paper"))
        model = None
        servo_params = settings.servo
        tank_yaml = optional("~tank_yaml")
        if plant == "paper" and tank_yaml:  # a fitted tank asked for, the paper's model about to run: say so
            raise ParameterError("~tank_yaml %r is for ~plant tank; ~plant is 'paper'" % tank_yaml)
        if plant != "paper":
            tank = load_tank_params(tank_yaml)
            push = rospy.get_param("~tank_disturbance", [])
            if push:
                tank = tank.with_values(disturbance_torque_std=float(push[0]),
                                        disturbance_correlation_time=float(push[1]))
            model = make_plant(plant, self.robot, tank)
            servo_params = tank_servo_params(servo_params, tank)  # the tank's servos, as the offline trials
            rospy.logwarn("sim_node: %s", VALIDITY_NOTE)
        servo = make_servo_model(rospy.get_param("~servo_model", "rate-limited"), servo_params)
        self.plant = PlantSimulator(self.robot, servo,
                                    initial_rotation=rpy_to_rot(roll, pitch, yaw),
                                    restoring_offset=offset if offset else None, model=model)
        self.commanded = self.plant.joint_positions.reshape(12).copy()
        self.previous_velocity = self.plant.state.velocity.copy()

        self.lockstep = bool(rospy.get_param("~lockstep", False))
        if self.lockstep and not rospy.get_param("/use_sim_time", False):
            raise ParameterError("~lockstep needs /use_sim_time true (sim.launch lockstep:=true sets both)")
        self.sim_clock = SimClock(float(rospy.get_param("~lockstep_start", 1.0)), self.dt)
        self.sim_time = self.sim_clock.t0
        self.lockstep_timeout = float(rospy.get_param("~lockstep_timeout", 2.0))
        self.lockstep_graph = [str(entry).split() for entry in rospy.get_param(
            "~lockstep_graph", ["imu/data attitude_controller", "servo_command pwm_node"])]
        if any(len(entry) != 2 for entry in self.lockstep_graph):
            raise ParameterError("~lockstep_graph entries are 'topic node', got %r" % (self.lockstep_graph,))
        self.lockstep_timeouts = 0

        # The fake MS5837 times its conversions on the clock its driver reads: simulated time in lock-step.
        self.fake = build_fake_hardware(self.hardware, log_transactions=False,  # runs for hours: no log
                                        clock=(lambda: self.sim_time) if self.lockstep else time.monotonic)
        self._setup_safety_sensors(settings)
        # The bus's own lock: bridged transactions and the physics updates of the fake registers
        # never interleave mid-transaction.
        self.lock = self.fake.lock
        self.bridge = BusBridgeServer(self.fake.bus, rospy.get_param("~bus_socket", "/tmp/uq_sim_i2c.sock"),
                                      self.lock, stuck_timeout_s=float(rospy.get_param("~i2c_stuck_timeout", 0.025)))
        if self.lockstep:
            self.vn100 = FakeVn100(boot_time=self.sim_clock.t0)
            imu_clock, realtime = (lambda: self.sim_time), False
        else:
            self.vn100 = FakeVn100()
            imu_clock, realtime = time.monotonic, True
        self._write_sensors(np.zeros(3))
        self._write_safety_sensors(0.0)
        self.imu_pty = PtyFakeVn100(self.vn100, clock=imu_clock, realtime=realtime,
                                    symlink_path=rospy.get_param("~imu_port", "/tmp/uq_sim_vn100"),
                                    period=float(rospy.get_param("~imu_pump_period", 0.05)))
        self.imu_pty.start()
        if self.lockstep:
            # Half a PCA9685 tick: the chip quantises the commanded widths.
            tick_us = 1e6 / (self.hardware.actual_pwm_frequency_hz * 4096.0)
            self.answers = AnswerTracker(0.5 * tick_us + 1e-6)
            self.joint_index = {name: i for i, name in enumerate(JOINT_NAMES)}
            self.clock_pub = rospy.Publisher("/clock", Clock, queue_size=10)
            self.state_sub = rospy.Subscriber("controller_state", ControllerState, self._on_state,
                                              queue_size=100, tcp_nodelay=True)
            self.command_sub = rospy.Subscriber("servo_command", ServoCommand, self._on_command,
                                                queue_size=100, tcp_nodelay=True)

        self.stand: Optional[np.ndarray] = None
        rospy.Subscriber("sim/stand_rpy_deg", Vector3Stamped, self._on_stand, queue_size=1)
        self.pose_pub = rospy.Publisher("sim/pose", PoseStamped, queue_size=10)
        self.output_pub = rospy.Publisher("sim/servo_output", ServoCommand, queue_size=10)
        rospy.Service("~imu_streaming", SetBool, self._on_imu_streaming)
        rospy.Service("~i2c_bus_stuck", SetBool, self._on_bus_stuck)
        rospy.Service("~pca9685_power", SetBool, self._on_pca_power)
        rospy.Service("~depth_sensor_fault", SetBool, self._on_depth_fault)
        rospy.Service("~water_inside", SetBool, self._on_water_inside)
        rospy.Service("~battery_flat", SetBool, self._on_battery_flat)
        rospy.on_shutdown(self._shutdown)
        self.steps = 0
        self.overruns = 0
        self.step_errors = 0
        self.started = time.monotonic()
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("none")  # no hardware (diagnostic_updater convention)
        self.diagnostics.add("simulation", self._diagnose)
        rospy.loginfo("sim_node: fake I2C bus on %s, fake VN-100 on %s, %.0f Hz physics, %s servos, %s plant%s",
                      self.bridge.path, self.imu_pty.path, rate,
                      rospy.get_param("~servo_model", "rate-limited"), plant,
                      "" if plant == "paper" else " (%s)" % (tank_yaml or "config/tank.yaml"))

    def _setup_safety_sensors(self, settings) -> None:
        """The depth model and the simulated packs (module docstring), with ~battery_* overrides."""
        sensors = settings.sensors
        depth = self.hardware.depth
        self.depth_model = DepthModel(depth.surface_pa, depth.fluid_density, sensors.mean_depth_m)
        self.water_temperature = sensors.temperature_c
        if self.fake.depth is not None:
            self.fake.depth.noise_counts = sensors.noise_counts
        capacity = float(rospy.get_param("~battery_capacity_ah", 0.0))
        charge = float(rospy.get_param("~battery_start_charge", -1.0))
        if capacity < 0.0 or charge > 1.0:
            raise ParameterError("~battery_capacity_ah must be >= 0 (0: simulation.yaml's) and ~battery_start_charge "
                                 "<= 1 (< 0: simulation.yaml's), got %r and %r" % (capacity, charge))
        self.packs = {pack.name: (pack, SimulatedPack(pack.cells, with_overrides(
            sensors.packs[pack.name], capacity if capacity > 0.0 else None, charge if charge >= 0.0 else None)))
            for pack in self.hardware.batteries.fitted}
        self._depth_due = 0
        self.water_inside = False
        self.leak_pub = rospy.Publisher("sim/leak_probe", Bool, queue_size=1)
        self._leak_due = 0

    def _write_safety_sensors(self, dt: float) -> None:
        """Advance the packs by ``dt`` and write them and (every 50 ms) the depth into the fake chips."""
        speed = float(np.abs(self.plant.joint_velocities).sum()) if dt > 0.0 else 0.0
        with self.lock:
            for pack, simulated in self.packs.values():
                simulated.step(dt, speed)
                self.fake.set_spare_voltage(pack.mux_channel, pack.adc_address, pack.adc_input,
                                            simulated.adc_volts(pack.divider_ratio))
            if self.fake.depth is not None and self._depth_due <= 0:
                z = float(self.plant.state.position[2])
                self.fake.depth.set_state(self.depth_model.pressure(z), self.water_temperature)
                self._depth_due = max(1, int(round(0.05 / self.dt)))
        self._depth_due -= 1
        self._leak_due -= 1
        if self._leak_due <= 0:
            self._leak_due = max(1, int(round(0.1 / self.dt)))
            self.leak_pub.publish(Bool(data=self.water_inside == self.hardware.leak.active_high))

    def run(self) -> None:
        if self.lockstep:
            self.run_lockstep()
        else:
            self.run_realtime()

    def run_realtime(self) -> None:
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

    # ---- lock-step -------------------------------------------------------------------------------

    def run_lockstep(self) -> None:
        """Advance simulated time one physics step per answered cycle (module docstring)."""
        self._wait_until_ready()
        k = 0
        while not rospy.is_shutdown():
            t = self.sim_clock.time(k)
            self._publish_clock(t)
            before = self.vn100.packets_sent
            self.vn100.advance(t)
            self.imu_pty.wake()
            if self.vn100.packets_sent > before:
                if not self.answers.wait(t, self._chip_widths, self.lockstep_timeout):
                    self.lockstep_timeouts += 1
                    rospy.logwarn_throttle(1.0, "sim_node: lock-step step at t=%.3f not answered within %.1f s; "
                                           "advancing anyway (%d so far)" % (t, self.lockstep_timeout,
                                                                             self.lockstep_timeouts))
            else:
                time.sleep(self.dt)  # no IMU output (sensor stalled): nothing to answer, pace at real time
            try:
                self.step(stamp=self.sim_clock.time(k + 1))
            except rospy.ROSException:
                if rospy.core.is_shutdown_requested():
                    break
                raise
            k += 1

    def _publish_clock(self, t: float) -> None:
        self.sim_time = t
        self.clock_pub.publish(Clock(clock=_ros_time(t)))

    def _chip_widths(self) -> np.ndarray:
        with self.lock:
            return np.asarray(self.fake.pulse_widths_us(), dtype=float)

    def _on_state(self, msg: ControllerState) -> None:
        self.answers.on_state(msg.header.stamp.to_sec(), msg.armed)

    def _on_command(self, msg: ServoCommand) -> None:
        widths = np.full(len(JOINT_NAMES), np.nan)
        for name, width in zip(msg.name, msg.pulse_width_us):
            i = self.joint_index.get(name)
            if i is not None:
                widths[i] = width
        self.answers.on_command(widths)

    def _lockstep_missing(self) -> List[str]:
        """What the stack still lacks before simulated time may start (empty: ready): the VN-100 set up,
        and every link of the control path up at both ends (:func:`missing_links`): the
        ``~lockstep_graph`` topics from each of their publishers, the controller's answers to this node,
        and /clock to every node on the path."""
        missing = []
        mode, divisor, _fields = self.vn100.binary_config[75]
        if mode not in (1, 3) or divisor <= 0 or self.vn100.async_paused:
            missing.append("VN-100 binary output not configured yet")
        me = rospy.get_name()
        master = rosgraph.Master(me)
        try:
            publishers = {topic: nodes for topic, nodes in master.getSystemState()[0]}
        except (rosgraph.MasterError, OSError, xmlrpc.client.Error) as exc:
            return missing + ["master not reachable: %s" % exc]
        wanted = [(rospy.resolve_name(topic), node if node.startswith("/") else
                   rosgraph.names.ns_join(rospy.get_namespace(), node)) for topic, node in self.lockstep_graph]
        wanted += [(self.state_sub.resolved_name, me), (self.command_sub.resolved_name, me)]
        links = []
        for topic, subscriber in wanted:
            if not publishers.get(topic):
                missing.append("no publisher of %s" % topic)
            links += [(publisher, topic, subscriber) for publisher in publishers.get(topic, [])]
        path_nodes = sorted({node for link in links for node in (link[0], link[2])} - {me})
        links += [(me, "/clock", node) for node in path_nodes]

        def bus_info(node: str):
            try:
                _code, _message, info = xmlrpc.client.ServerProxy(master.lookupNode(node)).getBusInfo(me)
                return info
            except (rosgraph.MasterError, OSError, xmlrpc.client.Error):
                return None

        return missing + missing_links(links, bus_info)

    def _wait_until_ready(self) -> None:
        """Hold simulated time at its start until the control path is connected end to end (so no
        answer is lost to a connection still being made). /clock is repeated meanwhile, so that every
        node, whenever it starts, has a valid time before the first step."""
        last_report = time.monotonic()
        while not rospy.is_shutdown():
            self._publish_clock(self.sim_clock.t0)
            missing = self._lockstep_missing()
            if not missing:
                rospy.loginfo("sim_node: lock-step on simulated time from t=%.3f s", self.sim_clock.t0)
                self.started = time.monotonic()
                return
            if time.monotonic() - last_report > 5.0:
                rospy.loginfo("sim_node: lock-step waiting for the stack: %s", "; ".join(missing))
                last_report = time.monotonic()
            time.sleep(0.05)

    # ---- physics step ----------------------------------------------------------------------------

    def _slowed(self, commanded: np.ndarray) -> np.ndarray:
        """A servo slowed by a hardware fault: its target moves at no more than its fraction of the servo speed,
        which the servo model then follows; the others' targets pass unchanged."""
        scale = self.built.speed_scale
        if np.all(scale >= 1.0):
            return commanded
        if self.slowed_targets is None:
            self.slowed_targets = self.plant.joint_positions.reshape(12).copy()
        step = scale * self.servo_speed * self.dt
        self.slowed_targets = np.where(scale < 1.0, self.slowed_targets
                                       + np.clip(commanded - self.slowed_targets, -step, step), commanded)
        return self.slowed_targets.copy()

    def step(self, stamp: Optional[float] = None) -> None:
        """One plant step from the chip's pulse widths; ``stamp``: simulated time of the new state
        (lock-step), else the ROS clock now."""
        with self.lock:
            widths = np.asarray(self.fake.pulse_widths_us(), dtype=float)
        targets = self.built.joint_targets(widths)  # NaN: that servo gets no pulse and holds where it is
        self.commanded = np.where(np.isnan(targets), self.plant.joint_positions.reshape(12), targets)
        self.commanded = self._slowed(self.commanded)
        try:
            state = self.plant.step(self.commanded.reshape(4, 3), self.dt)
        except (SimulationError, ValueError) as exc:
            # A command the model cannot follow: the plant stays where it was; say so, keep serving.
            self.step_errors += 1
            rospy.logerr_throttle(1.0, "sim_node: plant step rejected: %s" % exc)
            state = self.plant.state
        stand = self.stand
        if stand is not None:  # on the stand, held by the operator
            self.plant.place_body(stand)
            state = self.plant.state
        acceleration_world = (state.velocity - self.previous_velocity) / self.dt
        self.previous_velocity = state.velocity.copy()
        self._write_sensors(acceleration_world)
        self._write_safety_sensors(self.dt)
        self.steps += 1
        stamp = rospy.Time.now() if stamp is None else _ros_time(stamp)
        pose = PoseStamped()
        pose.header.stamp = stamp
        pose.header.frame_id = "odom"  # REP-105 fixed frame, as the visualization node's
        (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
         pose.pose.orientation.w) = [float(v) for v in rot_to_quat(state.rotation)]
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = [float(v) for v in state.position]
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
        volts = self.built.feedback_volts(self.plant.joint_positions.reshape(12))
        with self.lock:
            self.fake.set_joint_voltages(volts)
        # Specific force in the body frame, what an accelerometer measures (REP-145: +g up when level).
        specific_force = R.T @ (acceleration_world + GRAVITY_UP)
        self.vn100.set_state(*self.built.imu_output(rot_to_quat(R), state.omega, specific_force))

    def _diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        elapsed = time.monotonic() - self.started
        real_time = self.steps * self.dt / elapsed if elapsed > 0 else 0.0
        if self.step_errors:
            stat.summary(DiagnosticStatus.WARN, "%d plant steps rejected" % self.step_errors)
        elif self.lockstep and self.lockstep_timeouts:
            stat.summary(DiagnosticStatus.WARN, "%d lock-step steps advanced unanswered (not deterministic)"
                         % self.lockstep_timeouts)
        elif real_time < 0.95 and elapsed > 5.0 and not self.lockstep:
            stat.summary(DiagnosticStatus.WARN, "physics behind real time (%.2fx)" % real_time)
        else:
            stat.summary(DiagnosticStatus.OK, "running")
        stat.add("clock", "lock-step (simulated time)" if self.lockstep else "real time")
        stat.add("steps", str(self.steps))
        stat.add("real-time factor", "%.3f" % real_time)
        stat.add("overruns", str(self.overruns))
        stat.add("rejected steps", str(self.step_errors))
        stat.add("lock-step timeouts", str(self.lockstep_timeouts))
        stat.add("clamped joint commands", str(self.plant.clamped_joints))
        stat.add("IMU streaming", str(self.vn100.connected))
        stat.add("I2C bus stuck", str(self.bridge.stuck))
        stat.add("I2C transactions timed out", str(self.bridge.stuck_transactions))
        stat.add("PCA9685 powered", str(self.fake.pca_powered))
        stat.add("depth sensor powered", str(self.fake.depth_powered))
        stat.add("true depth [m]", "%.3f" % self.depth_model.depth(float(self.plant.state.position[2])))
        for name, (_pack, simulated) in sorted(self.packs.items()):
            stat.add("battery %s [V]" % name, "%.3f" % simulated.voltage)
            stat.add("battery %s charge" % name, "%.3f" % simulated.charge)
            stat.add("battery %s current [A]" % name, "%.2f" % simulated.current_a)
        stat.add("fake VN-100 packets", str(self.vn100.packets_sent))
        return stat

    def _on_stand(self, msg: Vector3Stamped) -> None:
        rpy = (msg.vector.x, msg.vector.y, msg.vector.z)
        if not all(math.isfinite(v) for v in rpy):
            self.stand = None
            rospy.loginfo("sim_node: off the stand, floating")
            return
        self.stand = rpy_to_rot(*(math.radians(v) for v in rpy))
        rospy.loginfo("sim_node: on the stand at roll %.1f, pitch %.1f, yaw %.1f deg", *rpy)

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

    def _on_bus_stuck(self, request) -> SetBoolResponse:
        self.bridge.set_stuck(bool(request.data))
        message = "I2C bus %s" % ("stuck: every transaction times out" if request.data else "free again")
        rospy.logwarn("sim_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _on_pca_power(self, request) -> SetBoolResponse:
        self.fake.set_pca_power(bool(request.data))
        message = "PCA9685 %s" % ("powered (power-on reset state)" if request.data else "unpowered: no pulses")
        rospy.logwarn("sim_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _on_depth_fault(self, request) -> SetBoolResponse:
        if self.fake.depth is None:
            return SetBoolResponse(success=False, message="no depth sensor fitted (hardware.yaml depth.fitted false)")
        self.fake.set_depth_power(not request.data)
        message = "MS5837 %s" % ("off the bus: every transaction NACKs" if request.data else "answering again")
        rospy.logwarn("sim_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _on_water_inside(self, request) -> SetBoolResponse:
        self.water_inside = bool(request.data)
        message = "leak probe %s" % ("wet: water inside the enclosure" if request.data else "dry")
        rospy.logwarn("sim_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _on_battery_flat(self, request) -> SetBoolResponse:
        if not self.packs:
            return SetBoolResponse(success=False, message="no pack fitted (sim.launch batteries:=true fits both)")
        with self.lock:
            for _pack, simulated in self.packs.values():
                simulated.set_charge(0.0 if request.data else simulated.settings.start_charge)
        message = "packs %s" % ("run flat (charge 0)" if request.data else "fresh (start charge)")
        rospy.logwarn("sim_node: %s", message)
        return SetBoolResponse(success=True, message=message)

    def _shutdown(self) -> None:
        self.imu_pty.stop()
        self.bridge.close()


def main(argv: Optional[List[str]] = None) -> None:
    start_node("sim_node", SimNode).run()
