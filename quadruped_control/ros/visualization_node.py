"""rviz glue: full joint state for the URDF, body and setpoint TF, foot-target markers.

Subscribes:
  joint_states      sensor_msgs/JointState   the 12 actuated angles (paper's theta1..3 per leg)
  imu/data          sensor_msgs/Imu          body orientation, world ENU <- base_link (REP-145)
  controller_state  ControllerState          setpoint R_d and foot targets (base_link)
Publishes:
  joint_states_visual  sensor_msgs/JointState        actuated + passive five-bar angles, for
                                                     robot_state_publisher (remapped)
  foot_target_markers  visualization_msgs/MarkerArray  one sphere per foot target, frame base_link
  TF  odom -> base_link (IMU orientation), odom -> setpoint (R_d), both at ~base_position
Parameters:
  ~world_frame (odom: REP-105's fixed frame, ENU, no position estimate), ~base_frame (base_link),
  ~imu_frame (imu_link: the URDF fixes it to base_link with aligned axes), ~setpoint_frame (setpoint),
  ~base_position ([0, 0, 0], m, where the body is drawn in the world frame: the robot has no position
  estimate), ~marker_rate (20 Hz, cap on marker updates), ~draw_rate (30 Hz, cap on joint state and TF
  updates), ~robot_yaml (package config/robot.yaml).

All maths lives in quadruped_control.ros.visualization; this node only wires messages.
"""
from __future__ import annotations

import time
from typing import Sequence

import rospy
import tf2_ros
from diagnostic_msgs.msg import DiagnosticStatus
from diagnostic_updater import DiagnosticStatusWrapper
from geometry_msgs.msg import TransformStamped
from sensor_msgs.msg import Imu, JointState
from visualization_msgs.msg import Marker, MarkerArray

from quadruped_common.config import config_path
from quadruped_common.monitoring import RateMonitor
from quadruped_common.ros.node_startup import start_node
from quadruped_common.ros.diagnostics import Updater
from quadruped_control.model.params import load_robot_params
from quadruped_control.ros.visualization import (Throttle, VisualizationError, foot_target_spheres,
                                             imu_orientation, unit_quaternion, visual_joint_state)
from underwater_quadruped.msg import ControllerState

#: Foot-target markers disappear this long after the controller stops publishing, s.
MARKER_LIFETIME = 1.0


def _publish(publisher: rospy.Publisher, msg) -> None:
    """Publish, except while shutting down (callbacks still running when the publishers close)."""
    try:
        publisher.publish(msg)
    except rospy.ROSException:
        if not rospy.core.is_shutdown_requested():
            raise


