"""One day in the tank (docs/tank_day.md): runs the day's plan (:func:`quadruped_control.control.tank_day.day_plan`)
on a running stack, one recorded run after another, each into its own folder of ``~day_dir`` with its record.

Before each run (and each operator step of a run) it logs the operator's task and publishes it on ``tank_day/prompt``
(std_msgs/String, latched), then waits for ``~next`` (std_srvs/Trigger; its reply says how the run began, or why it
did not) or ``~skip`` (skips the run at its prompt, ends it early while it runs). ``~auto_continue`` (the simulated
day) goes on by itself. A run: ``launch/record.launch`` in a roslaunch of its own, recording into the run's folder;
an armed run publishes its first setpoint, arms the controller (``attitude_controller/arm``; t_rec set through
dynamic_reconfigure for the Table-1 rows that need it), commands its setpoints with the maneuver node's code
(:class:`~quadruped_control.ros.maneuver_node.ManeuverNode`) and disarms; a disarmed run disarms and records its phases.
Then the recorder stops and the run's ``run.yaml`` is written (:func:`~quadruped_control.control.tank_day.run_record`):
gains at start and end (``attitude_controller/parameter_updates``), the configuration files the stack's ``*_yaml``
parameters load and their hashes, the code's version, the legs' pose (``joint_states``) at start and end, events, and
the operator's notes (``tank_day/note``, std_msgs/String, any time; ``~notes`` for the whole day). Started again on
the same ``~day_dir``, it goes on with the runs not yet done. When the plan is done the node ends (a required node:
the launch ends with it).

Parameters: ~day_dir, ~auto_continue (false), ~notes, the plan's (DayOptions): ~hang_seconds,
~tether_still_seconds, ~tether_hold_seconds, ~tether_release_seconds, ~step_delay, ~step_scale, ~table1_seconds,
~return_seconds, ~repeats, ~rows (Table-1 labels, e.g. ["roll 30"]; empty: all), ~yaw_reference (relative,
absolute), ~battery_minutes; ~arm_timeout (30 s), ~after (2 s recorded after the disarm).
"""
from __future__ import annotations

import dataclasses
import datetime
import glob
import os
import signal
import subprocess
import threading
import time
from typing import Any, Dict, List, Optional

import rosgraph
import rospy
import yaml
from dynamic_reconfigure.msg import Config
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger, TriggerResponse

from quadruped_common.config import ParameterError
from quadruped_common.ros.node_startup import start_node
from quadruped_control.control import tank_day
from quadruped_control.control.setpoint_sequence import SetpointHold
from quadruped_control.ros.maneuver_node import ManeuverNode
from underwater_quadruped.msg import ControllerState

CONTROLLER = "attitude_controller"


class RunRecorder:
    """``record.launch`` in a roslaunch of its own, recording into one run's folder (its output in record.log)."""

    def __init__(self, folder: str) -> None:
        self.folder = folder
        self.lock = threading.Lock()
        env = dict(os.environ, ROS_NAMESPACE=rospy.get_namespace())
        with open(os.path.join(folder, "record.log"), "w") as log:
            self.process = subprocess.Popen(["roslaunch", "underwater_quadruped", "record.launch",
                                             "bag_dir:=%s" % folder], stdout=log, stderr=subprocess.STDOUT, env=env)

    def ready(self, timeout: float) -> bool:
        """Whether the recorder has its bag open and listens to controller_state within ``timeout`` s (wall)."""
        topic = rospy.resolve_name("controller_state")
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.process.poll() is None and not rospy.is_shutdown():
            if glob.glob(os.path.join(self.folder, "*.bag.active")):
                _, subscribers, _ = rosgraph.Master(rospy.get_name()).getSystemState()
                if any(name == topic and any(n.endswith("/recorder") for n in nodes) for name, nodes in subscribers):
                    time.sleep(1.0)  # the connections and the latched topics (gains) come in
                    return True
            time.sleep(0.2)
        return False

    def stop(self, timeout: float = 30.0) -> None:
        """Ends the recording (SIGINT, as Ctrl-C: the bag is closed), then harder if it does not end."""
        with self.lock:
            for stop in (lambda: self.process.send_signal(signal.SIGINT), self.process.terminate, self.process.kill):
                if self.process.poll() is not None:
                    return
                stop()
                try:
                    self.process.wait(timeout)
                except subprocess.TimeoutExpired:
                    continue


