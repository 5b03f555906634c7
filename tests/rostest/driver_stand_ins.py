"""For rostests that run the controller without the drivers: what its arming checks need from them.

:class:`DriverStandIns` publishes, from a thread, what servo_feedback_node, pwm_node and ms5837_node would:
joint_states with the legs at the nominal pose (50 Hz), an OK outputs_state (5 Hz) and an OK health/depth (5 Hz:
config/hardware.yaml fits the depth sensor, so the controller watches it).
"""
import threading

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from quadruped_common.robot import JOINT_NAMES
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.simulation import nominal_joint_angles


class DriverStandIns:
    """Start with :meth:`start`, end with :meth:`stop`."""

    def __init__(self):
        self.joint_pub = rospy.Publisher("joint_states", JointState, queue_size=10)
        self.outputs_pub = rospy.Publisher("outputs_state", DiagnosticStatus, queue_size=1)
        self.depth_pub = rospy.Publisher("health/depth", DiagnosticStatus, queue_size=1)
        self.nominal = nominal_joint_angles(load_robot_params()).reshape(12).tolist()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self):
        self._thread.start()

    def stop(self):
        self._stop.set()

    def _run(self):
        rate = rospy.Rate(50)
        k = 0
        while not self._stop.is_set() and not rospy.is_shutdown():
            joints = JointState(name=list(JOINT_NAMES), position=self.nominal, velocity=[0.0] * 12)
            joints.header.stamp = rospy.Time.now()
            self.joint_pub.publish(joints)
            if k % 10 == 0:
                self.outputs_pub.publish(DiagnosticStatus(level=DiagnosticStatus.OK, name="test: outputs",
                                                          message="test stand-in: ready"))
                self.depth_pub.publish(DiagnosticStatus(level=DiagnosticStatus.OK, name="test: depth",
                                                        message="test stand-in: fresh"))
            k += 1
            try:
                rate.sleep()
            except rospy.ROSInterruptException:
                return
