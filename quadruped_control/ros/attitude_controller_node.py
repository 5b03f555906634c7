"""ROS glue of the attitude controller: topics, parameters, arming service, reconfigure, diagnostics.

All decisions live in :class:`quadruped_control.control.supervisor.ControlSupervisor` and the controller object
it wraps (the same :class:`~quadruped_control.control.controller.AttitudeController` the offline simulator
steps). This module only moves data between ROS and those objects.

Subscribes
  imu/data               sensor_msgs/Imu                 world ENU <- base_link FLU (REP-145)
  joint_states           sensor_msgs/JointState          measured joint angles / velocities
  attitude_setpoint      geometry_msgs/QuaternionStamped the setpoint, body FLU -> its yaw reference's frame
  attitude_setpoint_rpy_deg  geometry_msgs/Vector3Stamped  the setpoint as roll, pitch, yaw in DEGREES (unit in the
                                                         name, REP-103: R = Rz(yaw) Ry(pitch) Rx(roll))
                         Both in the yaw reference header.frame_id names: relative (yaw from the heading at arming),
                         absolute (world ENU) or tilt (roll and pitch only); empty: ~yaw_reference
                         (quadruped_control.control.yaw_reference). controller_state.setpoint is the world R_d.
  preflight/result       diagnostic_msgs/DiagnosticStatus  the pre-dive check's verdict (latched; OK: passed)
  estop_state            std_msgs/Bool      pwm_node's e-stop: true disarms at once and refuses arming until reset
  tether/heartbeat       std_msgs/Header    the laptop's heartbeat (heartbeat_node); watched with ~heartbeat_timeout
  outputs_state          diagnostic_msgs/DiagnosticStatus  pwm_node's outputs (OK: they take commands); an arming check
  health/<source>        diagnostic_msgs/DiagnosticStatus  each of ~health_sources (depth, battery, leak): fresh and
                                                         not ERROR to arm; armed, a hazard (an ERROR whose "reason"
                                                         is not a measurement fault) takes safety.yaml's action
Publishes
  servo_command          underwater_quadruped/ServoCommand   12 pulse widths (us) + joint targets,
                                                             header.stamp = the IMU sample's stamp
  controller_state       underwater_quadruped/ControllerState  telemetry of every step (stamp: step time)
  telemetry/rpy_deg, telemetry/setpoint_rpy_deg, telemetry/error_rpy_deg  geometry_msgs/Vector3Stamped  for the
                         operator's plots at ~telemetry_rate: measured and commanded (world: controller_state's
                         setpoint) x roll, y pitch, z yaw in DEGREES, and setpoint - measured wrapped to +-180
                         (quadruped_control.control.attitude_degrees); frame_id odom (world ENU)
  telemetry/heading_at_arming_deg  std_msgs/Float64 (latched)  the heading a relative setpoint's yaw counts from
                         (NaN before the first arm): relative yaw = world yaw - this
  diagnostics            diagnostic_msgs/DiagnosticArray
Services
  ~arm                   std_srvs/SetBool   legs move only when armed; refused (success false, every reason in
                                            the message and in the "arming" diagnostic) while a check fails
                                            (ControlSupervisor.arming_checks); armed, the soft start first
  ~save_gains            underwater_quadruped/SaveGains  the gains in force as a gain set of a yaml file, new or
                                            given (quadruped_control.control.gain_file: refused without overwrite
                                            over an existing set or the shipped config/controller.yaml)
Parameters
  ~gain_set (experiment) ~controller_yaml ~robot_yaml ~hardware_yaml ~calibration_yaml ~vn100_yaml ~safety_yaml
                         (package config/; vn100.yaml gives the IMU's plausible ranges, safety.yaml the soft
                         start, the outputs check and the disarm action)
  ~loop_rate (100 Hz)    ~imu_rate (200 Hz: the loop steps on every imu_rate/loop_rate-th sample, so
                          the command leaves right after the sample that caused it)
  ~imu_max_age (0.05 s)  ~arm_on_start (false: arms once the checks pass; the first start only)
  ~arm_on_start_delay (0 s: that arm not before this long after the start; sim.launch lock-step: 1 s)
  ~setpoint_rpy_deg ([0, 0, 0]: in ~yaw_reference)
  ~telemetry_rate (20 Hz: telemetry/*_rpy_deg every loop_rate/telemetry_rate-th step; 0: off)
  ~yaw_reference (yaw_reference of controller.yaml: relative | absolute | tilt)
  ~require_preflight (false; robot.launch: true): arming waits for a passed pre-dive check
  ~health_sources (default: what hardware_yaml fits: depth if depth.fitted, battery if a pack is, leak if leak.fitted)
  ~batteries_fitted ~leak_fitted (false: hardware_yaml decides; true: the simulated robot's packs, probe)
  ~heartbeat_timeout (0: not watched; robot.launch: 2 s): arming needs the tether heartbeat, and armed, none for
                         this long acts: ~tether_action (disarm | limp: the outputs off too | hold: armed, the
                         attitude it has as the setpoint)
  ~starts                the node's starts since the launch file set it to 0: a respawned node (start > 1)
                         comes back disarmed whatever ~arm_on_start says
  ~stroke_scheme (stroke.scheme of controller.yaml: paper | coordinated)
  dynamic_reconfigure (AttitudeController.cfg): k_p k_i k_d k_aw tau_max t_rec t_pow_max stroke_scheme
                         (a scheme switch is smooth: the feet return to the nominal pose first); seeded from the
                         gain set, so the latched ~parameter_updates (dynamic_reconfigure/Config, recorded) holds
                         the values in force from the start and after every change
"""
from __future__ import annotations