class VisualizationNode:
    def __init__(self) -> None:
        self.world_frame = rospy.get_param("~world_frame", "odom")
        self.base_frame = rospy.get_param("~base_frame", "base_link")
        self.imu_frame = rospy.get_param("~imu_frame", "imu_link")
        self.setpoint_frame = rospy.get_param("~setpoint_frame", "setpoint")
        position = rospy.get_param("~base_position", [0.0, 0.0, 0.0])
        if len(position) != 3:
            raise ValueError("~base_position must be [x, y, z], got %r" % (position,))
        self.base_position = [float(v) for v in position]
        self.params = load_robot_params(rospy.get_param("~robot_yaml", config_path("robot.yaml")))
        marker_rate = float(rospy.get_param("~marker_rate", 20.0))
        if marker_rate <= 0.0:
            raise ValueError("~marker_rate must be positive, got %r" % marker_rate)
        self.marker_throttle = Throttle(1.0 / marker_rate)
        # rviz draws at ~30 fps: forwarding the 100-200 Hz inputs would only load the robot's CPU
        # (and robot_state_publisher, which recomputes every link per joint state).
        draw_rate = float(rospy.get_param("~draw_rate", 30.0))
        if draw_rate <= 0.0:
            raise ValueError("~draw_rate must be positive, got %r" % draw_rate)
        self.joint_throttle = Throttle(1.0 / draw_rate)
        self.body_throttle = Throttle(1.0 / draw_rate)
        self.setpoint_throttle = Throttle(1.0 / draw_rate)

        self.rates = {topic: RateMonitor(2.0) for topic in ("joint_states", "imu/data", "controller_state")}
        self.dropped = 0
        self.diagnostics = Updater()
        self.diagnostics.setHardwareID("none")
        self.diagnostics.add("inputs", self.diagnose)
        self.diagnostics_timer = rospy.Timer(rospy.Duration(1.0), lambda _event: self.diagnostics.update())
        self.tf_broadcaster = tf2_ros.TransformBroadcaster()
        self.joint_pub = rospy.Publisher("joint_states_visual", JointState, queue_size=10)
        self.marker_pub = rospy.Publisher("foot_target_markers", MarkerArray, queue_size=2)
        rospy.Subscriber("joint_states", JointState, self.on_joint_states, queue_size=10)
        rospy.Subscriber("imu/data", Imu, self.on_imu, queue_size=10)
        rospy.Subscriber("controller_state", ControllerState, self.on_controller_state, queue_size=10)

    def diagnose(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        now = time.monotonic()
        rates = {topic: monitor.rate(now) for topic, monitor in self.rates.items()}
        silent = [topic for topic, rate in rates.items() if rate == 0.0]
        if silent:
            stat.summary(DiagnosticStatus.WARN, "nothing to draw from: %s" % ", ".join(silent))
        else:
            stat.summary(DiagnosticStatus.OK, "drawing")
        for topic, rate in rates.items():
            stat.add("%s rate [Hz]" % topic, "%.1f" % rate)
        stat.add("messages not drawn", str(self.dropped))
        return stat

    def on_joint_states(self, msg: JointState) -> None:
        self.rates["joint_states"].tick(time.monotonic())
        if not self.joint_throttle.ready(rospy.get_time()):
            return
        try:
            names, positions = visual_joint_state(msg.name, msg.position, self.params)
        except VisualizationError as exc:
            rospy.logwarn_throttle(5.0, "not drawing joint state: %s" % exc)
            self.dropped += 1
            return
        out = JointState()
        out.header = msg.header
        if out.header.stamp.is_zero():  # unstamped (e.g. rostopic pub): robot_state_publisher needs a time
            out.header.stamp = rospy.Time.now()
        out.name = names
        out.position = positions
        _publish(self.joint_pub, out)

    def on_imu(self, msg: Imu) -> None:
        self.rates["imu/data"].tick(time.monotonic())
        if not self.body_throttle.ready(rospy.get_time()):
            return
        q = msg.orientation
        try:
            orientation = imu_orientation((q.x, q.y, q.z, q.w), msg.orientation_covariance)
        except VisualizationError as exc:
            rospy.logwarn_throttle(5.0, "ignoring IMU orientation: %s" % exc)
            self.dropped += 1
            return
        if orientation is None:
            rospy.logwarn_throttle(30.0, "IMU message carries no orientation (covariance[0] = -1)")
            return
        if msg.header.frame_id and msg.header.frame_id.lstrip("/") not in (self.base_frame, self.imu_frame):
            rospy.logwarn_once("IMU frame '%s' is neither '%s' nor '%s' (URDF): drawn as '%s'"
                               % (msg.header.frame_id, self.imu_frame, self.base_frame, self.base_frame))
        stamp = msg.header.stamp if not msg.header.stamp.is_zero() else rospy.Time.now()
        self.broadcast(stamp, self.base_frame, orientation)

    def on_controller_state(self, msg: ControllerState) -> None:
        self.rates["controller_state"].tick(time.monotonic())
        stamp = msg.header.stamp if not msg.header.stamp.is_zero() else rospy.Time.now()
        q = msg.setpoint
        if self.setpoint_throttle.ready(rospy.get_time()):
            try:
                self.broadcast(stamp, self.setpoint_frame, unit_quaternion((q.x, q.y, q.z, q.w)))
            except VisualizationError as exc:
                rospy.logwarn_throttle(5.0, "ignoring setpoint: %s" % exc)
        if self.marker_throttle.ready(rospy.get_time()):
            points = [(p.x, p.y, p.z) for p in msg.foot_targets]
            try:
                spheres = foot_target_spheres(points, self.params.paw_diameter)
            except VisualizationError as exc:
                rospy.logwarn_throttle(5.0, "not drawing foot targets: %s" % exc)
                return
            _publish(self.marker_pub, self.markers(stamp, spheres))

    def broadcast(self, stamp: rospy.Time, child: str, xyzw: Sequence[float]) -> None:
        t = TransformStamped()
        t.header.stamp = stamp
        t.header.frame_id = self.world_frame
        t.child_frame_id = child
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = self.base_position
        r = t.transform.rotation
        r.x, r.y, r.z, r.w = (float(v) for v in xyzw)
        self.tf_broadcaster.sendTransform(t)

    def markers(self, stamp: rospy.Time, spheres) -> MarkerArray:
        array = MarkerArray()
        for sphere in spheres:
            m = Marker()
            m.header.stamp = stamp
            m.header.frame_id = self.base_frame
            m.ns = "foot_targets"
            m.id = sphere.leg
            m.type = Marker.SPHERE
            m.action = Marker.ADD
            m.pose.position.x, m.pose.position.y, m.pose.position.z = sphere.position
            m.pose.orientation.w = 1.0
            m.scale.x = m.scale.y = m.scale.z = sphere.diameter
            m.color.r, m.color.g, m.color.b, m.color.a = sphere.rgba
            m.lifetime = rospy.Duration(MARKER_LIFETIME)
            array.markers.append(m)
        return array


def main(argv=None) -> None:
    start_node("visualization", VisualizationNode)
    rospy.spin()


if __name__ == "__main__":
    main()
