#!/usr/bin/env python3
"""rostest: depth and battery topics on the simulated robot, their health going ERROR, and what the controller does
(safety_sensors.test: sim.launch, armed at start once its checks pass, health/depth and health/battery watched).

1. every topic arrives at its rate over a 5 s window (depth/* 10 Hz, battery/<pack> 2 Hz, health/* 2 Hz), with
   plausible contents (the fake sensor 0.5 m under water at 20 degC; depth/pose z = -depth in odom);
2. ``/sim_node/depth_sensor_fault true``: health/depth ERROR within depth.timeout_s (+ one poll and margin) and no
   depth reading published meanwhile, and the controller stays armed (a lost sensor is no hazard); ``false``: OK
   again;
3. the small packs run flat: health/battery goes from OK to ERROR, the pack named critical, its BatteryState
   below the critical cell voltage; the controller disarmed within 0.2 s of the ERROR (health.battery_action
   disarm) and arming refused with the battery named.
The measured figures are printed (rostest keeps them in the test's output).
"""
import math
import sys
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from sensor_msgs.msg import BatteryState, FluidPressure, Temperature
from std_srvs.srv import SetBool

from quadruped_drivers.hardware_config import load_hardware_config, with_batteries_fitted
from underwater_quadruped.msg import ControllerState

TOPICS = {"depth/pressure": FluidPressure, "depth/temperature": Temperature, "depth/pose": PoseWithCovarianceStamped,
          "battery/motors": BatteryState, "battery/electronics": BatteryState, "health/depth": DiagnosticStatus,
          "health/battery": DiagnosticStatus}
#: topic -> (lowest, highest) rate in Hz; health/* publish at 2 Hz and at once on a change
RATES = {"depth/pressure": (8.5, 11.5), "depth/temperature": (8.5, 11.5), "depth/pose": (8.5, 11.5),
         "battery/motors": (1.6, 2.4), "battery/electronics": (1.6, 2.4), "health/depth": (1.8, 4.0),
         "health/battery": (1.8, 4.0)}
WINDOW = 5.0


class SafetySensorsTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("safety_sensors_test", anonymous=True)
        self.hardware = with_batteries_fitted(load_hardware_config(rospy.get_param("~hardware_yaml")))  # as the nodes
        self.lock = threading.Lock()
        self.messages = {topic: [] for topic in TOPICS}
        for topic, kind in TOPICS.items():
            rospy.Subscriber(topic, kind, self.on_message, callback_args=topic, queue_size=50)
        self.truth = []  # (stamp, true world z) from sim/pose
        rospy.Subscriber("sim/pose", PoseStamped, self.on_truth, queue_size=200)
        self.armed = []  # (arrival time, armed) from controller_state
        rospy.Subscriber("controller_state", ControllerState, self.on_state, queue_size=100)

    def on_state(self, msg):
        with self.lock:
            self.armed.append((time.monotonic(), msg.armed))

    def armed_between(self, start, end):
        with self.lock:
            return [armed for t, armed in self.armed if start <= t <= end]
    def on_truth(self, msg):
        with self.lock:
            self.truth.append((msg.header.stamp.to_sec(), msg.pose.position.z))

    def true_depth(self, stamp):
        """The simulated body's depth at ``stamp``: the simulated robot's mean depth minus its world z then."""
        with self.lock:
            z = min(self.truth, key=lambda sample: abs(sample[0] - stamp))[1]
        return max(0.0, 0.5 - z)

    def on_message(self, msg, topic):
        with self.lock:
            self.messages[topic].append((time.monotonic(), msg))

    def since(self, topic, start):
        with self.lock:
            return [msg for t, msg in self.messages[topic] if t >= start]

    def rate(self, topic, start):
        """Messages per second of ``topic`` since ``start``: (n - 1) over the time from the first to the last."""
        with self.lock:
            times = [t for t, _ in self.messages[topic] if t >= start]
        return (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0

    def wait_for(self, predicate, timeout, what):
        deadline = time.monotonic() + timeout
        while not rospy.is_shutdown() and time.monotonic() < deadline:
            found = predicate()
            if found:
                return found
            time.sleep(0.01)
        self.fail("no %s within %.0f s" % (what, timeout))

    def first_health(self, topic, level, start):
        """(arrival time, message) of the first ``topic`` status at ``level`` since ``start``, or None."""
        with self.lock:
            return next(((t, msg) for t, msg in self.messages[topic] if t >= start and msg.level == level), None)

    def test_depth_and_battery_on_the_simulated_robot(self):
        depth = self.hardware.depth
        self.wait_for(lambda: any(self.since(topic, 0.0) for topic in TOPICS), 40.0, "a first message")
        with self.lock:
            begin = min(times[0][0] for times in self.messages.values() if times)
        self.wait_for(lambda: all(self.since(topic, 0.0) for topic in TOPICS), 40.0, "message on every topic")
        battery_ok, _ = self.wait_for(lambda: self.first_health("health/battery", DiagnosticStatus.OK, 0.0), 2.0,
                                      "health/battery OK at start (both packs read)")
        self.wait_for(lambda: any(armed for _, armed in list(self.armed)), 20.0, "the controller armed (arm:=true)")

        # 1. rates and contents
        start = time.monotonic()
        time.sleep(WINDOW)
        print("\nrates over %.0f s (wall clock, real-time simulated robot):" % WINDOW)
        for topic, (low, high) in RATES.items():
            rate = self.rate(topic, start)
            print("  %-22s %5.2f Hz" % (topic, rate))
            self.assertTrue(low <= rate <= high, "%s at %.2f Hz, expected %g..%g" % (topic, rate, low, high))
        for msg in self.since("depth/pressure", start):  # the fake follows the body (updated every 50 ms)
            expected = depth.surface_pa + depth.fluid_density * 9.80665 * self.true_depth(msg.header.stamp.to_sec())
            self.assertLess(abs(msg.fluid_pressure - expected), 50.0, "depth/pressure off the simulated depth")
        self.assertTrue(all(abs(m.temperature - 20.0) < 0.1 for m in self.since("depth/temperature", start)))
        poses = self.since("depth/pose", start)
        errors = [p.pose.pose.position.z + self.true_depth(p.header.stamp.to_sec()) for p in poses]
        print("depth/pose z - (-true depth): max %.4f m over %d readings; true depth %.3f m at the end"
              % (max(abs(e) for e in errors), len(errors), self.true_depth(poses[-1].header.stamp.to_sec())))
        self.assertTrue(all(p.header.frame_id == "odom" for p in poses))
        self.assertLess(max(abs(e) for e in errors), 0.005)
        covariance = poses[-1].pose.covariance
        self.assertLess(covariance[14], 1e-4)
        self.assertEqual([covariance[7 * i] for i in (0, 1, 3, 4, 5)], [1e6] * 5)
        self.assertTrue(all(m.level == DiagnosticStatus.OK for m in self.since("health/depth", start)))
        for pack in self.hardware.batteries.fitted:
            state = self.since("battery/" + pack.name, start)[-1]
            self.assertTrue(state.present and len(state.cell_voltage) == pack.cells and 0.0 <= state.percentage <= 1.0)
            self.assertEqual(state.power_supply_technology, BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO)
            self.assertTrue(2.8 * pack.cells < state.voltage < 4.3 * pack.cells, state.voltage)

        # 2. the depth sensor stops answering, then comes back
        fault = rospy.ServiceProxy("/sim_node/depth_sensor_fault", SetBool)
        fault.wait_for_service(10.0)
        lost = time.monotonic()
        self.assertTrue(fault(True).success)
        error_at, error = self.wait_for(lambda: self.first_health("health/depth", DiagnosticStatus.ERROR, lost),
                                        10.0, "health/depth ERROR after the fake stopped answering")
        published = self.since("depth/pressure", lost + 0.15)  # a reading under way may still come out
        print("depth sensor lost: health/depth ERROR %.3f s later (depth.timeout_s %.1f): %s"
              % (error_at - lost, depth.timeout_s, error.message))
        self.assertLessEqual(error_at - lost, depth.timeout_s + 0.3)
        self.assertGreater(error_at - lost, depth.timeout_s - 0.15)
        self.assertEqual(published, [], "depth readings published while the sensor did not answer")
        time.sleep(0.5)
        after = self.armed_between(error_at, time.monotonic())
        self.assertTrue(after and all(after), "the controller disarmed on the depth sensor's loss (no hazard)")
        back = time.monotonic()
        self.assertTrue(fault(False).success)
        ok_at, _ = self.wait_for(lambda: self.first_health("health/depth", DiagnosticStatus.OK, back), 10.0,
                                 "health/depth OK after the fake answers again")
        print("depth sensor back: health/depth OK %.3f s later" % (ok_at - back))

        # 3. the packs run flat
        error_at, error = self.wait_for(
            lambda: self.first_health("health/battery", DiagnosticStatus.ERROR, battery_ok), 40.0,
            "health/battery ERROR as the packs drain")
        warn = self.first_health("health/battery", DiagnosticStatus.WARN, battery_ok)
        print("packs draining (start charge 0.2, 0.03 Ah, stroking): health/battery OK at %.2f s, WARN at %s s, "
              "ERROR at %.2f s after the first message: %s" % (battery_ok - begin, "%.2f" % (warn[0] - begin)
                                                                 if warn else "-", error_at - begin, error.message))
        reason = dict((kv.key, kv.value) for kv in error.values)["reason"]  # e.g. "electronics:critical"
        critical = [part.split(":")[0] for part in reason.split(",") if part.endswith(":critical")]
        self.assertTrue(critical, "health/battery ERROR for another reason: %s" % reason)
        name = critical[0]
        pack = next(p for p in self.hardware.batteries.fitted if p.name == name)
        self.wait_for(lambda: [m for m in self.since("battery/" + name, error_at - 0.6)
                               if m.power_supply_health == BatteryState.POWER_SUPPLY_HEALTH_DEAD], 2.0,
                      "battery/%s with health DEAD" % name)
        state = self.since("battery/" + name, 0.0)[-1]
        self.assertLess(state.voltage / pack.cells, pack.critical_cell_v + pack.hysteresis_v)
        self.assertFalse(math.isnan(state.percentage))
        disarmed = self.wait_for(lambda: next((t for t, armed in list(self.armed) if t >= error_at and not armed),
                                              None), 2.0, "the controller disarmed after health/battery ERROR")
        print("battery critical: the controller disarmed %.3f s after health/battery ERROR reached the test"
              % (disarmed - error_at))
        self.assertLess(disarmed - error_at, 0.2)
        refused = rospy.ServiceProxy("attitude_controller/arm", SetBool)(True)
        self.assertFalse(refused.success)
        self.assertIn("battery: ", refused.message)


if __name__ == "__main__":
    rostest.rosrun("underwater_quadruped", "safety_sensors", SafetySensorsTest, sys.argv)