import math
import re
import threading
import time
from typing import List, Optional

import numpy as np
import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from dynamic_reconfigure.server import Server as ReconfigureServer
from geometry_msgs.msg import Point, Quaternion, QuaternionStamped, Vector3, Vector3Stamped
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Bool, Float64, Header
from std_srvs.srv import SetBool, SetBoolResponse

from quadruped_common.config import ParameterError
from quadruped_common.monitoring import STALE_IMU, HoldEpisodes, RateMonitor, WindowStatistics, hold_kind
from quadruped_common.robot import JOINT_NAMES
from quadruped_common.ros.node_startup import start_node
from quadruped_common.so3 import quat_to_rot, rot_to_quat, rot_to_rpy, rpy_to_rot
from quadruped_common.ros.diagnostics import Updater
from quadruped_control.control.attitude_degrees import attitude_degrees
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import TUNABLE_BOUNDS, apply_tunables, load_controller_config
from quadruped_control.control.gain_file import save_gain_set
from quadruped_control.control.safety_config import load_safety_config
from quadruped_control.control.supervisor import ControlSupervisor
from quadruped_control.control.yaw_reference import mode_of_frame
from quadruped_control.model.params import load_robot_params
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config, with_batteries_fitted
from quadruped_drivers.vn100.settings import load_vn100_settings, sensor_limits
from underwater_quadruped.cfg import AttitudeControllerConfig
from underwater_quadruped.msg import ControllerState, ServoCommand
from underwater_quadruped.srv import SaveGains, SaveGainsResponse

_PHASE_CODES = {"recovery": ControllerState.PHASE_RECOVERY, "power": ControllerState.PHASE_POWER,
                "hold": ControllerState.PHASE_HOLD}


def _problem_kind(problem: str) -> str:
    return re.sub(r"[-+]?[0-9.]+", "#", problem)


def _optional_path(name: str) -> Optional[str]:
    value = rospy.get_param(name, "")
    return value or None


def make_pulse_map(calibration, hardware):
    """Joint angles -> pulse widths through the servo calibration, clamped to the channel limits."""
    low, high = hardware.min_us, hardware.max_us

    def pulse_map(angles: np.ndarray) -> np.ndarray:
        return np.clip(calibration.angles_to_pulses(angles), low, high)

    return pulse_map


