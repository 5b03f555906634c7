"""Fault campaign: the whole robot failing while it moves, on the simulated robot through ``sim.launch``.

Runs the stack as the robot runs it (``sim.launch`` in real time, control path at its SCHED_FIFO
priority where permitted, recording on), keeps it in closed-loop manoeuvres with a *tether* process (the
operator's laptop: it publishes a new setpoint every few seconds and subscribes to the telemetry, as
rqt and rviz would), and injects faults at seeded random moments:

============================  =====================================================================  ======
kind                          injection                                                             expect
============================  =====================================================================  ======
kill_vn100_node               SIGKILL, its supervisor starts it again                                safe
kill_servo_feedback_node      SIGKILL, respawned (the controller does not steer on joint feedback)  track
kill_pwm_node                 SIGKILL, respawned                                                     safe
kill_attitude_controller      SIGKILL, respawned disarmed; the operator's arm command after 1 s      safe
kill_recorder                 SIGKILL of rosbag record; its wrapper records again into a new bag    track
imu_link_0.1 / _1 / _10       the VN-100's serial link silent for 0.1, 1, 10 s (``~imu_streaming``)  safe
i2c_stuck_0.1 / _2            every I2C transaction times out for 0.1, 2 s (``~i2c_bus_stuck``)      safe
pca9685_power                 the PCA9685 unpowered for 1 s and back (``~pca9685_power``)            safe
cpu_hogs                      two busy processes at the control path's priority for 10 s             safe
kill_rosmaster                SIGKILL of the master, a new one 2 s later with the old parameters     track
setpoint_gone                 SIGKILL of the tether (its connections close); a new one 2 s later     track
tether_gone                   SIGSTOP of the tether for 5 s (a cut cable: TCP stalls), then SIGCONT  track
heartbeat_lost                SIGSTOP of the heartbeat for 3 s: disarmed at its 2 s timeout; re-armed  stop
estop                         the e-stop (``estop`` service) mid-stroke; reset, enabled and re-armed   stop
estop_controller_dead         SIGKILL of the controller, the e-stop 50 ms later; reset after respawn  stop
battery_critical              both packs flat (``~battery_flat``), fresh again after 1 s; re-armed    stop
leak                          water on the leak probe (``~water_inside``) for 1 s; ``~reset``, re-armed  stop
depth_lost                    the MS5837 off the bus for 2 s (``~depth_sensor_fault``)               track
============================  =====================================================================  ======

*safe*: the robot must reach a safe state (chip holding or limp, or the controller holding) within the PWM
watchdog timeout plus one period, stay safe until the fault ends and track again within 5 s of its end;
*track*: the control path is not touched and must keep tracking; *stop*: a safe state within the same limit of the
moment the stack must act (the heartbeat's timeout, the e-stop, health/battery or health/leak ERROR reaching the
campaign), every arm refused (naming the cause) until the operator clears it, no leg motion until the operator's
arm, which ends the fault. The laptop's heartbeat (``heartbeat_node``, 2 s timeout, disarm) runs at the simulated
robot's priority: it stands for another machine, which the robot's CPU load does not starve. Every kind: no pulse outside its
limits, no leg motion while unarmed. Definitions and figures: :mod:`quadruped_control.analysis.fault_metrics`.

A master killed takes the parameter server and every registration with it; nodes keep their
connections, but a node started later cannot find the old ones (ROS 1 has no re-registration), so each
master kill ends its graph: the campaign starts a fresh graph for each one, after the other kinds.

Entry points: :func:`run_campaign` (``benchmarks/fault_campaign.py``, the fault rostest) and ``python -m
quadruped_control.ros.fault_campaign tether`` (the tether process).
"""
from __future__ import annotations

import argparse
import glob
import json
import math
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
import xmlrpc.client
from dataclasses import asdict
from typing import Dict, List, Optional, Sequence

import numpy as np

from quadruped_control.analysis.fault_metrics import (FaultRecord, InjectionResult, Timeline, judge_injection,
                                                      kind_summary, lost_messages, stamp_keys, tracking_rows)

#: kind -> (expectation, fault duration in s (None: ends when the stack says so))
KINDS: Dict[str, tuple] = {
    "kill_vn100_node": ("safe", None),
    "kill_servo_feedback_node": ("track", None),
    "kill_pwm_node": ("safe", None),
    "kill_attitude_controller": ("safe", None),
    "kill_recorder": ("track", None),
    "imu_link_0.1": ("safe", 0.1),
    "imu_link_1": ("safe", 1.0),
    "imu_link_10": ("safe", 10.0),
    "i2c_stuck_0.1": ("safe", 0.1),
    "i2c_stuck_2": ("safe", 2.0),
    "pca9685_power": ("safe", 1.0),
    "cpu_hogs": ("safe", 10.0),
    "setpoint_gone": ("track", 2.0),
    "tether_gone": ("track", 5.0),
    "kill_rosmaster": ("track", 2.0),
    "heartbeat_lost": ("stop", 3.0),
    "estop": ("stop", 1.0),
    "estop_controller_dead": ("stop", None),
    "battery_critical": ("stop", 1.0),
    "leak": ("stop", 1.0),
    "depth_lost": ("track", 2.0),
}
#: s: the heartbeat timeout the campaign's graph runs with (sim.launch heartbeat_timeout)
HEARTBEAT_TIMEOUT = 2.0
#: Setpoints (roll, pitch, yaw deg) the tether cycles through: always mid-manoeuvre.
MANOEUVRES = ((30.0, 0.0, 0.0), (-30.0, 0.0, 0.0), (0.0, 20.0, 0.0), (20.0, -20.0, 0.0), (0.0, 0.0, 40.0),
              (-20.0, 15.0, -30.0))
