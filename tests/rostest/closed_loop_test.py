#!/usr/bin/env python3
"""rostest: the simulated closed loop reaches and holds a 30 degree roll setpoint from a yaw offset.

Listens to /controller_state (geodesic error of every control step) and /sim/servo_output (the pulse
widths the fake PCA9685 really produces). Passes when the geodesic error, smoothed with the paper's
centred 3 s moving average, enters the 6 degree band and stays in it for ~hold_duration seconds before
~settle_timeout; and no pulse width ever left its channel's limits; with ~expected_scheme, that the
controller runs that stroke scheme (sim_coordinated.test); with ~expected_plant and ~expected_tank_yaml,
that sim_node runs that plant and tank (sim_tank.test); with ~expected_heading_deg (the relative yaw reference,
sim_closed_loop.test), that the world setpoint's yaw is that heading at arming and the body's true heading never
leaves it by more than 5 degrees.

With ~trajectory_file set, the simulated trajectory (/sim/pose stamps and quaternions) up to the
sensor-stall part is saved there (numpy .npz) for scripts/check_lockstep_determinism.sh.
"""
import math
import sys
import threading
import unittest

import numpy as np
import rospy
import rostest
from std_srvs.srv import SetBool

from quadruped_common.so3 import quat_to_rot, rot_to_rpy
from quadruped_control.analysis.metrics import moving_average_centered
from quadruped_drivers.hardware_config import load_hardware_config
from geometry_msgs.msg import PoseStamped
from underwater_quadruped.msg import ControllerState, ServoCommand

BAND = math.radians(6.0)


class ClosedLoopTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("closed_loop_test", anonymous=True)
        self.lock = threading.Lock()
        self.times, self.errors = [], []
        self.armed_seen = False
        self.armed_at, self.setpoint_yaw = None, None
        self.width_violations = []
        self.pose_t, self.pose_q = [], []
        self.recording = True
        hardware = load_hardware_config(rospy.get_param("~hardware_yaml"))
        self.low, self.high = hardware.min_us, hardware.max_us
        rospy.Subscriber("controller_state", ControllerState, self.on_state, queue_size=100)
        rospy.Subscriber("sim/servo_output", ServoCommand, self.on_output, queue_size=100)
        rospy.Subscriber("sim/pose", PoseStamped, self.on_pose, queue_size=1000)

    def on_pose(self, msg):
        with self.lock:
            if self.recording:
                o = msg.pose.orientation
                self.pose_t.append(msg.header.stamp.to_nsec())
                self.pose_q.append((o.x, o.y, o.z, o.w))

    def save_trajectory(self):
        with self.lock:
            self.recording = False
            path = rospy.get_param("~trajectory_file", "")
            if path:
                np.savez(path, stamp_ns=np.array(self.pose_t, dtype=np.int64), quaternion=np.array(self.pose_q))

    def on_state(self, msg):
        with self.lock:
            self.armed_seen |= msg.armed
            stamp = msg.header.stamp.to_sec()
            if msg.armed:
                s = msg.setpoint
                self.setpoint_yaw = math.degrees(rot_to_rpy(quat_to_rot((s.x, s.y, s.z, s.w)))[2])
                self.armed_at = stamp if self.armed_at is None else self.armed_at
            if msg.armed and not msg.holding and (not self.times or stamp > self.times[-1]):
                self.times.append(stamp)
                self.errors.append(msg.geodesic_error)

    def on_output(self, msg):
        widths = np.array(msg.pulse_width_us)
        on = widths > 0  # 0 = channel off (failsafe before arming), always within limits
        bad = on & ((widths < self.low - 1.0) | (widths > self.high + 1.0))
        if np.any(bad):
            self.width_violations.append(widths.tolist())

    def settled_for(self):
        """Seconds for which the smoothed error has been inside the band up to the newest complete
        point of the centred window, and the smoothed error series."""
        with self.lock:
            t, e = np.array(self.times), np.array(self.errors)
        if len(t) < 400:
            return 0.0, None
        smooth = moving_average_centered(e, t, 3.0)
        complete = t <= t[-1] - 1.5  # the centred window needs 1.5 s of future samples
        t, smooth = t[complete], smooth[complete]
        if len(t) == 0:
            return 0.0, None
        outside = np.nonzero(smooth > BAND)[0]
        if len(outside) == 0:
            start = t[0]
        elif outside[-1] == len(t) - 1:
            return 0.0, smooth
        else:
            start = t[outside[-1] + 1]
        return t[-1] - start, smooth

    def test_reaches_and_holds_roll_setpoint(self):
        timeout = rospy.get_param("~settle_timeout", 240.0)
        hold = rospy.get_param("~hold_duration", 15.0)
        deadline = rospy.get_time() + timeout
        held, smooth = 0.0, None
        while not rospy.is_shutdown() and rospy.get_time() < deadline:
            rospy.sleep(1.0)
            held, smooth = self.settled_for()
            if held >= hold:
                break
        self.assertTrue(self.armed_seen, "the controller never reported armed")
        last = "n/a" if smooth is None else "%.1f" % math.degrees(smooth[-1])
        self.assertGreaterEqual(held, hold, "smoothed geodesic error within 6 deg for only %.1f s "
                                "(last smoothed error %s deg)" % (held, last))
        self.assertEqual(self.width_violations, [], "pulse widths outside the channel limits")
        scheme = rospy.get_param("~expected_scheme", "")
        if scheme:
            self.assertEqual(rospy.get_param("attitude_controller/stroke_scheme"), scheme)
        for name in ("plant", "tank_yaml"):  # the simulated robot is the one the launch asked for
            expected = rospy.get_param("~expected_" + name, "")
            if expected:
                self.assertEqual(rospy.get_param("sim_node/" + name), expected)
        self.save_trajectory()
        heading = rospy.get_param("~expected_heading_deg", None)
        if heading is not None:  # the relative yaw reference: a roll step where the robot faced at arming
            self.assertAlmostEqual(self.setpoint_yaw, heading, delta=2.0)
            with self.lock:
                armed = np.array(self.pose_t) >= self.armed_at * 1e9
                yaw = np.array([math.degrees(rot_to_rpy(quat_to_rot(q))[2]) for q in np.array(self.pose_q)[armed]])
            self.assertGreater(len(yaw), 1000)
            self.assertLess(np.max(np.abs(yaw - self.setpoint_yaw)), 5.0, "the heading left the one at arming")

        # The sensor stalls (fake VN-100 silent behind its pty): the controller must hold the safe pose
        # with a stale-IMU reason within ~imu_max_age, and stroke again when the samples return.
        rospy.wait_for_service("sim_node/imu_streaming", timeout=10.0)
        streaming = rospy.ServiceProxy("sim_node/imu_streaming", SetBool)
        self.assertTrue(streaming(False).success)
        msg = rospy.wait_for_message("controller_state", ControllerState, timeout=5.0)
        deadline = rospy.get_time() + 2.0
        while not (msg.holding and "stale" in msg.hold_reason) and rospy.get_time() < deadline:
            msg = rospy.wait_for_message("controller_state", ControllerState, timeout=5.0)
        self.assertTrue(msg.holding and "stale" in msg.hold_reason,
                        "no stale-IMU hold after the sensor went silent: %r" % msg.hold_reason)
        self.assertTrue(streaming(True).success)
        deadline = rospy.get_time() + 5.0
        while msg.holding and rospy.get_time() < deadline:
            msg = rospy.wait_for_message("controller_state", ControllerState, timeout=5.0)
        self.assertFalse(msg.holding, "controller did not resume after the IMU returned")


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "closed_loop", ClosedLoopTest, sys.argv)
