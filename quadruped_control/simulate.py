"""Offline closed-loop simulator CLI (no ROS needed): ``python3 -m quadruped_control.simulate``.

Single trial (defaults: the paper's simulation gains and ideal servos, RK4 at dt = 0.01 s)::

    python3 -m quadruped_control.simulate --rpy 45 45 45 --duration 120 --out /tmp/trial

writes ``DIR/timeseries.csv``, ``DIR/metrics.json`` and ``DIR/attitude.png`` and prints a metrics table.

Studies:

- ``--study paper-sim``: the paper's section "Simulation Validation": setpoints 15, 45 and 75 degrees
  applied simultaneously to roll, pitch and yaw, simulation gains (K_p = 5, K_i = 0.15, K_d = 1,
  K_aw = 0.25, t_rec = 1.5 s), RK4 at 0.01 s. The paper gives neither the initial attitude nor the
  trial length: level at rest and 120 s (``paper_sim`` in config/simulation.yaml). Writes
  ``DIR/paper_sim.png`` (three trials in one figure), ``DIR/study.json`` and each trial's files in
  ``DIR/trial_<deg>/``.
- ``--study robustness``: the same setpoints under +-0.5 degree initial-attitude perturbations
  (several seeds), with the experiment gains (ideal and rate-limited servos), with the normalised force
  direction, with the rate-limited servo, and with the estimated robot parameters that matter varied
  (paw net buoyancy, leg pairing, nominal foot height): ``DIR/robustness.json`` and ``DIR/robustness.md``.

``--robot-yaml PATH`` replaces config/robot.yaml for plant and controller alike (single trials and both
studies; the robustness study varies its estimates around that file), e.g. to compare candidate
estimates without editing the package configuration.

This module is the command line only: each study is a module of :mod:`quadruped_control.studies`
(:data:`STUDIES`), and a single trial is :func:`quadruped_control.studies.trial.run_trial`.

Trials of a study run through :mod:`quadruped_control.studies` on worker processes (``--jobs``, default:
the number of CPUs, max 2 here) or on an existing Dask cluster (``--dask-scheduler ADDRESS``), with a
progress bar and ETA on stderr. Each finished trial is kept in ``DIR/trials/``; rerunning a study with the
same ``--out`` skips the trials already finished (``--no-resume`` runs them all again).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Optional, Sequence

from quadruped_common.config import ParameterError
from quadruped_control.control.strokes import SCHEMES
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants import PLANTS, VALIDITY_NOTE
from quadruped_control.sim.simulation import SimulationError, load_simulation_settings
from quadruped_control.studies import StudyError, ensemble, identify, paper_experiments, paper_sim, robustness, schemes
from quadruped_control.studies.runner import command_line, warn_uncommitted
from quadruped_control.studies.trial import AUTO_BATCH_MIN, GAIN_ALIASES, TrialSpec, format_metrics_table, run_trial

#: --study NAME -> its module (each has ``main_study(args) -> exit status``)
STUDIES = {"paper-sim": paper_sim, "robustness": robustness, "schemes": schemes,
           "paper-experiments": paper_experiments, "identify": identify, "ensemble": ensemble}

#: The studies after which ``--plant tank`` prints :data:`VALIDITY_NOTE`: those that run on the plant
#: ``--plant`` names. paper-experiments (on the tank by default) writes the note into its own report;
#: identify measures the tank plant against the robot and reports its own figures.
NOTE_AFTER_STUDIES = ("paper-sim", "robustness", "schemes")

__all__ = ["NOTE_AFTER_STUDIES", "STUDIES", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python3 -m quadruped_control.simulate",
                                     description="Offline closed-loop simulation of the underwater quadruped's "
                                                 "attitude controller (the paper's model, no ROS).")
    parser.add_argument("--rpy", nargs=3, type=float, metavar=("R", "P", "Y"), default=[45.0, 45.0, 45.0],
                        help="setpoint roll pitch yaw, degrees (default 45 45 45)")
    parser.add_argument("--initial-rpy", nargs=3, type=float, metavar=("R", "P", "Y"), default=[0.0, 0.0, 0.0],
                        help="initial roll pitch yaw, degrees (default level)")
    parser.add_argument("--duration", type=float, default=None, help="trial length, s (default 120)")
    parser.add_argument("--gains", choices=("sim", "experiment"), default=None,
                        help="paper gain set: sim (K_p 5, K_i 0.15, K_d 1) or experiment (K_p 10, K_i 3, K_d 0.5); "
                             "default sim, experiment for --study paper-experiments")
    parser.add_argument("--servo-model", choices=("ideal", "rate-limited"), default=None,
                        help="servo model (default from config/simulation.yaml: ideal, the paper's)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the IMU noise and, in a tank.yaml with a disturbance, of its draw (0: the "
                             "tank's own; default 0); the identification's search is seeded with it too")
    parser.add_argument("--attitude-noise", type=float, default=None, metavar="DEG",
                        help="IMU attitude noise std, degrees (default from config: 0)")
    parser.add_argument("--gyro-noise", type=float, default=None, metavar="RAD_S",
                        help="gyro noise std per axis, rad/s (default from config: 0)")
    parser.add_argument("--normalize-force", action="store_true",
                        help="normalise the allocation's force direction tau_hat x r_hat (not in the paper)")
    parser.add_argument("--restoring-offset", nargs=3, type=float, metavar=("X", "Y", "Z"), default=None,
                        help="centre of buoyancy relative to the centre of mass, body frame, m (default: none)")
    parser.add_argument("--plant", choices=PLANTS, default=None,
                        help="plant model: paper (the paper's idealised model; default) or tank (the robot on "
                             "its rope in the test tank, config/tank.yaml)")
    parser.add_argument("--tank-yaml", default=None, metavar="PATH",
                        help="tank parameters for --plant tank (default: the package's config/tank.yaml)")
    parser.add_argument("--tank-ensemble", default=None, metavar="DIR",
                        help="ensemble study: a folder of tank.yaml files, Table 1 on each (default: the package's "
                             "config/tank_ensemble, the sets fitted to Table 1)")
    parser.add_argument("--draws", type=int, default=1, metavar="N",
                        help="ensemble study: run every member N times, trial seeds --seed to --seed + N - 1, each "
                             "another draw of a disturbed tank's disturbance (default 1)")
    parser.add_argument("--tank-disturbance", nargs=2, type=float, default=None, metavar=("SIGMA", "TAU"),
                        help="ensemble study: every member in a tank that is not still, a disturbance torque of "
                             "standard deviation SIGMA N m per axis and correlation time TAU s (tank.yaml's "
                             "disturbance section; default: each member's own)")
    parser.add_argument("--controller", choices=("on", "off"), default="on",
                        help="off holds the legs at the nominal pose (passive dynamics, ballast checks)")
    parser.add_argument("--robot-yaml", default=None, metavar="PATH",
                        help="robot model parameters for plant and controller (default: the package's "
                             "config/robot.yaml); the robustness study varies its estimates around this file")
    parser.add_argument("--scheme", choices=SCHEMES, default=None,
                        help="stroke scheme (default: stroke.scheme of config/controller.yaml, 'paper')")
    parser.add_argument("--screen", type=int, default=8,
                        help="identify: Morris screening trajectories, >= 2 (default 8: 8 x (parameters + 1) sets)")
    parser.add_argument("--evaluations", type=int, default=1000,
                        help="identify: CMA-ES budget of the full fit, parameter sets (default 1000)")
    parser.add_argument("--cv-evaluations", type=int, default=300,
                        help="identify: CMA-ES budget of each cross-validation fold (default 300)")
    parser.add_argument("--polish-evaluations", type=int, default=0,
                        help="identify: after each CMA-ES fit (full and folds), a compass search from its best set "
                             "with this budget, parameter sets (default 0: none, as the runs before it)")
    parser.add_argument("--popsize", type=int, default=16,
                        help="identify: CMA-ES population, also the baseline's grid size (default 16)")
    parser.add_argument("--ensemble", type=int, default=8,
                        help="identify: parameter sets kept as the ensemble (default 8)")
    parser.add_argument("--include", nargs="+", default=[], metavar="PARAMETER",
                        help="identify: parameters fitted whatever the screening says (e.g. a candidate effect "
                             "under test: --include paw_wake_fraction paw_wake_time_constant)")
    parser.add_argument("--parameters", nargs="+", default=[], metavar="PARAMETER",
                        help="identify: fit exactly these parameters (the screening still runs and is "
                             "reported; to repeat an earlier run's choice with another budget)")
    parser.add_argument("--start", choices=identify.STARTS, default="screening",
                        help="identify: where every fit starts: the screening's best set (the full fit) or its best "
                             "on the fold's training groups (default, as the runs before it), or the nominal values "
                             "of --tank-yaml (the same start whatever other candidates the screening spans)")
    parser.add_argument("--slow-recovery-check", action="store_true",
                        help="identify: the paper's t_rec observation as three more experiments: pitch 75, 90 and "
                             "roll+pitch 60 with t_rec = 1.5 s must not settle (the paper needed 1.0 s there)")
    parser.add_argument("--band", type=float, default=1.0, metavar="FACTOR",
                        help="identify: count each timing term only beyond this factor of the paper's, "
                             "max(0, |ln ratio| - ln FACTOR) (default 1: the whole log-ratio; 2 is the reproduction targets' band)")
    parser.add_argument("--study", choices=tuple(STUDIES),
                        default=None,
                        help="run a study (paper-experiments: Table 1's 15 experiments, default on the tank plant "
                             "with the experiment gains and rate-limited servos; ensemble: Table 1 on each "
                             "member of --tank-ensemble)")
    parser.add_argument("--perturbed", type=int, default=1,
                        help="schemes study: perturbed (+-0.5 deg) starts per case besides the nominal one (default 1)")
    parser.add_argument("--scheme-groups", default="paper-sim,table1,random",
                        help="schemes study: case groups (default %(default)s)")
    parser.add_argument("--scheme-gains", default="simulation,experiment",
                        help="schemes study: gain sets (default %(default)s)")
    parser.add_argument("--scheme-servos", default="ideal,rate-limited",
                        help="schemes study: servo models (default %(default)s)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                        help="worker processes for studies (default %(default)s)")
    parser.add_argument("--dask-scheduler", default=None, metavar="ADDRESS",
                        help="run a study's trials on an existing Dask cluster (e.g. tcp://host:8786) "
                             "instead of local processes")
    parser.add_argument("--engine", choices=("auto", "trial", "batch"), default="auto",
                        help="studies: 'trial' runs each trial on its own, 'batch' runs them together on the "
                             "batched simulator, 'auto' (default) batches a study of at least %d trials the "
                             "batch can run" % AUTO_BATCH_MIN)
    parser.add_argument("--batch-size", type=int, default=1500, metavar="N",
                        help="batched engine: at most N trials per batch (default %(default)s; the record costs about "
                             "0.2 MB per trial and simulated minute)")
    parser.add_argument("--no-resume", dest="resume", action="store_false",
                        help="run every trial of a study again instead of reusing DIR/trials/*.json")
    parser.add_argument("--out", default="simulation_output", help="output directory (default %(default)s)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    #: the command as given, for the studies' reports
    args.command = command_line("quadruped_control.simulate", argv)
    args.duration_given = args.duration is not None
    if args.gains is None:
        args.gains = "experiment" if args.study == "paper-experiments" else "sim"
    args.servo_model_given = args.servo_model
    if args.duration is None:
        args.duration = 120.0
    if not (math.isfinite(args.duration) and args.duration > 0.0):
        parser.error("--duration must be a positive number of seconds")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.plant == "tank" and args.restoring_offset is not None:
        parser.error("--restoring-offset is the paper plant's option; the tank plant's centre of buoyancy "
                     "is hydrostatics.center_of_buoyancy in config/tank.yaml (--tank-yaml)")
    for name in ("rpy", "initial_rpy", "restoring_offset"):
        value = getattr(args, name)
        if value is not None and not all(math.isfinite(v) for v in value):
            parser.error("--%s needs finite numbers" % name.replace("_", "-"))
    try:
        if args.robot_yaml is not None:
            args.robot_yaml = os.path.abspath(args.robot_yaml)
            load_robot_params(args.robot_yaml)  # fail early (exit 1) on a missing or invalid file
        settings = load_simulation_settings()
        if args.servo_model is None:
            args.servo_model = settings.servo_model
        attitude_noise = math.degrees(settings.attitude_noise) if args.attitude_noise is None else args.attitude_noise
        gyro_noise = settings.gyro_noise if args.gyro_noise is None else args.gyro_noise
        if attitude_noise < 0.0 or gyro_noise < 0.0 or not (math.isfinite(attitude_noise) and math.isfinite(gyro_noise)):
            parser.error("noise levels must be finite and non-negative")
        if args.study == "identify" and (args.screen < 2 or args.evaluations < 2 or args.cv_evaluations < 2
                                         or args.popsize < 2 or args.ensemble < 1):
            parser.error("identify needs --screen, --evaluations, --cv-evaluations and --popsize >= 2 and "
                         "--ensemble >= 1")
        if args.study == "identify" and args.polish_evaluations < 0:
            parser.error("--polish-evaluations must be >= 0 (0: no polish), got %d" % args.polish_evaluations)
        if args.study == "identify" and not (math.isfinite(args.band) and args.band >= 1.0):
            parser.error("--band must be a factor >= 1 (1: the whole log-ratio), got %r" % (args.band,))
        if args.study == "identify":
            from quadruped_control.studies.identify_parameters import PARAMETERS
            for option in ("include", "parameters"):
                unknown = sorted(set(getattr(args, option)) - {name for name, _, _ in PARAMETERS})
                if unknown:
                    parser.error("--%s: unknown parameter(s) %s" % (option, ", ".join(unknown)))
            if args.include and args.parameters:
                parser.error("--include adds to the screening's choice, --parameters replaces it: give one")
            if len(set(args.parameters)) == 1:  # pycma: "optimization in 1-D is not supported" (pycma issue 86)
                parser.error("--parameters: CMA-ES fits two or more parameters; name a second one")
        for option, given in (("--tank-ensemble", args.tank_ensemble is not None), ("--draws", args.draws != 1),
                              ("--tank-disturbance", args.tank_disturbance is not None)):
            if given and args.study != "ensemble":
                parser.error("%s is the ensemble study's (--study ensemble)" % option)
        if args.study is not None:
            warn_uncommitted()  # before any trial runs: a dirty tree's figures name no commit
            status = STUDIES[args.study].main_study(args)
            if args.plant == "tank" and args.study in NOTE_AFTER_STUDIES:
                print("note: %s" % VALIDITY_NOTE)
            return status
        spec = TrialSpec(label="setpoint %s deg" % " ".join("%g" % v for v in args.rpy),
                         setpoint_rpy_deg=tuple(args.rpy), initial_rpy_deg=tuple(args.initial_rpy),
                         duration=args.duration, gains=GAIN_ALIASES[args.gains], servo_model=args.servo_model,
                         seed=args.seed, normalize_force=args.normalize_force,
                         restoring_offset=tuple(args.restoring_offset) if args.restoring_offset else None,
                         attitude_noise_deg=attitude_noise, gyro_noise=gyro_noise, out_dir=args.out,
                         robot_yaml=args.robot_yaml, quiet=args.quiet, scheme=args.scheme, plant=args.plant or "paper",
                         tank_yaml=args.tank_yaml, controller=args.controller)
        summary = run_trial(spec)
    except (ParameterError, SimulationError, StudyError, ValueError) as exc:
        sys.stderr.write("simulate: error: %s\n" % exc)
        return 1
    print(format_metrics_table(summary["metrics"], "%s, %s plant, %s gains, %s servos, %s strokes, %.0f s (%.0fx real time)"
                               % (spec.label, spec.plant, spec.gains, spec.servo_model, summary["scheme"], spec.duration,
                                  summary["real_time_factor"])))
    print("wrote %s/{timeseries.csv, metrics.json, attitude.png}" % args.out)
    if spec.plant == "tank":
        print("note: %s" % VALIDITY_NOTE)
    return 0


if __name__ == "__main__":
    sys.exit(main())