RECOVERY_LIMIT = 5.0
NODE_NAMES = {"kill_vn100_node": "/vn100_node", "kill_servo_feedback_node": "/servo_feedback_node",
              "kill_pwm_node": "/pwm_node", "kill_attitude_controller": "/attitude_controller",
              "kill_recorder": "/recorder"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def control_priority_prefix() -> List[str]:
    """The launch prefix of the control path: SCHED_FIFO 20 where permitted (as scripts/sim_maneuver.sh)."""
    ok = subprocess.run(["chrt", "-f", "20", "true"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return ["chrt", "-f", "20"] if ok.returncode == 0 else []


def sim_priority_prefix() -> List[str]:
    ok = subprocess.run(["chrt", "-f", "30", "true"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return ["chrt", "-f", "30"] if ok.returncode == 0 else []


# --------------------------------------------------------------------------------------------------
# The graph under test
# --------------------------------------------------------------------------------------------------

class Graph:
    """A master of its own, ``sim.launch`` against it (recording into ``out/bags``), and the tether."""

    def __init__(self, out: str, port: int, seed: int, tether_period: float = 6.0) -> None:
        self.out = os.path.abspath(out)  # roslaunch runs in ROS_HOME: a relative bag_dir would land there
        self.port = port
        self.uri = "http://localhost:%d" % port
        self.seed = seed
        self.tether_period = tether_period
        self.env = dict(os.environ, ROS_MASTER_URI=self.uri, ROS_HOME=os.path.join(out, "ros_home"))
        os.makedirs(self.env["ROS_HOME"], exist_ok=True)
        self.bag_dir = os.path.join(out, "bags")
        os.makedirs(self.bag_dir, exist_ok=True)
        self.master: Optional[subprocess.Popen] = None
        self.launch: Optional[subprocess.Popen] = None
        self.tether: Optional[subprocess.Popen] = None
        self.heartbeat: Optional[subprocess.Popen] = None
        self.params_dump = os.path.join(out, "params.yaml")
        self.launch_log = open(os.path.join(out, "launch.log"), "ab")

    def _popen(self, args: Sequence[str], log=None) -> subprocess.Popen:
        return subprocess.Popen(list(args), env=self.env, stdout=log or subprocess.DEVNULL,
                                stderr=subprocess.STDOUT if log else subprocess.DEVNULL, start_new_session=True)

    def start_master(self) -> None:
        self.master = self._popen(["rosmaster", "--core", "-p", str(self.port)], self.launch_log)
        deadline = time.monotonic() + 30.0
        proxy = xmlrpc.client.ServerProxy(self.uri)
        while time.monotonic() < deadline:
            try:
                proxy.getPid("/fault_campaign")
                return
            except OSError:
                time.sleep(0.1)
        raise RuntimeError("rosmaster on port %d did not come up" % self.port)

    def start(self) -> None:
        self.start_master()
        control = " ".join(control_priority_prefix())
        self.launch = self._popen(
            ["roslaunch", "underwater_quadruped", "sim.launch", "arm:=true", "record:=true",
             "bag_dir:=%s" % self.bag_dir, "description:=false", "launch_prefix:=%s" % control,
             "sim_launch_prefix:=%s" % " ".join(sim_priority_prefix()), "sim_id:=faults%d" % self.port,
             "heartbeat_timeout:=%g" % HEARTBEAT_TIMEOUT], self.launch_log)
        self.heartbeat = self._popen(sim_priority_prefix() + ["rosrun", "underwater_quadruped", "heartbeat_node",
                                                              "__name:=heartbeat"], self.launch_log)
        self.start_tether()

    def start_tether(self) -> None:
        self.tether = self._popen([sys.executable, "-m", "quadruped_control.ros.fault_campaign", "tether",
                                   "--seed", str(self.seed), "--period", str(self.tether_period)],
                                  self.launch_log)

    def dump_params(self) -> None:
        subprocess.run(["rosparam", "dump", self.params_dump, "/"], env=self.env, check=True, timeout=30)

    def kill_master(self) -> None:
        assert self.master is not None
        os.killpg(self.master.pid, signal.SIGKILL)
        self.master.wait()

    def restart_master(self) -> None:
        self.start_master()
        subprocess.run(["rosparam", "load", self.params_dump, "/"], env=self.env, check=True, timeout=30)

    def stop(self) -> None:
        for process, sig, wait in ((self.tether, signal.SIGKILL, 5.0), (self.heartbeat, signal.SIGKILL, 5.0),
                                   (self.launch, signal.SIGINT, 60.0),
                                   (self.master, signal.SIGINT, 10.0)):
            if process is None or process.poll() is not None:
                continue
            try:
                os.killpg(process.pid, sig)
                process.wait(timeout=wait)
            except (subprocess.TimeoutExpired, ProcessLookupError):
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                process.wait()
        self.launch_log.close()


# --------------------------------------------------------------------------------------------------
# What the campaign watches
# --------------------------------------------------------------------------------------------------

class Monitor:
    """Records the chip's widths (sim/servo_output), the commands (servo_command), the controller's
    telemetry (controller_state) and the IMU stamps, on the stamps of the messages (wall time: real-time
    simulation)."""

    def __init__(self) -> None:
        import rospy
        from sensor_msgs.msg import Imu

        from underwater_quadruped.msg import ControllerState, ServoCommand

        self.lock = threading.Lock()
        self.chip: List[tuple] = []
        self.commands: List[tuple] = []
        self.states: List[tuple] = []
        self.imu_stamps: List[float] = []
        self.state_stamps: List[float] = []
        self.names: List[str] = []
        kwargs = dict(queue_size=2000, tcp_nodelay=True)
        self.subscribers = [
            rospy.Subscriber("sim/servo_output", ServoCommand, self._on_chip, **kwargs),
            rospy.Subscriber("servo_command", ServoCommand, self._on_command, **kwargs),
            rospy.Subscriber("controller_state", ControllerState, self._on_state, **kwargs),
            rospy.Subscriber("imu/data", Imu, self._on_imu, **kwargs),
        ]

    def _ordered(self, msg) -> List[float]:
        if not self.names:
            self.names = list(msg.name)
        index = {n: i for i, n in enumerate(msg.name)}
        return [msg.pulse_width_us[index[n]] if n in index else math.nan for n in self.names]

    def _on_chip(self, msg) -> None:
        with self.lock:
            self.chip.append((msg.header.stamp.to_sec(), self._ordered(msg)))

    def _on_command(self, msg) -> None:
        with self.lock:
            self.commands.append((msg.header.stamp.to_sec(), self._ordered(msg)))

    def _on_state(self, msg) -> None:
        t = msg.header.stamp.to_sec()
        with self.lock:
            self.states.append((t, bool(msg.armed), bool(msg.holding)))
            self.state_stamps.append(t)

    def _on_imu(self, msg) -> None:
        with self.lock:
            self.imu_stamps.append(msg.header.stamp.to_sec())

    def timeline(self, since: float = -math.inf) -> Timeline:
        """The samples stamped from ``since`` on (all by default), sorted by stamp. Messages arrive in
        stamp order but for a few, so the tail is found from the end of each list."""
        def tail(rows: List[tuple]) -> List[tuple]:
            start = len(rows)
            while start > 0 and rows[start - 1][0] >= since - 1.0:
                start -= 1
            return sorted(row for row in rows[start:] if row[0] >= since)

        with self.lock:
            chip, commands, states = tail(self.chip), tail(self.commands), tail(self.states)
        return Timeline(np.array([c[0] for c in chip]), np.array([c[1] for c in chip]).reshape(-1, 12),
                        np.array([c[0] for c in commands]), np.array([c[1] for c in commands]).reshape(-1, 12),
                        np.array([s[0] for s in states]), np.array([s[1] for s in states], dtype=bool),
                        np.array([s[2] for s in states], dtype=bool))

    def tracking_now(self, hardware, window: float = 0.3) -> bool:
        """The last ``window`` s tracked (controller armed and stroking, chip following its commands)."""
        import rospy
        now = rospy.get_time()
        timeline = self.timeline(since=now - window - 0.2)  # the tail only: this runs every 0.1 s
        recent = timeline.chip_t >= now - window
        if recent.sum() < 5:
            return False
        tick = 1e6 / (hardware.actual_pwm_frequency_hz * 4096.0)
        return bool(tracking_rows(timeline, tick)[recent].mean() > 0.8)


# --------------------------------------------------------------------------------------------------
# Injections
# --------------------------------------------------------------------------------------------------

def _node_pid(name: str) -> Optional[int]:
    import rosgraph
    try:
        uri = rosgraph.Master("/fault_campaign").lookupNode(name)
        code, _message, pid = xmlrpc.client.ServerProxy(uri).getPid("/fault_campaign")
        return int(pid) if code == 1 else None
    except Exception:  # noqa: BLE001 - not registered (yet), or its process is gone
        return None


def _wait(predicate, timeout: float, period: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return False


def _set_bool(service: str, value: bool) -> None:
    import rospy
    from std_srvs.srv import SetBool
    rospy.wait_for_service(service, timeout=10.0)
    response = rospy.ServiceProxy(service, SetBool)(value)
    if not response.success:
        raise RuntimeError("%s(%s) refused: %s" % (service, value, response.message))


#: s: the operator retries an arm command this long once a stop is cleared (outputs_state and health/* come at
#: 5 and 2 Hz: the controller may not have heard the all-clear yet)
ARM_RETRY = 5.0
#: The topics the operator watches: when the stack must act on a stop, and that it is clear again.
WATCHED = ("tether/heartbeat", "health/battery", "health/leak", "health/depth")


class Injector:
    def __init__(self, graph: Graph) -> None:
        import rospy
        from diagnostic_msgs.msg import DiagnosticStatus
        from std_msgs.msg import Header
        self.graph = graph
        self.lock = threading.Lock()
        self.heard: Dict[str, List[tuple]] = {topic: [] for topic in WATCHED}
        for topic in WATCHED:
            rospy.Subscriber(topic, Header if topic == "tether/heartbeat" else DiagnosticStatus, self._on_message,
                             callback_args=topic, queue_size=50, tcp_nodelay=True)

    def _on_message(self, msg, topic: str) -> None:
        import rospy
        with self.lock:
            self.heard[topic] = self.heard[topic][-100:] + [(rospy.get_time(), getattr(msg, "level", 0))]

    def _first(self, topic: str, since: float, level: Optional[int] = None, timeout: float = 5.0) -> float:
        """Arrival time of the first ``topic`` message after ``since`` (at ``level``); RuntimeError after ``timeout``."""
        found: List[float] = []

        def arrived() -> bool:
            with self.lock:
                found[:] = [t for t, lv in self.heard[topic] if t > since and (level is None or lv == level)][:1]
            return bool(found)
        if not _wait(arrived, timeout, 0.01):
            raise RuntimeError("no %s%s within %.0f s" % (topic, "" if level is None else " at level %d" % level,
                                                          timeout))
        return found[0]

    def _arm(self, retry: float = ARM_RETRY) -> float:
        """The operator's arm command, repeated every 0.2 s for ``retry`` s until accepted; the time it was."""
        import rospy
        from std_srvs.srv import SetBool
        rospy.wait_for_service("/attitude_controller/arm", timeout=30.0)
        arm = rospy.ServiceProxy("/attitude_controller/arm", SetBool)
        deadline = time.monotonic() + retry
        while True:
            at = rospy.get_time()
            answer = arm(True)
            if answer.success:
                return at
            if time.monotonic() > deadline:
                raise RuntimeError("arming refused %.0f s after the stop was cleared: %s" % (retry, answer.message))
            time.sleep(0.2)

    def _refused(self, check: str) -> None:
        """An arm command now must be refused, naming ``check``."""
        import rospy
        from std_srvs.srv import SetBool
        answer = rospy.ServiceProxy("/attitude_controller/arm", SetBool)(True)
        if answer.success or check + ": " not in answer.message:
            raise RuntimeError("arm %s during the stop: %s" % ("accepted" if answer.success else
                                                               "refused without naming %s" % check, answer.message))

    def _stop(self, kind: str) -> FaultRecord:
        """The *stop* kinds (module docstring)."""
        import rospy
        from diagnostic_msgs.msg import DiagnosticStatus as Status
        from std_srvs.srv import Trigger
        duration = KINDS[kind][1]
        now = rospy.get_time
        begin = now()
        if kind == "heartbeat_lost":
            heartbeat = self.graph.heartbeat
            assert heartbeat is not None
            os.killpg(heartbeat.pid, signal.SIGSTOP)
            try:
                with self.lock:
                    last = max(t for t, _ in self.heard["tether/heartbeat"])
                start = last + HEARTBEAT_TIMEOUT  # the controller's deadline
                time.sleep(max(0.0, start + 0.3 - now()))
                self._refused("tether")
                time.sleep(max(0.0, begin + duration - now()))
            finally:
                os.killpg(heartbeat.pid, signal.SIGCONT)
            self._first("tether/heartbeat", now(), timeout=5.0)
            time.sleep(0.5)  # the heartbeat is back: nothing may move until the operator arms
            cleared = "heartbeat back"
        elif kind in ("estop", "estop_controller_dead"):
            pid = _node_pid("/attitude_controller")
            if kind == "estop_controller_dead":
                if pid is None:
                    raise RuntimeError("/attitude_controller is not running")
                os.kill(pid, signal.SIGKILL)
                time.sleep(0.05)
            start = now()
            _set_bool("/estop", True)
            try:
                if kind == "estop_controller_dead":
                    if not _wait(lambda: (_node_pid("/attitude_controller") or pid) != pid, 60.0, 0.1):
                        raise RuntimeError("the controller was not respawned within 60 s")
                    rospy.wait_for_service("/attitude_controller/arm", timeout=30.0)
                    time.sleep(0.5)  # its checks have heard the latched estop_state
                else:
                    time.sleep(0.3)
                self._refused("e-stop")
                time.sleep(max(0.0, start + (duration or 0.0) - now()))
            finally:
                _set_bool("/estop", False)
                _set_bool("/pwm_node/enable", True)
            cleared = "e-stop reset, outputs enabled"
        else:
            service, topic, check = {"battery_critical": ("/sim_node/battery_flat", "health/battery", "battery"),
                                     "leak": ("/sim_node/water_inside", "health/leak", "leak")}[kind]
            _set_bool(service, True)
            try:
                start = self._first(topic, begin, Status.ERROR)  # the hazard reported: the stack must act now
                time.sleep(0.3)
                self._refused(check)
                time.sleep(max(0.0, start + duration - now()))
            finally:
                cleared_at = now()
                _set_bool(service, False)
            if kind == "leak":
                time.sleep(0.3)  # the probe reads dry
                answer = rospy.ServiceProxy("/leak_node/reset", Trigger)()
                if not answer.success:
                    raise RuntimeError("/leak_node/reset refused: %s" % answer.message)
            self._first(topic, cleared_at, Status.OK)
            cleared = "%s OK again" % topic
        end = self._arm()
        # From the safe state on (the limit after start), nothing may move until the operator's arm.
        return FaultRecord(kind, start, end, "stop", unarmed=[(start + 0.15, end)],
                           limp=kind.startswith("estop"), note="%s, re-armed by the operator" % cleared)

    def inject(self, kind: str) -> FaultRecord:
        import rospy
        expect, duration = KINDS[kind]
        now = rospy.get_time
        if kind in NODE_NAMES:
            name = NODE_NAMES[kind]
            pid = _node_pid(name)
            if pid is None:
                raise RuntimeError("%s is not running" % name)
            start = now()
            os.kill(pid, signal.SIGKILL)
            if not _wait(lambda: (_node_pid(name) or pid) != pid, 60.0, 0.1):
                raise RuntimeError("%s was not respawned within 60 s" % name)
            if kind != "kill_attitude_controller":
                return FaultRecord(kind, start, now(), expect)
            rospy.wait_for_service(name + "/arm", timeout=30.0)
            time.sleep(1.0)  # the operator looks before arming: the restarted controller must not move the legs
            end = self._arm()
            # Unarmed from the kill until the arm command; the commands it published before it died may
            # still land in the first few ms (IMU-to-PWM latency p99 about 5 ms), hence the 50 ms.
            return FaultRecord(kind, start, end, expect, unarmed=[(start + 0.05, end)],
                               note="re-armed by the operator")
        if kind.startswith("imu_link") or kind.startswith("i2c_stuck") or kind == "pca9685_power":
            service, fault_value = {"imu": ("/sim_node/imu_streaming", False), "i2c": ("/sim_node/i2c_bus_stuck", True),
                                    "pca": ("/sim_node/pca9685_power", False)}[kind[:3]]
            start = now()
            _set_bool(service, fault_value)
            time.sleep(duration)
            end = now()  # the fault ends when it is released (what follows is the stack's recovery)
            _set_bool(service, not fault_value)
            return FaultRecord(kind, start, end, expect)
        if kind == "cpu_hogs":
            hog = control_priority_prefix() + [sys.executable, "-c", "while True: pass"]
            start = now()
            hogs = [subprocess.Popen(hog, start_new_session=True) for _ in range(2)]
            time.sleep(duration)
            end = now()
            for process in hogs:
                process.kill()
                process.wait()
            return FaultRecord(kind, start, end, expect, note="2 x %s" % " ".join(hog[:3] or ["nice 0"]))
        if kind in ("setpoint_gone", "tether_gone"):
            tether = self.graph.tether
            assert tether is not None
            start = now()
            if kind == "setpoint_gone":
                os.killpg(tether.pid, signal.SIGKILL)
                tether.wait()
                time.sleep(duration)
                end = now()
                self.graph.start_tether()
            else:
                os.killpg(tether.pid, signal.SIGSTOP)
                time.sleep(duration)
                end = now()
                os.killpg(tether.pid, signal.SIGCONT)
            return FaultRecord(kind, start, end, expect)
        if expect == "stop":
            return self._stop(kind)
        if kind == "depth_lost":
            start = now()
            _set_bool("/sim_node/depth_sensor_fault", True)
            time.sleep(duration)
            end = now()
            _set_bool("/sim_node/depth_sensor_fault", False)
            lost = self._first("health/depth", start, 2, timeout=0.5) - start  # reported: a lost sensor, no hazard
            return FaultRecord(kind, start, end, expect, note="health/depth ERROR %.2f s after" % lost)
        if kind == "kill_rosmaster":
            self.graph.dump_params()
            start = now()
            self.graph.kill_master()
            time.sleep(duration)
            end = now()
            self.graph.restart_master()
            return FaultRecord(kind, start, end, expect, note="new master with the old parameters")
        raise ValueError("unknown fault kind %r" % kind)


# --------------------------------------------------------------------------------------------------
# The campaign
# --------------------------------------------------------------------------------------------------

def _bag_stamps(bag_dir: str):
    """For /imu/data and /controller_state of every bag in ``bag_dir`` (``.active`` ones reindexed): the
    first stamp and the stamps as :func:`~quadruped_control.analysis.fault_metrics.stamp_keys`; None
    without a bag."""
    from quadruped_control.analysis.bag_report import read_bags
    paths = sorted(glob.glob(os.path.join(bag_dir, "*.bag")) + glob.glob(os.path.join(bag_dir, "*.bag.active")))
    if not paths:
        return None
    data = read_bags(paths)
    return [(min(stamps) if stamps else None, stamp_keys(stamps)) for stamps in (data.imu_t, data.state_t)]


#: The publisher of each recorded topic the campaign compares, by the fault kind that kills it.
_PUBLISHER_KILLS = ("kill_vn100_node", "kill_attitude_controller")  # /imu/data, /controller_state
#: s: a message stamped this shortly before its publisher's SIGKILL can still be in the dying process's
#: socket to the recorder (while its copy to the campaign got through): lost by the fault, not by the
#: record. Stamps precede sending by the driver's and controller's latency (IMU-to-PWM p99 about 4 ms).
IN_FLIGHT_S = 0.05


def _lost_before(received_imu, received_state, bag, start: float, since: float, kind: str = "") -> Optional[int]:
    """Messages of /imu/data and /controller_state stamped in [since, start) that the campaign received
    and the bag lacks (matched by stamp). ``since``: 5 s before the fault, but not before the recording
    began nor before the previous fault was over (a respawned publisher reaches the recorder a little
    after the campaign's own subscriber: that gap belongs to the fault before). A topic whose publisher
    this ``kind`` kills ends :data:`IN_FLIGHT_S` before the kill."""
    if bag is None:
        return None
    ends = [start - IN_FLIGHT_S if kind == killer else start for killer in _PUBLISHER_KILLS]
    return sum(lost_messages(received, keys, max(since, first), end)
               for received, (first, keys), end in zip((received_imu, received_state), bag, ends)
               if first is not None)


#: s: the seeded wait before each injection is drawn from this range (a random moment of the manoeuvre)
PAUSE = (1.0, 4.0)


def run_graph(kinds: Sequence[str], out: str, seed: int, log=print, ready_timeout: float = 120.0,
              pause: Sequence[float] = PAUSE) -> List[dict]:
    """One graph: start it, inject ``kinds`` in order at seeded random moments (``pause`` s apart, after the
    recovery of the one before), stop it, judge every injection. Returns one dict per injection
    (:class:`InjectionResult` fields plus the fault record)."""
    import rospy

    from quadruped_drivers.hardware_config import load_hardware_config

    hardware = load_hardware_config(None)
    rng = random.Random(seed)
    os.makedirs(out, exist_ok=True)
    graph = Graph(out, free_port(), seed)
    records: List[FaultRecord] = []
    errors: List[str] = []
    graph.start()
    try:
        os.environ["ROS_MASTER_URI"] = graph.uri
        rospy.init_node("fault_campaign", anonymous=True, disable_signals=True)
        monitor = Monitor()
        injector = Injector(graph)
        if not _wait(lambda: monitor.tracking_now(hardware), ready_timeout, 0.2):
            raise RuntimeError("the stack did not start tracking within %.0f s (see %s/launch.log)"
                               % (ready_timeout, out))
        for number, kind in enumerate(kinds):
            time.sleep(rng.uniform(pause[0], pause[1]))  # a random moment of the manoeuvre
            if not _wait(lambda: monitor.tracking_now(hardware), 20.0, 0.1):
                errors.append("%s #%d: not tracking before the injection" % (kind, number))
            try:
                record = injector.inject(kind)
            except Exception as exc:  # noqa: BLE001 - the campaign goes on; the failure is reported
                errors.append("%s #%d: injection failed: %s" % (kind, number, exc))
                log("  %s: injection failed: %s" % (kind, exc))
                continue
            records.append(record)
            _wait(lambda: monitor.tracking_now(hardware), RECOVERY_LIMIT + 1.0, 0.1)
            time.sleep(0.5)
            log("  %-26s %3d/%d  %.2f s" % (kind, number + 1, len(kinds), record.end - record.start))
        time.sleep(1.0)
        timeline = monitor.timeline()
        with monitor.lock:
            imu_stamps, state_stamps = list(monitor.imu_stamps), list(monitor.state_stamps)
    finally:
        graph.stop()
        rospy.signal_shutdown("graph stopped")
    # What was recorded stays with the graph, so that the judgement can be made again (judge_graph).
    np.savez_compressed(os.path.join(out, "timeline.npz"), imu_stamps=np.array(imu_stamps),
                        state_stamps=np.array(state_stamps), **asdict(timeline))
    with open(os.path.join(out, "records.json"), "w") as handle:
        json.dump({"records": [asdict(r) for r in records], "errors": errors}, handle, indent=1)
    return judge_graph(out)


def judge_graph(out: str) -> List[dict]:
    """Judge every injection of the graph recorded in ``out`` (``timeline.npz``, ``records.json``, the bags):
    one dict per injection (:class:`InjectionResult` fields plus the fault record), then the errors."""
    from quadruped_drivers.hardware_config import load_hardware_config

    hardware = load_hardware_config(None)
    saved = np.load(os.path.join(out, "timeline.npz"))
    timeline = Timeline(**{name: saved[name] for name in Timeline.__dataclass_fields__})
    imu_stamps, state_stamps = saved["imu_stamps"], saved["state_stamps"]
    with open(os.path.join(out, "records.json")) as handle:
        saved_records = json.load(handle)
    records = [FaultRecord(**{k: (v if k != "unarmed" else [tuple(x) for x in v]) for k, v in r.items()})
               for r in saved_records["records"]]
    errors = saved_records["errors"]
    bag = _bag_stamps(os.path.join(out, "bags"))
    min_us = [j.min_us for j in hardware.joints]
    max_us = [j.max_us for j in hardware.joints]
    results = []
    previous_end = -math.inf
    for record in records:
        result = judge_injection(timeline, record, min_us, max_us, hardware.actual_pwm_frequency_hz,
                                 settle_window=RECOVERY_LIMIT)
        result.lost_before = _lost_before(imu_stamps, state_stamps, bag, record.start,
                                          since=max(record.start - 5.0, previous_end + 1.0), kind=record.kind)
        previous_end = record.end
        entry = asdict(result)
        entry.update(end=record.end, expect=record.expect, note=record.note)
        results.append(entry)
    for error in errors:
        results.append({"kind": "error", "error": error})
    return results


def run_campaign(kinds: Sequence[str], per_kind: int, out: str, seed: int = 0, log=print,
                 pause: Sequence[float] = PAUSE) -> Dict[str, dict]:
    """``per_kind`` injections of each of ``kinds`` in a seeded random order on one graph, then each master
    kill on a graph of its own (module docstring); returns the per-kind summaries and writes
    ``out/fault_campaign.json``. ``pause``: :func:`run_graph`'s."""
    rng = random.Random(seed)
    plain = [k for k in kinds if k != "kill_rosmaster"] * per_kind
    rng.shuffle(plain)
    results: List[dict] = []
    if plain:
        log("graph 1: %d injections" % len(plain))
        results += _isolated(plain, os.path.join(out, "graph_main"), seed, pause)
    if "kill_rosmaster" in kinds:
        for number in range(per_kind):
            log("graph for master kill %d/%d" % (number + 1, per_kind))
            results += _isolated(["kill_rosmaster"], os.path.join(out, "graph_master_%02d" % number), seed + 1 + number,
                                 pause)
    summary = summarise(results, kinds)
    with open(os.path.join(out, "fault_campaign.json"), "w") as handle:
        json.dump({"seed": seed, "per_kind": per_kind, "summary": summary, "injections": results}, handle,
                  indent=1, default=float)
    return summary


def _isolated(kinds: Sequence[str], out: str, seed: int, pause: Sequence[float] = PAUSE) -> List[dict]:
    """:func:`run_graph` in a child process: rospy can init one node per process, and a master kill
    leaves the campaign's node registered with a master that is gone."""
    result_file = os.path.join(out, "results.json")
    os.makedirs(out, exist_ok=True)
    subprocess.run([sys.executable, "-m", "quadruped_control.ros.fault_campaign", "graph", "--out", out,
                    "--seed", str(seed), "--pause", str(pause[0]), str(pause[1]), "--kinds"] + list(kinds), check=False)
    if not os.path.exists(result_file):
        return [{"kind": "error", "error": "graph in %s left no results" % out}]
    with open(result_file) as handle:
        return json.load(handle)


def rejudge_campaign(out: str) -> Dict[str, dict]:
    """:func:`judge_graph` over every graph of a campaign's ``out`` folder; rewrites its
    ``fault_campaign.json`` summary and returns it."""
    with open(os.path.join(out, "fault_campaign.json")) as handle:
        campaign = json.load(handle)
    results: List[dict] = []
    for folder in sorted(glob.glob(os.path.join(out, "graph_*"))):
        results += judge_graph(folder)
    kinds = [k for k in KINDS if any(r.get("kind") == k for r in results)]
    campaign.update(summary=summarise(results, kinds), injections=results)
    with open(os.path.join(out, "fault_campaign.json"), "w") as handle:
        json.dump(campaign, handle, indent=1, default=float)
    return campaign["summary"]


def summarise(results: Sequence[dict], kinds: Sequence[str]) -> Dict[str, dict]:
    summary: Dict[str, dict] = {}
    for kind in kinds:
        rows = [InjectionResult(**{k: r[k] for k in InjectionResult.__dataclass_fields__})
                for r in results if r.get("kind") == kind]
        summary[kind] = kind_summary(rows, KINDS[kind][0])
        summary[kind]["errors"] = [r["error"] for r in results if r.get("kind") == "error" and
                                   r["error"].startswith(kind + " ")]
    errors = [r["error"] for r in results if r.get("kind") == "error"]
    summary["_errors"] = {"count": len(errors), "errors": errors}
    return summary


#: Messages a killed recorder may lose per kill: its unwritten 16 KB chunk (launch/record.launch) holds
#: about 0.06 s of the stack's topics; /imu/data and /controller_state together are 300 messages/s.
RECORDER_CHUNK_MESSAGES = 30


def failures(summary: Dict[str, dict], safe_limit: float, recovery_limit: float = RECOVERY_LIMIT,
             lost_allowed: Optional[Dict[str, int]] = None) -> List[str]:
    """What breaks the campaign's targets (docs/faults.md), per kind (empty: every target met). ``lost_allowed``: messages
    per injection a kind may lose from the bag (default none: a target of 0)."""
    problems = []
    for kind, row in summary.items():
        if kind.startswith("_"):
            if row["count"]:
                problems += row["errors"]
            continue
        if row["injections"] == 0:
            problems.append("%s: no injection ran" % kind)
            continue
        if row["pulses_outside"]:
            problems.append("%s: %d pulses outside limits" % (kind, row["pulses_outside"]))
        if row["moved_unarmed"]:
            problems.append("%s: legs moved while unarmed (%d rows)" % (kind, row["moved_unarmed"]))
        if row["expect"] != "track":
            if row["never_safe"]:
                problems.append("%s: not safe in %d injections" % (kind, row["never_safe"]))
            elif row["time_to_safe_max"] is not None and row["time_to_safe_max"] > safe_limit:
                problems.append("%s: safe after %.3f s > %.3f s" % (kind, row["time_to_safe_max"], safe_limit))
        if row["recovered"] < row["injections"]:
            problems.append("%s: tracked again in %d of %d" % (kind, row["recovered"], row["injections"]))
        elif row["time_to_recovery_max"] is not None and row["time_to_recovery_max"] > recovery_limit:
            problems.append("%s: recovery took %.2f s" % (kind, row["time_to_recovery_max"]))
        allowed = (lost_allowed or {}).get(kind, 0) * row["injections"]
        if row["lost_before"] and row["lost_before"] > allowed:
            problems.append("%s: %d messages lost from the bag before the fault%s" % (
                kind, row["lost_before"], " (allowed %d)" % allowed if allowed else ""))
    return problems


def format_table(summary: Dict[str, dict]) -> str:
    def fmt(value, digits=3):
        return "-" if value is None else ("%.*f" % (digits, value) if isinstance(value, float) else str(value))
    lines = ["| fault | expect | injections | time to safe state, max [s] | tracking during (min) | "
             "recovery median / max [s] | pulses outside limits | legs moved unarmed | lost before fault |",
             "|---|---|---|---|---|---|---|---|---|"]
    for kind, row in summary.items():
        if kind.startswith("_"):
            continue
        lines.append("| %s | %s | %d | %s | %s | %s / %s (%d of %d) | %d | %d | %s |" % (
            kind, row["expect"], row["injections"],
            fmt(row["time_to_safe_max"]) + (" (never: %d)" % row["never_safe"] if row["never_safe"] else ""),
            fmt(row["tracking_fraction_min"], 2), fmt(row["time_to_recovery_median"], 2),
            fmt(row["time_to_recovery_max"], 2), row["recovered"], row["injections"], row["pulses_outside"],
            row["moved_unarmed"], fmt(row["lost_before"])))
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------------
# The tether process
# --------------------------------------------------------------------------------------------------

def run_tether(seed: int, period: float) -> None:
    """The operator's laptop: a new manoeuvre setpoint every ``period`` s (seeded), and subscriptions to
    the telemetry that it reads slowly (small queues, as a GUI would)."""
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from sensor_msgs.msg import Imu

    from underwater_quadruped.msg import ControllerState
    rospy.init_node("tether", anonymous=True)
    publisher = rospy.Publisher("attitude_setpoint_rpy_deg", Vector3Stamped, queue_size=1, latch=True)
    for topic, kind in (("controller_state", ControllerState), ("imu/data", Imu), ("/diagnostics", DiagnosticArray)):
        rospy.Subscriber(topic, kind, lambda _msg: None, queue_size=1)
    rng = random.Random(seed)
    while not rospy.is_shutdown():
        msg = Vector3Stamped()
        msg.header.stamp = rospy.Time.now()
        msg.vector.x, msg.vector.y, msg.vector.z = rng.choice(MANOEUVRES)
        publisher.publish(msg)
        rospy.sleep(period)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    tether = sub.add_parser("tether")
    tether.add_argument("--seed", type=int, default=0)
    tether.add_argument("--period", type=float, default=6.0)
    graph = sub.add_parser("graph")
    graph.add_argument("--out", required=True)
    graph.add_argument("--seed", type=int, default=0)
    graph.add_argument("--kinds", nargs="+", required=True, choices=sorted(KINDS))
    graph.add_argument("--pause", nargs=2, type=float, default=list(PAUSE), metavar=("LOW", "HIGH"))
    judge = sub.add_parser("judge", help="judge a campaign's recorded graphs again (OUT of run_campaign)")
    judge.add_argument("out")
    args = parser.parse_args(argv)
    if args.command == "tether":
        run_tether(args.seed, args.period)
        return 0
    if args.command == "judge":
        print(format_table(rejudge_campaign(args.out)))
        return 0
    # A terminated campaign still stops its graph (run_graph's finally): SIGTERM as SystemExit.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    results = run_graph(args.kinds, args.out, args.seed, pause=args.pause)
    with open(os.path.join(args.out, "results.json"), "w") as handle:
        json.dump(results, handle, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