class AttitudeControllerNode:
    def __init__(self) -> None:
        robot = load_robot_params(_optional_path("~robot_yaml"))
        gain_set = rospy.get_param("~gain_set", "experiment")
        self.gain_source = "gain set '%s' of %s" % (gain_set,
                                                    _optional_path("~controller_yaml") or "config/controller.yaml")
        self.config = load_controller_config(_optional_path("~controller_yaml"), gain_set)
        scheme = rospy.get_param("~stroke_scheme", "") or self.config.stroke_scheme
        self.config = self.config.replace(stroke_scheme=scheme)
        yaw_reference = rospy.get_param("~yaw_reference", "") or self.config.yaw_reference
        self.config = self.config.replace(yaw_reference=yaw_reference)
        hardware = load_hardware_config(_optional_path("~hardware_yaml"))
        if rospy.get_param("~batteries_fitted", False):
            hardware = with_batteries_fitted(hardware)
        leak_fitted = hardware.leak.fitted or bool(rospy.get_param("~leak_fitted", False))
        fitted = (["depth"] * hardware.depth.fitted + ["battery"] * bool(hardware.batteries.fitted)
                  + ["leak"] * leak_fitted)
        calibration = load_servo_calibration(_optional_path("~calibration_yaml"))
        self.loop_rate = float(rospy.get_param("~loop_rate", 100.0))
        imu_rate = float(rospy.get_param("~imu_rate", 200.0))
        if not (self.loop_rate > 0 and imu_rate >= self.loop_rate):
            raise ParameterError("need imu_rate >= loop_rate > 0, got imu_rate %r, loop_rate %r"
                                 % (imu_rate, self.loop_rate))
        self.decimation = max(1, int(round(imu_rate / self.loop_rate)))
        self.period = 1.0 / self.loop_rate

        # IMU plausibility: the sensor's ranges from vn100.yaml, the same values the driver checks.
        vn100 = load_vn100_settings(_optional_path("~vn100_yaml"))
        imu_limits = sensor_limits(vn100)
        self.config = self.config.replace(max_angular_rate=imu_limits.max_angular_rate)
        controller = AttitudeController(robot, self.config)
        # A respawned controller (roslaunch respawns it after a crash or a kill) never moves the legs
        # without a new arm command: ~arm_on_start applies to the first start only. The parameter server
        # outlives the process, so a start that finds ~starts already set is a restart.
        self.starts = int(rospy.get_param("~starts", 0)) + 1
        rospy.set_param("~starts", self.starts)
        arm_on_start = bool(rospy.get_param("~arm_on_start", False)) and self.starts == 1
        if self.starts > 1:
            rospy.logwarn("attitude controller: restart %d: disarmed until %s is called",
                          self.starts - 1, rospy.resolve_name("~arm"))
        require_preflight = bool(rospy.get_param("~require_preflight", False))
        heartbeat_timeout = float(rospy.get_param("~heartbeat_timeout", 0.0))  # 0: not watched
        self.safety = load_safety_config(_optional_path("~safety_yaml"))
        self.supervisor = ControlSupervisor(controller, make_pulse_map(calibration, hardware),
                                            max_imu_age=float(rospy.get_param("~imu_max_age", 0.05)),
                                            armed=arm_on_start, imu_limits=imu_limits,
                                            require_preflight=require_preflight,
                                            heartbeat_timeout=heartbeat_timeout or None,
                                            tether_action=str(rospy.get_param("~tether_action", "disarm")),
                                            safety=self.safety,
                                            health_sources=list(rospy.get_param("~health_sources", fitted)))
        roll, pitch, yaw = [math.radians(v) for v in rospy.get_param("~setpoint_rpy_deg", [0.0, 0.0, 0.0])]
        self.supervisor.set_setpoint(rpy_to_rot(roll, pitch, yaw))
        rospy.set_param("~yaw_reference", self.config.yaw_reference)
        if arm_on_start:
            rospy.loginfo("attitude controller: ~arm_on_start: arming once every check passes")
        self.was_armed = False
        self.reported_arm_failure = ""
        self.reported_tracking: dict = {}
        self.reported_imu_drops = 0
        self.lock = threading.Lock()
        self.imu_count = 0
        self.last_step_wall: Optional[float] = None
        self.sim_time = bool(rospy.get_param("/use_sim_time", False))
        if self.sim_time:
            self._wait_for_clock()
        # ROS clock (simulated time under use_sim_time) of the last step; the start counts as one, so
        # the fallback timer's first step comes 1.5 periods after start-up (deterministic in lock-step).
        self.last_step_time: float = rospy.get_time()
        # ~arm_on_start_delay: the start-up arm not before this long after the start, so that in lock-step it
        # lands on the same tick in every run whenever the drivers' first messages come.
        self.supervisor.arm_not_before = self.last_step_time + float(rospy.get_param("~arm_on_start_delay", 0.0))
        self.hold_episodes = HoldEpisodes()
        self.jitter = WindowStatistics(2000)
        self.step_time = WindowStatistics(2000)
        self.overruns = 0
        self.loop_monitor = RateMonitor(2.0)
        self.imu_monitor = RateMonitor(2.0)
        self.joint_monitor = RateMonitor(2.0)
        self.last_problem = ""
        self.joint_index = {name: i for i, name in enumerate(JOINT_NAMES)}

        self.command_pub = rospy.Publisher("servo_command", ServoCommand, queue_size=10)
        self.state_pub = rospy.Publisher("controller_state", ControllerState, queue_size=10)
        telemetry_rate = float(rospy.get_param("~telemetry_rate", 20.0))
        self.telemetry_every = max(1, int(round(self.loop_rate / telemetry_rate))) if telemetry_rate > 0 else 0
        self.telemetry_steps = 0
        self.rpy_pub = rospy.Publisher("telemetry/rpy_deg", Vector3Stamped, queue_size=5)
        self.setpoint_rpy_pub = rospy.Publisher("telemetry/setpoint_rpy_deg", Vector3Stamped, queue_size=5)
        self.error_rpy_pub = rospy.Publisher("telemetry/error_rpy_deg", Vector3Stamped, queue_size=5)
        self.heading_pub = rospy.Publisher("telemetry/heading_at_arming_deg", Float64, queue_size=1, latch=True)
        self.heading_published: Optional[float] = None
        self.heading_pub.publish(Float64(math.nan))
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("none")  # no hardware of its own (diagnostic_updater convention)
        self.diagnostics.add("control loop", self._diagnose_loop)
        self.diagnostics.add("inputs", self._diagnose_inputs)
        self.diagnostics.add("arming", self._diagnose_arming)
        self.diagnostics.add("servo tracking", self._diagnose_tracking)

        # Seed the reconfigure parameters from the chosen gain set: the server reads them at start-up
        # instead of the .cfg defaults, so gain_set:=experiment is not overwritten by the defaults.
        gains = self.config.gains
        for name, value in (("k_p", gains.k_p), ("k_i", gains.k_i), ("k_d", gains.k_d),
                            ("k_aw", gains.k_aw), ("tau_max", self.config.tau_max),
                            ("t_rec", self.config.t_rec), ("t_pow_max", self.config.t_pow_max)):
            rospy.set_param("~" + name, float(value))
        rospy.set_param("~stroke_scheme", self.config.stroke_scheme)
        self.reconfigure = ReconfigureServer(AttitudeControllerConfig, self._on_reconfigure)

        rospy.Service("~arm", SetBool, self._on_arm)
        rospy.Service("~save_gains", SaveGains, self._on_save_gains)
        rospy.Subscriber("preflight/result", DiagnosticStatus, self._on_preflight, queue_size=1)
        rospy.Subscriber("estop_state", Bool, self._on_estop, queue_size=1, tcp_nodelay=True)
        rospy.Subscriber("tether/heartbeat", Header, self._on_heartbeat, queue_size=1, tcp_nodelay=True)
        rospy.Subscriber("outputs_state", DiagnosticStatus, self._on_outputs_state, queue_size=1)
        for source in self.supervisor.health_sources:
            rospy.Subscriber("health/" + source, DiagnosticStatus, self._on_health, callback_args=source, queue_size=1)
        rospy.Subscriber("joint_states", JointState, self._on_joint_states, queue_size=5)
        rospy.Subscriber("attitude_setpoint", QuaternionStamped, self._on_setpoint, queue_size=1)
        rospy.Subscriber("attitude_setpoint_rpy_deg", Vector3Stamped, self._on_setpoint_rpy, queue_size=1)
        rospy.Subscriber("imu/data", Imu, self._on_imu, queue_size=5, tcp_nodelay=True)
        # Fallback: when IMU samples stop, this timer still ticks the supervisor so that it holds.
        self.fallback_timer = rospy.Timer(rospy.Duration(self.period), self._on_fallback_timer)
        rospy.loginfo("attitude controller: gain set '%s' (K_p %.3g K_i %.3g K_d %.3g K_aw %.3g), "
                      "%.0f Hz stepped every %d IMU samples, %s strokes, %s yaw reference, %s", gain_set, gains.k_p,
                      gains.k_i, gains.k_d, gains.k_aw, self.loop_rate, self.decimation, self.config.stroke_scheme,
                      self.config.yaw_reference, "ARMED" if self.supervisor.armed else "disarmed (call ~arm)")

    # ---- callbacks -----------------------------------------------------------------------------

    def _on_imu(self, msg: Imu) -> None:
        o, w = msg.orientation, msg.angular_velocity
        with self.lock:
            a = msg.linear_acceleration
            dropped = self.supervisor.set_imu((o.x, o.y, o.z, o.w), (w.x, w.y, w.z), msg.header.stamp.to_sec(),
                                              (a.x, a.y, a.z))
            self.imu_monitor.tick(time.monotonic())
            self.imu_count += 1
            due = self.imu_count % self.decimation == 0
        if dropped:
            rospy.logwarn_throttle(1.0, "attitude controller: IMU sample dropped: %s" % dropped)
        if due:
            if self.sim_time:
                self._wait_for_next_clock()
            self._step()

    def _wait_for_clock(self) -> None:
        """Under use_sim_time, wait for the first /clock so that timers start at a valid time."""
        while not rospy.is_shutdown() and rospy.get_time() == 0.0:
            time.sleep(0.01)

    def _wait_for_next_clock(self, timeout: float = 1.0) -> None:
        """Under use_sim_time, an IMU sample can overtake the /clock message of its step (different
        connections): the step waits until the clock has moved past the previous step."""
        deadline = time.monotonic() + timeout
        while rospy.get_time() <= self.last_step_time and time.monotonic() < deadline \
                and not rospy.is_shutdown():
            time.sleep(0.0002)

    def _on_fallback_timer(self, _event) -> None:
        # Judged on the ROS clock, like the timer itself: under use_sim_time (lock-step simulation) a
        # slow machine must not make the fallback step in between two IMU-driven steps.
        if rospy.get_time() - self.last_step_time > 1.5 * self.period:
            self._step()

    def _on_joint_states(self, msg: JointState) -> None:
        positions = np.full(12, np.nan)
        velocities = np.full(12, np.nan)
        for k, name in enumerate(msg.name):
            i = self.joint_index.get(name)
            if i is None:
                continue
            if k < len(msg.position):
                positions[i] = msg.position[k]
            if k < len(msg.velocity):
                velocities[i] = msg.velocity[k]
        with self.lock:
            self.supervisor.set_joint_feedback(positions, velocities, msg.header.stamp.to_sec())
            self.joint_monitor.tick(time.monotonic())

    def _set_setpoint(self, R: np.ndarray, frame_id: str, text: str) -> None:
        """A setpoint message's rotation in the yaw reference its frame_id names (mode_of_frame)."""
        try:
            mode = mode_of_frame(frame_id)
            with self.lock:
                target = self.supervisor.set_setpoint(R, mode)
                mode, psi_0 = self.supervisor.yaw.mode, self.supervisor.yaw.psi_0
        except ValueError as exc:
            rospy.logerr("attitude setpoint rejected: %s", exc)
            return
        if mode == "relative":
            text += " relative to the heading at arming (%s)" % (
                "not armed yet" if psi_0 is None else "%.1f deg" % math.degrees(psi_0))
        rospy.loginfo("attitude setpoint: %s, %s: world roll %.1f pitch %.1f yaw %s deg", text, mode,
                      *np.degrees(rot_to_rpy(target.R_d)[:2]),
                      "free" if target.yaw_free else "%.1f" % math.degrees(rot_to_rpy(target.R_d)[2]))

    def _on_setpoint(self, msg: QuaternionStamped) -> None:
        q = np.array([msg.quaternion.x, msg.quaternion.y, msg.quaternion.z, msg.quaternion.w])
        if not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-3:
            rospy.logerr("attitude setpoint rejected: quaternion %s is not a finite unit quaternion", q)
            return
        self._set_setpoint(quat_to_rot(q / np.linalg.norm(q)), msg.header.frame_id, "quaternion %s" % np.round(q, 4))

    def _on_setpoint_rpy(self, msg: Vector3Stamped) -> None:
        rpy = np.array([msg.vector.x, msg.vector.y, msg.vector.z])
        if not np.all(np.isfinite(rpy)):
            rospy.logerr("attitude setpoint rejected: roll/pitch/yaw %s not finite", rpy)
            return
        self._set_setpoint(rpy_to_rot(*np.radians(rpy)), msg.header.frame_id,
                           "roll %.1f pitch %.1f yaw %.1f deg" % tuple(rpy))

    def _on_arm(self, request) -> SetBoolResponse:
        with self.lock:
            was_armed = self.supervisor.armed
            message = self.supervisor.arm(bool(request.data))
            success = self.supervisor.armed == bool(request.data)
        rospy.logwarn("attitude controller %s", message)
        if was_armed and not request.data and self.safety.disarm_action == "limp":
            self._go_limp("disarm")
        return SetBoolResponse(success=success, message=message)

    def _on_health(self, msg: DiagnosticStatus, source: str) -> None:
        reason = next((item.value for item in msg.values if item.key == "reason"), "")
        with self.lock:
            self.supervisor.set_health(source, msg.level >= DiagnosticStatus.ERROR, msg.message, rospy.get_time(),
                                       reason)

    def _on_outputs_state(self, msg: DiagnosticStatus) -> None:
        with self.lock:
            self.supervisor.set_outputs_state("" if msg.level == DiagnosticStatus.OK else msg.message,
                                              rospy.get_time())

    def _on_heartbeat(self, _msg: Header) -> None:
        with self.lock:
            self.supervisor.set_heartbeat(rospy.get_time())

    def _on_tether_lost(self, action: str) -> None:
        if action == "hold":
            rospy.logerr("attitude controller: TETHER LOST: no heartbeat for %.1f s: holding the attitude the robot "
                         "has (armed) until a new setpoint", self.supervisor.heartbeat_timeout)
            return
        rospy.logerr("attitude controller: TETHER LOST: no heartbeat for %.1f s: disarmed%s; arm again once it "
                     "is back", self.supervisor.heartbeat_timeout, ", outputs off (limp)" if action == "limp" else "")
        if action == "limp":
            self._go_limp("tether failsafe")

    def _go_limp(self, why: str) -> None:
        """Every output off (pwm_node/enable false), off the calling thread: a service call can wait."""
        threading.Thread(target=self._outputs_off, args=(why,), name="limp", daemon=True).start()

    def _outputs_off(self, why: str) -> None:
        try:
            rospy.wait_for_service("pwm_node/enable", timeout=1.0)
            rospy.ServiceProxy("pwm_node/enable", SetBool)(False)
        except (rospy.ROSException, rospy.ServiceException) as exc:
            rospy.logerr("attitude controller: %s could not switch the outputs off: %s", why, exc)

    def _on_estop(self, msg: Bool) -> None:
        with self.lock:
            was_armed = self.supervisor.armed
            self.supervisor.set_estop(msg.data)
        if msg.data:
            rospy.logerr("attitude controller: e-stop latched%s; arming refused until it is reset",
                         ": disarmed" if was_armed else "")
        else:
            rospy.logwarn("attitude controller: e-stop reset; disarmed until %s", rospy.resolve_name("~arm"))

    def _on_preflight(self, msg: DiagnosticStatus) -> None:
        passed = msg.level == DiagnosticStatus.OK
        with self.lock:
            self.supervisor.set_preflight(passed, msg.message)
        rospy.loginfo("attitude controller: pre-dive check %s: %s", "passed" if passed else "FAILED", msg.message)

    def _on_reconfigure(self, config, _level):
        """Validate and apply live gains/timing; an invalid update (NaN, out of range, t_rec < 2 t_pow_max)
        is refused as a whole, logged and reverted; this callback never raises."""
        current = self.supervisor.controller.config
        try:
            updated = apply_tunables(current, {name: getattr(config, name) for name in TUNABLE_BOUNDS})
            updated = updated.replace(stroke_scheme=config.stroke_scheme)
        except (ValueError, TypeError, AttributeError) as exc:
            rospy.logerr("reconfigure refused (values kept): %s", exc)
            for name in TUNABLE_BOUNDS:
                setattr(config, name, getattr(current.gains if name.startswith("k_") else current, name))
            config.stroke_scheme = current.stroke_scheme
            return config
        with self.lock:
            self.supervisor.controller.set_gains(updated.gains)
            self.supervisor.controller.set_timing(t_rec=updated.t_rec, t_pow_max=updated.t_pow_max,
                                                  tau_max=updated.tau_max)
            self.supervisor.controller.set_stroke_scheme(updated.stroke_scheme)
        old_values = dict(vars(current.gains), tau_max=current.tau_max, t_rec=current.t_rec, t_pow_max=current.t_pow_max)
        new_values = dict(vars(updated.gains), tau_max=updated.tau_max, t_rec=updated.t_rec, t_pow_max=updated.t_pow_max)
        changed = ["%s %.4g -> %.4g" % (name, old_values[name], new_values[name]) for name in TUNABLE_BOUNDS
                   if abs(old_values[name] - new_values[name]) > 1e-12]
        if updated.stroke_scheme != current.stroke_scheme:
            changed.append("stroke_scheme %s -> %s (switching once the feet are at the nominal pose)"
                           % (current.stroke_scheme, updated.stroke_scheme))
        if changed:
            rospy.loginfo("reconfigure: %s", ", ".join(changed))
        return config

    def _on_save_gains(self, request) -> SaveGainsResponse:
        """Write the gains in force as a gain set (:func:`~quadruped_control.control.gain_file.save_gain_set`);
        a refusal or a failed write is the response's message; this callback never raises."""
        note = "saved by %s ~save_gains at %s: %s as tuned live" % (
            rospy.get_name(), time.strftime("%Y-%m-%d %H:%M:%S"), self.gain_source)
        try:
            message = save_gain_set(self.supervisor.controller.config, request.path, request.gain_set,
                                    request.overwrite, note)
        except (ValueError, OSError) as exc:
            rospy.logwarn("save_gains refused: %s", exc)
            return SaveGainsResponse(False, str(exc))
        rospy.loginfo("save_gains: %s", message)
        return SaveGainsResponse(True, message)

    # ---- the control step ------------------------------------------------------------------------

    def _step(self) -> None:
        if rospy.is_shutdown():
            return
        started = time.monotonic()
        with self.lock:
            if self.last_step_wall is not None:
                period = started - self.last_step_wall
                self.jitter.add(abs(period - self.period))
                if period > 2.0 * self.period:
                    self.overruns += 1
            self.last_step_wall = started
            self.loop_monitor.tick(started)
            # Controller time and the clock the IMU stamps are judged against; it also stamps this
            # step's controller_state (the moment of the decision, not of the publish, which can wait
            # behind other threads).
            step_stamp = rospy.Time.now()
            now = step_stamp.to_sec()
            self.last_step_time = now
            tether = self.supervisor.check_tether(now)
            health = self.supervisor.check_health(now)
            pending = self.supervisor.arm_pending
            result = self.supervisor.tick(now, now)
            soft_start = result.problem.startswith("soft start")  # a start, not a hold
            held = bool(result.problem) and result.armed and not soft_start
            self.hold_episodes.update(now, held, hold_kind(result.problem) if held else "")
            armed_now, was_armed, self.was_armed = result.armed, self.was_armed, result.armed
            failure = self.supervisor.last_arm_failure
            tracking = {name: level for name, level, _ in self.supervisor.tracking_levels if level}
            self.telemetry_steps += 1
            telemetry = bool(self.telemetry_every) and self.telemetry_steps % self.telemetry_every == 0
            attitude = self.supervisor.attitude() if telemetry else None
            psi_0 = self.supervisor.yaw.psi_0
        if tether is not None:
            self._on_tether_lost(tether)
        for source, action, why in health:
            if action == "warn":
                rospy.logwarn("attitude controller: health/%s: %s (safety.yaml: warn only)", source, why)
                continue
            rospy.logerr("attitude controller: health/%s: %s: disarmed%s; arm again once it is well", source, why,
                         ", outputs off (limp)" if action == "limp" else "")
            if action == "limp":
                self._go_limp("health/" + source)
        if armed_now and not was_armed and pending:  # an arm asked for at start-up, now that the checks pass
            rospy.logwarn("attitude controller armed (~arm_on_start): %s", result.problem or "strokes start")
        if tracking != self.reported_tracking:
            for name, level in sorted(tracking.items()):
                if level > self.reported_tracking.get(name, 0):
                    (rospy.logerr if level >= DiagnosticStatus.ERROR else rospy.logwarn)(
                        "attitude controller: servo tracking: %s %s: its feedback is off the servo model", name,
                        "ERROR" if level >= DiagnosticStatus.ERROR else "WARN")
            self.reported_tracking = tracking
            self.diagnostics.force_update()  # at once, not at the next period
        if failure != self.reported_arm_failure:
            self.reported_arm_failure = failure
            if failure:
                rospy.logerr("attitude controller: arm withdrawn: %s", failure)
        # Log on a change of the kind of problem (numbers such as the sample age change every step).
        if _problem_kind(result.problem) != _problem_kind(self.last_problem):
            if soft_start:
                rospy.loginfo("attitude controller: %s", result.problem)
            elif result.problem:
                rospy.logwarn("attitude controller holding the safe pose: %s", result.problem)
            elif self.last_problem:
                rospy.loginfo("attitude controller stroking again (was: %s)", self.last_problem)
        self.last_problem = result.problem
        stamp = rospy.Time.from_sec(result.imu_stamp) if result.imu_stamp is not None else rospy.Time.now()
        try:
            # The servo command first: it is what the IMU-to-PWM latency is measured on.
            if result.pulse_widths_us is not None:
                command = ServoCommand()
                command.header.stamp = stamp
                command.name = list(JOINT_NAMES)
                command.pulse_width_us = result.pulse_widths_us.tolist()
                command.joint_target = result.joint_targets.tolist()
                self.command_pub.publish(command)
            self.state_pub.publish(self._state_message(result, step_stamp))
            if telemetry:
                self._publish_telemetry(attitude, result.output.state.R_d, step_stamp)
            if psi_0 != self.heading_published:
                self.heading_published = psi_0
                self.heading_pub.publish(Float64(math.nan if psi_0 is None else math.degrees(psi_0)))
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise
            return  # shutting down: the publishers are already closed
        self.step_time.add(time.monotonic() - started)
        self.diagnostics.update()

    def _publish_telemetry(self, R: Optional[np.ndarray], R_d: np.ndarray, stamp) -> None:
        """telemetry/*_rpy_deg of measured attitude R (None: not known yet) and world setpoint R_d."""
        degrees = attitude_degrees(R, R_d)
        for publisher, values in ((self.rpy_pub, degrees.rpy), (self.setpoint_rpy_pub, degrees.setpoint),
                                  (self.error_rpy_pub, degrees.error)):
            msg = Vector3Stamped(vector=Vector3(*values))
            msg.header.stamp, msg.header.frame_id = stamp, "odom"
            publisher.publish(msg)

    def _state_message(self, result, stamp) -> ControllerState:
        record = result.output.state
        msg = ControllerState()
        msg.header.stamp = stamp
        msg.header.frame_id = "base_link"
        x, y, z, w = rot_to_quat(record.setpoint)
        msg.setpoint = Quaternion(x, y, z, w)
        msg.attitude_error = Vector3(*record.e_R)
        msg.geodesic_error = float(record.geodesic_error)
        msg.torque_command = Vector3(*record.tau_cmd)
        msg.torque_saturated = Vector3(*record.tau_sat)
        msg.integral = Vector3(*record.integral)
        msg.torque_estimated = Vector3(*result.torque_estimated)
        msg.armed = result.armed
        msg.holding = bool(record.holding)
        msg.hold_reason = result.problem
        msg.pair_phase = [_PHASE_CODES[p] for p in record.pair_phase]
        msg.pair_phase_time = [float(v) for v in record.pair_phase_time]
        msg.foot_targets = [Point(*p) for p in np.asarray(record.foot_targets)]
        return msg

    # ---- diagnostics -----------------------------------------------------------------------------

    def _diagnose_loop(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        now = time.monotonic()
        rate = self.loop_monitor.rate(now)
        jitter = self.jitter.summary(1e3)
        compute = self.step_time.summary(1e3)
        if self.last_problem.startswith("soft start") and self.supervisor.armed:
            stat.summary(DiagnosticStatus.OK, "armed, %s" % self.last_problem)
        elif self.last_problem and self.supervisor.armed:
            stat.summary(DiagnosticStatus.WARN, "holding safe pose: %s" % self.last_problem)
        elif rate < 0.9 * self.loop_rate:
            stat.summary(DiagnosticStatus.WARN, "loop at %.1f Hz, below %.0f Hz" % (rate, self.loop_rate))
        else:
            stat.summary(DiagnosticStatus.OK, "armed, stroking" if self.supervisor.armed else "disarmed")
        stat.add("armed", str(self.supervisor.armed))
        stat.add("restarts", str(self.starts - 1))
        stat.add("hold reason", self.last_problem)
        stat.add("loop rate [Hz]", "%.2f" % rate)
        stat.add("period jitter p50 [ms]", "%.3f" % jitter["p50"])
        stat.add("period jitter p99 [ms]", "%.3f" % jitter["p99"])
        stat.add("step time p50 [ms]", "%.3f" % compute["p50"])
        stat.add("step time p99 [ms]", "%.3f" % compute["p99"])
        stat.add("overruns", str(self.overruns))
        stat.add("held steps", str(self.hold_episodes.held_ticks))
        stat.add("hold episodes", str(self.hold_episodes.episodes))
        stat.add("stale-IMU hold episodes", str(self.hold_episodes.episodes_of(STALE_IMU)))
        stat.add("time held [s]", "%.3f" % self.hold_episodes.time_held)
        stat.add("controller errors", str(self.supervisor.controller_errors))
        return stat

    def _diagnose_arming(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        with self.lock:
            checks = self.supervisor.arming_checks()
            armed, pending, soft = self.supervisor.armed, self.supervisor.arm_pending, self.supervisor.soft_starting
        failing = ["%s: %s" % (name, problem) for name, problem in checks if problem]
        if armed:
            stat.summary(DiagnosticStatus.OK, "armed, soft start" if soft else "armed")
        elif failing:
            stat.summary(DiagnosticStatus.WARN, "arming refused: " + "; ".join(failing))
        else:
            stat.summary(DiagnosticStatus.OK, "ready to arm")
        stat.add("arm pending (asked at start)", str(pending))
        for name, problem in checks:
            stat.add(name, problem or "ok")
        return stat

    def _diagnose_tracking(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        with self.lock:
            watch = self.supervisor.tracking
            levels = list(self.supervisor.tracking_levels)
            largest = watch.largest_rms.copy() if watch is not None else None
            active = watch is not None and watch.active
        bound = self.safety.tracking.bound
        failing = [(name, level, rms) for name, level, rms in levels if level > DiagnosticStatus.OK]
        if not active:
            stat.summary(DiagnosticStatus.OK, "not armed: not judged")
        elif failing:
            worst = max(level for _, level, _ in failing)
            stat.summary(worst, "%s off the servo model (RMS %s; bound %.1f deg)" % (
                ", ".join(name for name, _, _ in failing),
                ", ".join("%.1f deg" % math.degrees(rms) for _, _, rms in failing), math.degrees(bound)))
        else:
            stat.summary(DiagnosticStatus.OK, "every joint follows its command")
        for i, (name, level, rms) in enumerate(levels):
            stat.add(name, "%s, RMS %.2f deg, largest since arming %.2f deg" % (
                ("OK", "WARN", "ERROR")[level], math.degrees(rms) if math.isfinite(rms) else float("nan"),
                math.degrees(largest[i]) if largest is not None else float("nan")))
        return stat

    def _diagnose_inputs(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        now = time.monotonic()
        problem = self.supervisor.imu_problem(rospy.get_time())
        joints = self.joint_monitor.rate(now)
        drops = self.supervisor.imu_dropped
        new_drops, self.reported_imu_drops = drops - self.reported_imu_drops, drops
        if problem:
            stat.summary(DiagnosticStatus.ERROR, problem)
        elif new_drops:
            stat.summary(DiagnosticStatus.WARN, "%d implausible IMU samples dropped (last: %s)"
                         % (new_drops, self.supervisor.last_imu_drop))
        elif joints == 0.0:
            stat.summary(DiagnosticStatus.WARN, "no joint_states (torque estimate unavailable)")
        else:
            stat.summary(DiagnosticStatus.OK, "IMU and joint feedback fresh")
        stat.add("imu rate [Hz]", "%.1f" % self.imu_monitor.rate(now))
        stat.add("joint_states rate [Hz]", "%.1f" % joints)
        stat.add("imu samples received", str(self.supervisor.imu_received))
        stat.add("imu samples dropped (implausible)", str(drops))
        for reason, count in sorted(self.supervisor.imu_drop_reasons.items()):
            stat.add("dropped: %s" % reason, str(count))
        stat.add("last dropped sample", self.supervisor.last_imu_drop)
        stat.add("joint readings outside the servo range", str(self.supervisor.joint_readings_implausible))
        return stat


def main(argv: Optional[List[str]] = None) -> None:
    start_node("attitude_controller", AttitudeControllerNode)
    rospy.spin()
