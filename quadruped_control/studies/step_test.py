"""The setpoint step test: the robot holds a tilt, the setpoint steps towards upright and away from it, and
how long each step takes to settle is set beside what each tank model does on the same steps.

    python -m quadruped_control.studies.step_test RUN [--compare YAML_OR_DIR ...] [--seed 0]
        [--tank-disturbance SIGMA TAU] [--jobs 1] --out DIR
    python -m quadruped_control.studies.step_test --simulated TRUTH_YAML [--tank-disturbance SIGMA TAU]
        [--attitude-noise-deg 0.05] (and the options above)

Why (docs/identification.md, "The step test as a study"): the shipped ensemble's members fit Table 1
within 3 of each other and take 1.5 to 15 s to return 12 deg towards upright from a held 45 deg roll. A plant whose trim leaves a net static torque pushing away from upright returns much
more slowly than it moves away; one whose trim and rope balance takes the same time both ways. The robot's
roll group in Table 1 settled 18-95 s after its rise, which no fitted set reproduces; this test, eighteen
minutes in the tank with nothing added, says which kind of plant the robot is.

The protocol (:data:`PROTOCOL`; on the robot ``roslaunch underwater_quadruped step_test.launch``, which records
and publishes the setpoints in turn once the controller is armed, docs/tuning_and_recording.md): roll 45 deg held
120 s, then 33, 45, 57 and 45 deg for 90 s each; level for 120 s; the same in pitch. A RUN is a bag (or a split recording's
parts joined by commas) with ``/imu/data`` and ``/controller_state``, read by
:func:`quadruped_control.analysis.bag_report.read_bags`; the steps are the changes of the controller's setpoint
while it was acting, armed and not holding its safe pose (:func:`~quadruped_control.analysis.steps.find_steps`), so
any single-axis sequence is read, not only this one; once the controller has first acted (its start-up hold
apart), a step's response ends where it stopped acting, and a step taken less than ten seconds after such a
stop is listed as not read (:func:`~quadruped_control.analysis.steps.response_ends`). ``--simulated`` runs the
protocol on the tank plant of TRUTH_YAML instead (the robot's own closed loop, experiment gains, rate-limited
servos, through :func:`~.trial.trial_simulation`): what the test would show of a plant whose values are known. A RUN
may also be a folder: a tank day's (its step-test run) or one run's (:mod:`~quadruped_control.studies.day_folder`,
which says what it found missing).

The models run the gains the robot ran (:func:`record_gains`): those in force at the record's first step, from the
bag's controller parameter_updates, else from the run's run.yaml, else (said in the report) the experiment gain set.

Each step's response (:func:`~quadruped_control.analysis.steps.step_response`): the paper's settling time
within 6 deg, the same within 2 deg, the overshoot past the new setpoint, and how well the tilt before it was
held. Each ``--compare`` tank.yaml (default: the shipped ensemble, config/tank_ensemble) is asked what the
record asked of the robot (:func:`record_sequence`): from rest at the record's first attitude, the same
setpoints at the same times, with the controller stopped where the robot's was, so that each step finds the
model with the history the robot had (its integral wound up by the same holds). A model agrees on a step when
its settling time within 6 deg is within a factor 2 of the robot's, or neither settles
(:func:`~quadruped_control.analysis.steps.agrees`); the report counts, per model, the steps it agrees on that
change one axis and run at least the settling hold, 30 s (:func:`~quadruped_control.analysis.steps.judged`).

Output in ``--out``: ``step_test.json`` (the command, the code's fingerprint, the steps, every model's
responses), ``step_test.md``, and ``step_test.png`` (each step's stepped angle, the robot's beside each
model's). Docs: docs/identification.md, "The step test as a study".
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, config_path
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.control.controller_config import apply_tunables, load_controller_config
from quadruped_control.control.setpoint_sequence import STEP_TEST
from quadruped_control.analysis.bag_report import (BagReportError, attitude_rpy, gains_in_force, gains_text,
                                                  read_bags)
from quadruped_control.analysis.metrics import SETTLING_HOLD
from quadruped_control.analysis.steps import (HOLD_CHECK, Step, StepResponse, agrees, find_steps, judged,
                                              response_ends, step_response)
from quadruped_control.sim.simulation import SimulationError
from quadruped_control.studies import StudyError
from quadruped_control.studies.day_folder import is_folder, missing_text, one_run
from quadruped_control.studies.ensemble import DEFAULT_FOLDER, disturbance_overrides, member_tanks, tank_files
from quadruped_control.studies.runner import (code_record, command_line, describe_source, warn_uncommitted,
                                              write_study_report)
from quadruped_control.studies.trial import TrialSpec, trial_simulation

__all__ = ["CONTROLLER_STATES", "PROTOCOL", "Hold", "StepRecord", "controller_states", "gains_overrides", "model_run",
           "record_from_bag", "record_gains", "record_sequence", "run_sequence", "step_test_spec"]

#: The test's setpoints (roll, pitch, yaw in deg) and how long each is held (s), in order from level: the
#: maneuver node's ``protocol:=step_test`` (:data:`~quadruped_control.control.setpoint_sequence.STEP_TEST`).
PROTOCOL: Tuple[Tuple[Tuple[float, float, float], float], ...] = tuple((hold.rpy_deg, hold.seconds)
                                                                      for hold in STEP_TEST)


#: What the controller does from a time on: strokes ("acting"), holds its safe pose ("holding": the legs back at
#: the nominal pose, the integral kept), or is disarmed ("disarmed": cleared when it is armed again).
CONTROLLER_STATES = ("acting", "holding", "disarmed")

#: A hold of the sequence a model is asked: the setpoint (roll, pitch, yaw, deg), how long (s), and optionally
#: the controller's state (:data:`CONTROLLER_STATES`; "acting" if left out).
Hold = Tuple[Any, ...]


class StepRecord:
    """Attitudes (roll, pitch, yaw, rad) at times ``t`` (s from the record's start, sorted) with the setpoint's
    steps; ``source`` names it. ``ends``, one per step, says where its response ends (None: not read, see
    :func:`~quadruped_control.analysis.steps.response_ends`); by default each runs to the next step or the
    record's end. ``controller``: the times (s, same clock) from which the controller was in each state of
    :data:`CONTROLLER_STATES`, in order; by default acting throughout."""

    def __init__(self, t: np.ndarray, rpy: np.ndarray, steps: List[Step], source: str,
                 ends: Optional[List[Optional[float]]] = None,
                 controller: Optional[List[Tuple[float, str]]] = None) -> None:
        self.t, self.rpy, self.steps, self.source = t, rpy, steps, source
        #: the bag's gains_in_force from the first step to the record's end (None: not recorded)
        self.gains: Optional[Dict[str, Any]] = None
        self.controller = [(float(t[0]), "acting")] if not controller else list(controller)
        self.ends = response_ends(steps, (), float(t[-1])) if ends is None else list(ends)
        if len(self.ends) != len(steps):
            raise ValueError("a step record needs one end per step (%d steps, %d ends)" % (len(steps), len(self.ends)))

    def responses(self) -> List[Tuple[Step, StepResponse]]:
        """The response of each step that is read, to its end."""
        return [(step, step_response(self.t, self.rpy, step, end)) for step, end in zip(self.steps, self.ends)
                if end is not None]

    def unread(self) -> List[Step]:
        """The steps taken too soon after the controller stopped acting to be read."""
        return [step for step, end in zip(self.steps, self.ends) if end is None]


def gains_overrides(gains: Optional[Dict[str, Any]]) -> Tuple[Tuple[str, Any], ...]:
    """The controller configuration's overrides (TrialSpec.config_overrides) that make the experiment gain set the
    ``gains`` a record ran (parameter_updates' names: k_p ... t_pow_max, stroke_scheme); none for None. ParameterError
    for values the controller would refuse."""
    if not gains:
        return ()
    tunables = {k: float(v) for k, v in gains.items() if k in ("k_p", "k_i", "k_d", "k_aw", "tau_max", "t_rec",
                                                               "t_pow_max")}
    config = apply_tunables(load_controller_config(None, "experiment"), tunables)
    if gains.get("stroke_scheme"):
        config = config.replace(stroke_scheme=str(gains["stroke_scheme"]))
    return (("gains", config.gains), ("tau_max", config.tau_max), ("t_rec", config.t_rec),
            ("t_pow_max", config.t_pow_max), ("stroke_scheme", config.stroke_scheme))


def record_gains(record: "StepRecord", run_record: Optional[Dict[str, Any]]) -> Tuple[Optional[Dict[str, Any]], str]:
    """The gains the robot ran the record's steps with, and where they come from: the bag's parameter_updates in
    force at the first step (a change during the record is named: the models keep the first), else the run's
    run.yaml (``gains.at_arming``, else ``at_start``), else none (the models then run the experiment gain set)."""
    if record.gains is not None and record.gains["gains"] is not None:
        changes = record.gains["gain_changes"]
        return record.gains["gains"], "the bag's parameter_updates%s" % (
            "" if not changes else " (changed %d time(s) during the record; the models keep the first)" % len(changes))
    logged = (run_record or {}).get("gains") or {}
    recorded = logged.get("at_arming") or logged.get("at_start")
    if recorded:
        return dict(recorded), "the run's run.yaml (the bag has no parameter_updates)"
    return None, "the robot's unknown: no parameter_updates in the bag, no run.yaml"


def step_test_spec(tank_yaml: str, seed: int, overrides: Tuple[Tuple[str, Any], ...], noise_deg: float,
                   robot_yaml: Optional[str], start_deg: Sequence[float],
                   setpoint_deg: Optional[Sequence[float]] = None,
                   config_overrides: Tuple[Tuple[str, Any], ...] = ()) -> TrialSpec:
    """The trial the test runs: the robot's closed loop on the tank plant with the experiment gains (or those of
    ``config_overrides``: :func:`gains_overrides`) and rate-limited servos (Table 1's settings), starting at rest at
    ``start_deg`` with the setpoint ``setpoint_deg`` (default the start)."""
    start = tuple(float(v) for v in start_deg)
    setpoint = start if setpoint_deg is None else tuple(float(v) for v in setpoint_deg)
    return TrialSpec(label="step test", setpoint_rpy_deg=setpoint, initial_rpy_deg=start, duration=1.0, seed=seed,
                     gains="experiment", servo_model="rate-limited", plant="tank", tank_yaml=tank_yaml,
                     robot_yaml=robot_yaml, tank_overrides=overrides, attitude_noise_deg=noise_deg, quiet=True,
                     config_overrides=tuple(config_overrides))


def run_sequence(spec: TrialSpec, sequence: Sequence[Hold], source: str) -> StepRecord:
    """The closed loop of ``spec`` taken through ``sequence`` (setpoint rpy in deg, seconds held, and the
    controller's state if given: :data:`Hold`) from its start, as the robot is by the setpoints published in
    turn: the record of the attitude the IMU reports and the setpoint's steps. A hold "holding" turns the
    controller to its safe pose (the legs retrace to the nominal pose), "disarmed" stops it as disarming does
    (the servos keep their last command: :meth:`ClosedLoopSimulation.disarm`), and acting after "disarmed"
    clears it, as arming does. SimulationError if the loop cannot go on."""
    sim = trial_simulation(spec)
    times: List[np.ndarray] = []
    angles: List[np.ndarray] = []
    steps: List[Step] = []
    states: List[Tuple[float, str]] = []
    current = np.radians(spec.setpoint_rpy_deg)
    for hold in sequence:
        setpoint_deg, seconds = hold[0], hold[1]
        state = hold[2] if len(hold) > 2 else "acting"
        if state not in CONTROLLER_STATES:
            raise ValueError("a hold's controller state must be one of %s, got %r" % (CONTROLLER_STATES, state))
        if not states or states[-1][1] != state:
            if state == "disarmed":
                sim.disarm()
            else:
                sim.set_controller(state == "acting", reset=bool(states) and states[-1][1] == "disarmed")
            states.append((sim.time, state))
        setpoint = np.radians(setpoint_deg)
        # a step acts from the instant the setpoint changes (find_steps' rule for what counts as one)
        steps += find_steps([sim.time - sim.dt, sim.time], [current, setpoint])
        current = setpoint
        sim.set_setpoint(rpy_to_rot(*setpoint))
        result = sim.run(seconds)
        # each run's first sample is the previous run's last instant, measured again under the new setpoint
        first = 0 if not times else 1
        times.append(result.t[first:])
        angles.append(result.rpy[first:])
    return StepRecord(np.concatenate(times), np.concatenate(angles), steps, source, controller=states)


def controller_states(t: np.ndarray, armed: np.ndarray, holding: np.ndarray) -> List[Tuple[float, str]]:
    """The times (sorted ``t``) from which the controller was in each state of :data:`CONTROLLER_STATES`, from
    its samples' armed and holding flags: one entry per change, the first at ``t[0]``."""
    names = np.where(~armed, "disarmed", np.where(holding, "holding", "acting"))
    return [(float(t[k]), str(names[k])) for k in range(t.size) if k == 0 or names[k] != names[k - 1]]


def record_from_bag(paths: Sequence[str], source: str) -> StepRecord:
    """The steps of a recorded run (module docstring): the IMU's attitude (Z-Y-X, REP 103) and the setpoint
    of each /controller_state message while the controller was acting (armed and not holding its safe pose);
    once it has first acted, each step's response ends where it stopped acting, and a step taken soon after such
    a stop is not read (:func:`~quadruped_control.analysis.steps.response_ends`). StudyError if the bag lacks either
    stream."""
    data = read_bags(paths)
    if len(data.imu_t) < 2 or len(data.state_t) < 2:
        raise StudyError("step_test: %s needs /imu/data and /controller_state (got %d and %d messages)"
                         % (source, len(data.imu_t), len(data.state_t)))
    imu_t, rpy = attitude_rpy(data.imu_t, data.imu_q)
    all_state_t = np.asarray(data.state_t, dtype=float)
    armed, holding = np.asarray(data.state_armed, dtype=bool), np.asarray(data.state_holding, dtype=bool)
    acting = armed & ~holding
    state_t, setpoint_rpy = attitude_rpy(all_state_t[acting],
                                         np.asarray(data.state_setpoint, dtype=float).reshape(-1, 4)[acting])
    if imu_t.size < 2 or state_t.size < 2:
        raise StudyError("step_test: %s has fewer than two usable %s samples"
                         % (source, "/imu/data" if imu_t.size < 2 else "acting (armed, not holding) /controller_state"))
    start = float(imu_t[0])
    times = imu_t - start
    # a step the IMU's record ends at or before has no response to read (the recorder stopped first)
    steps = [step for step in find_steps(state_t - start, setpoint_rpy)
             if np.count_nonzero(times >= step.time) >= 2]
    if not steps:
        raise StudyError("step_test: the setpoint of %s never changed while the controller was acting (armed, not "
                         "holding) and the IMU recording" % source)
    order = np.argsort(all_state_t, kind="stable")
    order = order[np.isfinite(all_state_t[order])]
    state_times, acting_in_order = all_state_t[order] - start, acting[order]
    states = controller_states(state_times, armed[order], holding[order])
    # a hold or disarm before the controller first acted is the run's start, not a stop in the test
    stops = state_times[~acting_in_order & (state_times > np.min(state_times[acting_in_order]))]
    record = StepRecord(times, rpy, steps, source, response_ends(steps, stops, float(times[-1])), states)
    record.gains = gains_in_force(data, start + steps[0].time, math.inf)
    return record


def record_sequence(record: StepRecord) -> Tuple[List[float], List[float], List[Hold]]:
    """What the record asked of the robot, for a model to be asked the same: its first attitude and the
    setpoint before its first step (deg), then the holds (:data:`Hold`) from the record's start to its end: the
    setpoint (deg), how long, and the controller's state, a new hold at each step and at each change of the
    controller's state (a first step at the start is the first setpoint, held from there)."""
    start = [math.degrees(float(v)) for v in record.rpy[0]]
    first = [math.degrees(v) for v in record.steps[0].before]
    t0, t_end = float(record.t[0]), float(record.t[-1])
    changes = [step.time for step in record.steps] + [time for time, _ in record.controller]
    boundaries = sorted({t0, t_end} | {time for time in changes if t0 < time < t_end})
    sequence: List[Hold] = []
    for begin, end in zip(boundaries[:-1], boundaries[1:]):
        setpoint = first
        for step in record.steps:
            if step.time <= begin:
                setpoint = [math.degrees(v) for v in step.after]
        # before the record's first controller message, the state it reports first
        state = record.controller[0][1]
        for time, name in record.controller:
            if time <= begin:
                state = name
        if sequence and sequence[-1][0] == setpoint and sequence[-1][2] == state:
            sequence[-1] = (setpoint, sequence[-1][1] + end - begin, state)
        else:
            sequence.append((setpoint, end - begin, state))
    return start, first, sequence


def model_run(job: Tuple[Any, ...]) -> Dict[str, Any]:
    """One tank.yaml asked what the record asked of the robot (:func:`record_sequence`): from rest at the
    record's first attitude, the same setpoints held as long, with the record's gains (:func:`gains_overrides`; job:
    path, start, first, sequence, seed, tank overrides, noise, robot.yaml and optionally the config overrides); its
    steps' responses. A loop that cannot go on is reported, not raised."""
    path, start, first, sequence, seed, overrides, noise_deg, robot_yaml = job[:8]
    spec = step_test_spec(path, seed, overrides, noise_deg, robot_yaml, start, first, job[8] if len(job) > 8 else ())
    try:
        record = run_sequence(spec, sequence, os.path.basename(path))
    except SimulationError as exc:
        return {"tank_yaml": os.path.basename(path), "failed": str(exc)}
    return {"tank_yaml": os.path.basename(path), "record": record}


def _model_responses(run: Dict[str, Any], responses: Sequence[Tuple[Step, StepResponse]]) -> List[Dict[str, Any]]:
    """A model's run (:func:`model_run`) read step by step as the record is: per step of the record, the
    model's response to its own step at that time, for no longer than the record's (which a stop of the
    controller may cut short), with its stepped angle from the step on, for the figure."""
    name = run["tank_yaml"]
    if "failed" in run:
        return [{"tank_yaml": name, "failed": run["failed"]} for _ in responses]
    record: StepRecord = run["record"]
    # run_sequence reads every step of a model's run (the robot's stops cut it below, by the robot's duration)
    own: List[Tuple[Step, float]] = [(step, end) for step, end in zip(record.steps, record.ends) if end is not None]
    out = []
    for step, robot in responses:
        # the model's own step nearest in time: its holds are whole control periods, the record's are not
        match, end = min(own, key=lambda pair: abs(pair[0].time - step.time))
        response = step_response(record.t, record.rpy, match, min(end, match.time + robot.duration))
        out.append({"tank_yaml": name, "response": response.as_dict(),
                    "series": _series(record, match, response.duration)})
    return out


def _series(record: StepRecord, step: Step, duration: float, stride: int = 10) -> Dict[str, List[float]]:
    """The stepped angle (deg) for ``duration`` s from the step on, every ``stride``-th sample, for the figure."""
    keep = (record.t >= step.time - 1e-9) & (record.t <= step.time + duration + 1e-9)
    t = record.t[keep][::stride] - step.time
    return {"t": [round(float(v), 3) for v in t],
            "deg": [round(math.degrees(float(v)), 3) for v in record.rpy[keep, step.axis][::stride]]}


def _fmt(value: Optional[float]) -> str:
    return "--" if value is None else "%.1f" % value


def _text(report: Dict[str, Any]) -> str:
    lines = ["# Step test: %s" % report["source"], "",
             "Command: `%s`  " % " ".join(report["command"]),
             "Code: %s (fingerprint %s)" % (describe_source(report["code_source"]), report["code"]), "",
             ("Gains the models ran, from %s: %s." % (report["gains_source"], gains_text(report["gains"]))
              if report.get("gains") else "Gains the models ran: the experiment gain set (%s)."
              % report.get("gains_source", "")), "",
             "Settling time within 6 deg / within 2 deg (s from the step; --: not settled in the record), "
             "overshoot past the new setpoint (deg). A model agrees on a step when its 6 deg time is within 2x "
             "of the robot's, or neither settles (*: it does not).", ""]
    models = report["models"]
    header = "| step | record | " + " | ".join(m for m in models) + " |"
    lines += [header, "|" + "---|" * (2 + len(models))]
    for entry in report["steps"]:
        robot = entry["record"]
        label = "%s %g -> %g%s%s%s" % (robot["axis"], round(robot["before_deg"], 1), round(robot["after_deg"], 1),
                                       " (towards upright)" if robot["towards_upright"] else "",
                                       "" if entry["single_axis"] else " +", "" if entry["judged"] else " ~")
        cells = ["%s / %s, %.1f" % (_fmt(robot["settle_6"]), _fmt(robot["settle_2"]), robot["overshoot_deg"])]
        for model in entry["models"]:
            if "failed" in model:
                cells.append("failed")
                continue
            response = model["response"]
            cells.append("%s / %s, %.1f%s" % (_fmt(response["settle_6"]), _fmt(response["settle_2"]),
                                              response["overshoot_deg"], "" if model["agrees"] else " *"))
        lines.append("| %s | %s |" % (label, " | ".join(cells)))
    lines += ["", "Steps each model agrees on (of the %d that change one axis and run at least %g s; a step marked + "
              "changes more, and one marked ~ runs less, cut short by a stop of the controller or the record's end, "
              "in which nothing settles: neither is counted):" % (report["counted_steps"], SETTLING_HOLD), ""]
    for name, count in zip(models, report["agreement"]):
        lines.append("- %s: %d" % (name, count))
    if report.get("unread_steps"):
        lines += ["", "Not read: %d step(s) taken less than %g s after the controller stopped acting (disarmed or "
                  "holding its safe pose), at %s s. A response the controller stopped acting in is read up to the "
                  "stop, and each model's for as long." % (len(report["unread_steps"]), HOLD_CHECK,
                                                          ", ".join("%.1f" % step["time"]
                                                                    for step in report["unread_steps"]))]
    if report.get("truth"):
        lines += ["", "Simulated record: %s (seed %d, tank disturbance %s)."
                  % (report["truth"]["tank_yaml"], report["seed"], report["truth"]["disturbance"] or "none")]
    return "\n".join(lines + missing_text(report.get("missing", []))) + "\n"


def _plot(path: str, report: Dict[str, Any], record: StepRecord) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = report["steps"]
    columns = min(4, max(1, len(steps)))
    rows = int(math.ceil(len(steps) / columns)) or 1
    figure, axes = plt.subplots(rows, columns, figsize=(4.0 * columns, 3.0 * rows), squeeze=False)
    for k, entry in enumerate(steps):
        axis = axes[k // columns][k % columns]
        robot = entry["record"]
        step = Step(entry["time"], tuple(entry["before"]), tuple(entry["after"]))  # type: ignore[arg-type]
        series = _series(record, step, robot["duration"], stride=1)
        end = series["t"][-1] if series["t"] else 0.0
        axis.plot(series["t"], series["deg"], color="black", linewidth=1.5, label="record")
        for model in entry["models"]:
            if "series" in model:
                axis.plot(model["series"]["t"], model["series"]["deg"], linewidth=0.8, alpha=0.8,
                          label=model["tank_yaml"])
        target = robot["after_deg"]
        axis.axhspan(target - 6.0, target + 6.0, color="0.9")
        axis.set_xlim(0.0, max(end, 1.0))
        axis.set_title("%s %g -> %g deg" % (robot["axis"], round(robot["before_deg"], 1), round(target, 1)),
                       fontsize=9)
        axis.set_xlabel("s from the step", fontsize=8)
    for k in range(len(steps), rows * columns):
        axes[k // columns][k % columns].axis("off")
    handles, labels = axes[0][0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=min(5, len(labels)), fontsize=7)
    figure.tight_layout(rect=(0.0, 0.08, 1.0, 1.0))
    figure.savefig(path, dpi=90)
    plt.close(figure)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", nargs="?", metavar="RUN", help="the recorded test: a bag, a split recording's "
                        "parts joined by commas, or a tank day's folder (its step-test run)")
    parser.add_argument("--compare", nargs="*", default=None, metavar="YAML_OR_DIR",
                        help="tank.yaml files or folders of them to run on the same steps (default: the shipped "
                             "ensemble, config/%s)" % DEFAULT_FOLDER)
    parser.add_argument("--robot-yaml", default=None, help="robot parameters (default: config/robot.yaml)")
    parser.add_argument("--simulated", metavar="TRUTH_YAML", help="run the protocol on this tank.yaml instead")
    parser.add_argument("--tank-disturbance", nargs=2, type=float, metavar=("SIGMA", "TAU"),
                        help="a tank that pushes (N m, s): the --simulated truth's and every model's")
    parser.add_argument("--attitude-noise-deg", type=float, default=0.05,
                        help="the simulated IMU's attitude noise, deg (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="the simulated tank's and IMU's draw")
    parser.add_argument("--jobs", type=int, default=1, help="model runs in parallel processes (default 1)")
    parser.add_argument("--out", default="out/step_test", help="output folder (default %(default)s)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.attitude_noise_deg) and args.attitude_noise_deg >= 0.0):
        parser.error("--attitude-noise-deg must be >= 0, got %r" % (args.attitude_noise_deg,))
    if args.jobs < 1:
        parser.error("--jobs must be at least 1, got %d" % args.jobs)
    if bool(args.simulated) == bool(args.run):
        parser.error("give one recorded RUN or --simulated TRUTH_YAML")
    warn_uncommitted()
    overrides = disturbance_overrides(args.tank_disturbance)
    missing: List[str] = []
    gains, gains_source = None, "the simulated record's"
    try:
        compare = tank_files(args.compare if args.compare is not None else [config_path(DEFAULT_FOLDER)])
        if not compare:
            raise StudyError("step_test: --compare names no tank.yaml")
        member_tanks(compare + ([args.simulated] if args.simulated else []), overrides, 1)  # each file, the push
        if args.simulated:
            record = run_sequence(step_test_spec(args.simulated, args.seed, overrides, args.attitude_noise_deg,
                                        args.robot_yaml, (0.0, 0.0, 0.0)), PROTOCOL,
                                  "simulated: %s" % os.path.basename(args.simulated))
        else:
            source, run_record = args.run, None
            if is_folder(args.run):
                run, missing = one_run(args.run, "step_test", "step_test", needs=("/imu/data", "/controller_state"),
                                       wants=("/attitude_controller/parameter_updates",))
                source, run_record = run.source, run.record
            paths = [part for part in source.split(",") if part]
            for path in paths:
                if not os.path.isfile(path):
                    raise StudyError("step_test: no such bag: %s" % path)
            record = record_from_bag(paths, source)
            gains, gains_source = record_gains(record, run_record)
            if gains is None:
                missing.append("gains: %s; the models run the experiment gain set" % gains_source)
                sys.stderr.write("step_test: missing: %s\n" % missing[-1])
        config_overrides = gains_overrides(gains)
        responses = record.responses()
        start, first, sequence = record_sequence(record)
        jobs = [(path, start, first, sequence, args.seed + 1, overrides, args.attitude_noise_deg, args.robot_yaml,
                 config_overrides) for path in compare]
        if args.jobs > 1:
            with ProcessPoolExecutor(max_workers=min(args.jobs, len(jobs))) as pool:
                runs = list(pool.map(model_run, jobs))
        else:
            runs = [model_run(job) for job in jobs]
        model_responses = [_model_responses(run, responses) for run in runs]
    except (ParameterError, BagReportError, ValueError, SimulationError) as exc:
        sys.stderr.write("step_test: error: %s\n" % exc)
        return 1
    except StudyError as exc:
        sys.stderr.write("%s\n" % exc)
        return 1
    names = [os.path.basename(path) for path in compare]
    steps = []
    agreement = [0] * len(compare)
    for k, (step, response) in enumerate(responses):
        models = [entries[k] for entries in model_responses]
        for m, model in enumerate(models):
            model["agrees"] = "response" in model and agrees(model["response"]["settle_6"], response.settle_6)
            agreement[m] += int(model["agrees"] and step.single_axis and judged(response))
        steps.append({"time": step.time, "before": list(step.before), "after": list(step.after),
                      "single_axis": step.single_axis, "judged": judged(response), "record": response.as_dict(),
                      "models": models})
    report: Dict[str, Any] = {
        "study": "step_test", "command": command_line("quadruped_control.studies.step_test", argv), **code_record(),
        "source": record.source, "seconds": float(record.t[-1]), "seed": args.seed,
        "tank_overrides": [list(item) for item in overrides], "models": names, "steps": steps,
        "agreement": agreement, "single_axis_steps": sum(step.single_axis for step, _ in responses),
        "gains": gains, "gains_source": gains_source, "missing": missing,
        "counted_steps": sum(step.single_axis and judged(response) for step, response in responses)}
    report["unread_steps"] = [{"time": step.time, "before": list(step.before), "after": list(step.after)}
                              for step in record.unread()]
    if args.simulated:
        report["truth"] = {"tank_yaml": os.path.basename(args.simulated),
                           "disturbance": list(args.tank_disturbance) if args.tank_disturbance else None}
    write_study_report(args.out, "step_test", _text(report), report, lambda path: _plot(path, report, record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