class Prompt:
    """An operator's task waiting for ``~next`` or ``~skip``; ``outcome``: the reply to ``~next``."""

    def __init__(self, text: str) -> None:
        self.text, self.choice, self.outcome = text, "", ""
        self.chosen, self.answered = threading.Event(), threading.Event()

    def answer(self, outcome: str) -> None:
        self.outcome = outcome
        self.answered.set()


def _stamp() -> Dict[str, Any]:
    return {"ros_time": rospy.get_time(), "wall": datetime.datetime.now().isoformat(timespec="seconds")}


def _options() -> tank_day.DayOptions:
    values: Dict[str, Any] = {}
    for field in dataclasses.fields(tank_day.DayOptions):
        if rospy.has_param("~" + field.name):
            value = rospy.get_param("~" + field.name)
            if field.name == "rows":
                value = tuple(value if isinstance(value, list) else [r.strip() for r in str(value).split(",")
                                                                     if r.strip()])
            values[field.name] = value
    return tank_day.DayOptions(**values)


class TankDayNode:
    def __init__(self) -> None:
        self.day_dir = os.path.abspath(os.path.expanduser(str(rospy.get_param("~day_dir", "~/bags/tank_day"))))
        self.auto = bool(rospy.get_param("~auto_continue", False))
        self.day_notes = str(rospy.get_param("~notes", ""))
        self.arm_timeout = float(rospy.get_param("~arm_timeout", 30.0))
        self.after = float(rospy.get_param("~after", 2.0))
        self.options = _options()
        self.plan = tank_day.day_plan(self.options)
        self.lock = threading.Lock()
        self.prompt: Optional[Prompt] = None
        self.running = ""  # the run recording now
        self.end_run = threading.Event()
        self.notes: List[Dict[str, Any]] = []
        self.gains: Optional[Dict[str, Any]] = None
        self.legs: Dict[str, float] = {}
        self.controller_seen = False
        self.recorder: Optional[RunRecorder] = None
        self.reconfigure = None
        self.maneuver = ManeuverNode(sequence=(), delay=0.0, timeout=self.arm_timeout)
        self.prompt_pub = rospy.Publisher("tank_day/prompt", String, queue_size=1, latch=True)
        rospy.Subscriber("attitude_controller/parameter_updates", Config, self._on_gains, queue_size=5)
        rospy.Subscriber("joint_states", JointState, self._on_joints, queue_size=1)
        rospy.Subscriber("controller_state", ControllerState, self._on_state, queue_size=1)
        rospy.Subscriber("tank_day/note", String, self._on_note, queue_size=20)
        rospy.Service("~next", Trigger, self._on_next)
        rospy.Service("~skip", Trigger, self._on_skip)
        rospy.on_shutdown(self._stop_recorder)

    # ---- inputs ----------------------------------------------------------------------------------

    def _on_gains(self, msg: Config) -> None:
        self.gains = {p.name: p.value for p in (*msg.bools, *msg.ints, *msg.strs, *msg.doubles)}

    def _on_joints(self, msg: JointState) -> None:
        self.legs = dict(zip(msg.name, (float(q) for q in msg.position)))

    def _on_state(self, msg: ControllerState) -> None:
        self.controller_seen = True

    def _on_note(self, msg: String) -> None:
        with self.lock:
            self.notes.append({"ros_time": rospy.get_time(), "text": msg.data})
        rospy.loginfo("tank day: note for %s: %s", self.running or "the next run", msg.data)

    def _on_next(self, _request) -> TriggerResponse:
        with self.lock:
            prompt = self.prompt
            if prompt is None or prompt.chosen.is_set():
                return TriggerResponse(False, "nothing waits for next: %s" % (
                    "%s is running (skip ends it)" % self.running if self.running else "no prompt yet"))
            prompt.choice = "next"
            prompt.chosen.set()
        answered = prompt.answered.wait(120.0)
        return TriggerResponse(True, prompt.outcome if answered else "next taken; see the log")

    def _on_skip(self, _request) -> TriggerResponse:
        with self.lock:
            prompt = self.prompt
            if prompt is not None and not prompt.chosen.is_set():
                prompt.choice = "skip"
                prompt.chosen.set()
                return TriggerResponse(True, "skipped: %s" % prompt.text)
            if self.running:
                self.end_run.set()
                self.maneuver.stop.set()
                return TriggerResponse(True, "ending %s now (within 10 s)" % self.running)
        return TriggerResponse(False, "nothing to skip")

    # ---- the day -----------------------------------------------------------------------------------

    def ask(self, text: str) -> Prompt:
        """Log and publish the operator's task; wait for next or skip (at once with ~auto_continue)."""
        prompt = Prompt(text)
        rospy.loginfo("tank day: %s%s", text, "" if self.auto else "  [rosservice call %s | %s]" % (
            rospy.resolve_name("~next"), rospy.resolve_name("~skip")))
        self.prompt_pub.publish(String(text))
        with self.lock:
            self.prompt = prompt
            if self.auto:
                prompt.choice = "next"
                prompt.chosen.set()
        while not prompt.chosen.wait(0.2):
            if rospy.is_shutdown():
                raise rospy.ROSInterruptException("shut down at a prompt")
        return prompt

    def wait_for_stack(self, timeout: float = 60.0) -> None:
        """Until the controller has reported its state and gains and the legs their angles (wall time), so that
        the first run's record has them; a warning naming what is missing after ``timeout``."""
        deadline = time.monotonic() + timeout
        while not rospy.is_shutdown() and time.monotonic() < deadline:
            if self.controller_seen and self.gains is not None and self.legs:
                return
            time.sleep(0.2)
        rospy.logwarn("tank day: after %.0f s, still no %s: the runs' records will lack them", timeout, ", ".join(
            name for name, seen in (("controller_state", self.controller_seen), ("gains", self.gains is not None),
                                    ("joint_states", bool(self.legs))) if not seen))

    def run(self) -> None:
        self.wait_for_stack()
        os.makedirs(self.day_dir, exist_ok=True)
        self._write(os.path.join(self.day_dir, tank_day.PLAN_FILE),
                    tank_day.plan_record(self.plan, self.options, self.day_notes))
        done: Dict[str, Any] = {}
        for path in glob.glob(os.path.join(self.day_dir, "*", tank_day.RUN_FILE)):
            with open(path) as stream:
                done[os.path.basename(os.path.dirname(path))] = yaml.safe_load(stream) or {}
        todo = tank_day.remaining(self.plan, done)
        if len(todo) < len(self.plan):
            rospy.loginfo("tank day: %s already holds %d of the %d runs; going on with %s", self.day_dir,
                          len(self.plan) - len(todo), len(self.plan), todo[0][0].name if todo else "none")
        try:
            for run, attempt in todo:
                while self.do_run(run, attempt) == "aborted":
                    if self.auto:
                        rospy.logfatal("tank day: %s could not begin, and nobody is there to try again "
                                       "(~auto_continue): the day stops", run.name)
                        rospy.signal_shutdown("a run could not begin")
                        return
                    attempt += 1
        except rospy.ROSInterruptException:
            return
        text = "The day is done: %s. Read it with the studies (docs/tank_day.md)." % self.day_dir
        rospy.loginfo("tank day: %s", text)
        self.prompt_pub.publish(String(text))
        rospy.signal_shutdown("tank day done")

    def do_run(self, run: tank_day.Run, attempt: int) -> str:
        """One attempt of ``run``: its prompt, the recording, its record; its status."""
        folder = os.path.join(self.day_dir, run.name + ("_a%d" % attempt if attempt > 1 else ""))
        prompt = self.ask("%s: %s" % (os.path.basename(folder), run.prompt))
        log: Dict[str, Any] = {"attempt": attempt, "day_notes": self.day_notes, "events": []}
        os.makedirs(folder, exist_ok=True)
        if prompt.choice == "skip":
            prompt.answer("skipped")
            return self._finish(run, folder, "skipped", log, "skipped by the operator")
        log.update(start=_stamp(), gains={"at_start": self.gains}, legs_rad={"at_start": dict(self.legs)},
                   config=tank_day.config_files(_yaml_params()), code=tank_day.code_version(_package_dir()))
        self.end_run.clear()
        self.recorder = RunRecorder(folder)
        if not self.recorder.ready(30.0):
            self._stop_recorder()
            prompt.answer("%s: the recorder did not start (%s); the prompt stands" % (run.name, folder + "/record.log"))
            return self._finish(run, folder, "aborted", log, "the recorder did not start (record.log)")
        self.running = run.name
        status, why = "complete", ""
        try:
            if run.armed:
                status, why = self.armed_run(run, log, prompt)
            else:
                prompt.answer("%s: recording into %s" % (run.name, folder))
                status, why = self.disarmed_run(run, log)
        except rospy.ROSInterruptException:
            status, why = "ended early", "the day was stopped"
        finally:
            self.running = ""
            log.update(end=_stamp())
            log["gains"]["at_end"] = self.gains
            log["legs_rad"]["at_end"] = dict(self.legs)
            self._stop_recorder()
        if glob.glob(os.path.join(folder, "*.bag.active")):
            log["events"].append({"at": None, "what": "a bag was left open (.bag.active): read from a reindexed copy"})
        return self._finish(run, folder, status, log, why)

    def _event(self, log: Dict[str, Any], what: str) -> None:
        log["events"].append({"at": rospy.get_time() - log["start"]["ros_time"], "what": what})
        rospy.loginfo("tank day: %s", what)

    def _wait(self, seconds: float) -> bool:
        """Record on for ``seconds`` (ROS time); False when the operator ended the run first."""
        end = rospy.get_time() + seconds
        while rospy.get_time() < end:
            if self.end_run.is_set():
                return False
            rospy.sleep(min(0.5, end - rospy.get_time()))
        return True

    def disarmed_run(self, run: tank_day.Run, log: Dict[str, Any]) -> tuple:
        self._arm(False)
        for phase in run.phases:
            if phase.prompt:
                prompt = self.ask("%s, %s: %s" % (run.name, phase.name, phase.prompt))
                if prompt.choice == "skip":
                    prompt.answer("ended %s" % run.name)
                    return "ended early", "ended by the operator before %s" % phase.name
                prompt.answer("%s: %s, recording %.0f s" % (run.name, phase.name, phase.seconds))
            self._event(log, phase.name)
            if not self._wait(phase.seconds):
                return "ended early", "ended by the operator during %s" % phase.name
        return "complete", ""

    def armed_run(self, run: tank_day.Run, log: Dict[str, Any], prompt: Prompt) -> tuple:
        maneuver = self.maneuver
        maneuver.sequence, maneuver.delay, maneuver.frame_id = run.holds, run.delay, run.yaw_reference
        maneuver.index = -1
        maneuver.stop.clear()
        maneuver.armed.clear()
        first = SetpointHold((0.0, 0.0, 0.0), run.delay) if run.delay > 0.0 else run.holds[0]
        maneuver.publish(first, -1 if run.delay > 0.0 else 0)
        t_rec = self._set_t_rec(run.t_rec, log) if run.t_rec is not None else None
        armed, message = self._arm(True)
        if not armed:
            prompt.answer("%s: arming refused: %s; the prompt stands" % (run.name, message))
            self._set_t_rec(t_rec, log)
            return "aborted", "arming refused: %s" % message
        self._event(log, "armed")
        log["gains"]["at_arming"] = self.gains
        prompt.answer("%s: armed, recording into %s" % (run.name, self.recorder.folder))
        try:
            completed = maneuver.command()
        finally:
            maneuver.stop.set()  # the disarm that follows is the run's end, not a stop to warn of
            self._arm(False)
            self._event(log, "disarmed")
            self._set_t_rec(t_rec, log)
        rospy.sleep(self.after)
        if completed:
            return "complete", ""
        return "ended early", ("ended by the operator" if self.end_run.is_set() else
                               "the controller did not act within %.0f s of arming" % self.arm_timeout
                               if maneuver.index < 0 else "the sequence did not end")

    def _arm(self, on: bool) -> tuple:
        try:
            rospy.wait_for_service(CONTROLLER + "/arm", 10.0)
            reply = rospy.ServiceProxy(CONTROLLER + "/arm", SetBool)(on)
            return bool(reply.success), str(reply.message)
        except (rospy.ROSException, rospy.ServiceException) as exc:
            return False, str(exc)

    def _set_t_rec(self, value: Optional[float], log: Dict[str, Any]) -> Optional[float]:
        """Set the controller's t_rec live (dynamic_reconfigure); the value it had before (None: unchanged)."""
        if value is None:
            return None
        from dynamic_reconfigure.client import Client

        try:
            if self.reconfigure is None:
                self.reconfigure = Client(CONTROLLER, timeout=10.0)
            before = float(self.reconfigure.get_configuration(timeout=10.0)["t_rec"])
            self.reconfigure.update_configuration({"t_rec": float(value)})
        except Exception as exc:  # noqa: BLE001 - dynamic_reconfigure raises several kinds; the run goes on
            self._event(log, "t_rec %.2f s could not be set: %s" % (value, exc))
            return None
        self._event(log, "t_rec %.2f s (was %.2f)" % (value, before))
        return before

    def _stop_recorder(self) -> None:
        if self.recorder is not None:
            self.recorder.stop()

    def _finish(self, run: tank_day.Run, folder: str, status: str, log: Dict[str, Any], why: str) -> str:
        with self.lock:
            start = log.get("start", {}).get("ros_time", rospy.get_time())
            log["notes"] = [{"at": round(n["ros_time"] - start, 3), "text": n["text"]} for n in self.notes]
            self.notes = []
            self.prompt = None
        if why:
            log["why"] = why
        self._write(os.path.join(folder, tank_day.RUN_FILE), tank_day.run_record(run, status, log))
        rospy.loginfo("tank day: %s %s%s", os.path.basename(folder), status, ": " + why if why else "")
        return status

    @staticmethod
    def _write(path: str, record: Dict[str, Any]) -> None:
        with open(path + ".tmp", "w") as stream:
            yaml.safe_dump(record, stream, sort_keys=False, default_flow_style=None, width=120)
        os.replace(path + ".tmp", path)


def _yaml_params() -> Dict[str, Any]:
    """The stack's ``*_yaml`` (and ``plant``) parameters, full name -> value, with every file the controller loads
    (a parameter it does not find: its loader's default)."""
    names = [n for n in rospy.get_param_names() if n.endswith("_yaml") or n.endswith("/plant")]
    params = {name: rospy.get_param(name, "") for name in names}
    for key in tank_day.CONTROLLER_FILES:
        params.setdefault(rospy.resolve_name(CONTROLLER + "/" + key), "")
    return params


def _package_dir() -> str:
    try:
        import rospkg

        return rospkg.RosPack().get_path("underwater_quadruped")
    except Exception:  # noqa: BLE001 - rospkg raises ResourceNotFound, or is missing: the source tree instead
        return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main(argv: Optional[List[str]] = None) -> None:
    node = start_node("tank_day", TankDayNode, errors=(ParameterError,))
    node.run()
