"""The batched engine (:mod:`quadruped_control.sim.batch`, with the batched controller of
:mod:`quadruped_control.sim.batch_controller` and plant of :mod:`quadruped_control.sim.plants.paper_batch`)
against the per-trial engine, trial by trial."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from quadruped_common import jit
from quadruped_common.so3 import rotations_to_rpy, rpy_to_rot
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.batch import BatchSimulation, BatchTrial
from quadruped_control.sim.servo_model import load_servo_params, make_servo_model
from quadruped_control.sim.simulation import ClosedLoopSimulation


@pytest.fixture(scope="module")
def robot():
    return load_robot_params()


def _cases():
    cases = []
    for gains in ("simulation", "experiment"):
        for rpy in ((45.0, 0.0, 0.0), (15.0, 15.0, 15.0), (0.0, 0.0, 75.0), (30.0, -20.0, 60.0)):
            for servo in ("ideal", "rate-limited"):
                cases.append((gains, rpy, servo))
    return cases


def _assert_states_agree(result, i, out, what):
    """Every state (R, omega, p, servo angles) of batch trial ``i`` against the per-trial result, bit for
    bit: both engines run the same functions (compiled or not), and the norms are squares, sums and sqrt
    (jit.hypot3), which round the same everywhere."""
    states = result.states
    for name, expected, got in (("R", out.rotation, states["rotation"][i]), ("omega", out.omega, states["omega"][i]),
                                ("p", out.position, states["position"][i]),
                                ("q", out.joint_positions, states["joints"][i].reshape(-1, 12))):
        error = float(np.max(np.abs(expected - got)))
        assert error == 0.0, "%s: %s differs by %.3g" % (what, name, error)


def test_batch_states_agree_with_the_per_trial_engine_bit_for_bit_over_10_s(robot):
    """Every state (p, v, R, omega, servo angles) of 16 mixed trials (both gain sets, both servo models,
    roll/yaw/combined setpoints, a tilted start) against the per-trial engine, sample by sample."""
    servo_params = load_servo_params()
    configs = {g: load_controller_config(None, g) for g in ("simulation", "experiment")}
    cases = _cases()
    initial = [rpy_to_rot(*np.radians((10.0 * (i % 3), -5.0 * (i % 2), 0.0))) for i in range(len(cases))]
    trials = [BatchTrial(config=configs[g], setpoint=rpy_to_rot(*np.radians(rpy)), initial=initial[i],
                         servo_model=servo, servo_params=servo_params) for i, (g, rpy, servo) in enumerate(cases)]
    duration = 10.0
    result = BatchSimulation(robot, trials).run(duration, record_states=1001)
    assert not result.failed.any() and not result.refused.any() and not result.ik_fallbacks.any()
    for i, (g, rpy, servo) in enumerate(cases):
        sim = ClosedLoopSimulation(robot, configs[g], make_servo_model(servo, servo_params),
                                   initial_R=initial[i], setpoint_R=rpy_to_rot(*np.radians(rpy)))
        out = sim.run(duration)
        _assert_states_agree(result, i, out, "%s %s %s" % (g, rpy, servo))
        # The recorded angles: the batch's so3.rpy_f per sample, the per-trial result numpy's vectorised
        # form over all samples (the same arithmetic).
        np.testing.assert_array_equal(result.geodesic[i], out.geodesic)
        np.testing.assert_array_equal(result.rpy[i], out.rpy)


def test_ideal_only_batch_does_not_alias_the_controller_targets(robot):
    """Regression: with only ideal servos the joint state once aliased the controller's target array."""
    config = load_controller_config(None, "simulation")
    trial = BatchTrial(config=config, setpoint=rpy_to_rot(*np.radians((45.0, 45.0, 45.0))))
    result = BatchSimulation(robot, [trial]).run(2.0)
    out = ClosedLoopSimulation(robot, config, setpoint_R=trial.setpoint).run(2.0)
    np.testing.assert_allclose(result.geodesic[0], out.geodesic, rtol=0, atol=1e-15)


def test_a_diverging_trial_is_flagged_and_frozen_without_stopping_the_others(robot):
    config = load_controller_config(None, "simulation")
    good = BatchTrial(config=config, setpoint=rpy_to_rot(0.5, 0.0, 0.0))
    sim = BatchSimulation(robot, [good, good])
    sim.step()
    sim.omega[1] = [math.inf, 0.0, 0.0]  # what a blown-up integration leaves
    result = sim.run(0.5)
    assert result.refused.tolist() == [False, True] or result.failed.tolist() == [False, True]
    assert not result.trusted(1) and result.trusted(0)
    assert np.isfinite(result.geodesic[0]).all()


def test_batch_refuses_what_it_does_not_run(robot):
    config = load_controller_config(None, "simulation")
    with pytest.raises(ValueError, match="attitude_noise"):
        BatchSimulation(robot, [BatchTrial(config=config, setpoint=np.eye(3), attitude_noise=-1.0)])
    with pytest.raises(ValueError, match="share dt"):
        BatchSimulation(robot, [BatchTrial(config=config, setpoint=np.eye(3)),
                                BatchTrial(config=config.replace(dt=0.02), setpoint=np.eye(3))])
    with pytest.raises(ValueError, match="servo_params"):
        BatchSimulation(robot, [BatchTrial(config=config, setpoint=np.eye(3), servo_model="rate-limited")])
    with pytest.raises(ValueError, match="unknown servo"):
        BatchSimulation(robot, [BatchTrial(config=config, setpoint=np.eye(3), servo_model="fast")])
    with pytest.raises(ValueError, match="duration"):
        BatchSimulation(robot, [BatchTrial(config=config, setpoint=np.eye(3))]).run(float("nan"))


def _objects_cases():
    """(scheme, controller on, attitude noise rad, gyro noise rad/s, seed, setpoint rpy deg, servo)."""
    return [("coordinated", True, 0.0, 0.0, 0, (45.0, 0.0, 0.0), "rate-limited"),
            ("coordinated", True, 0.0, 0.0, 0, (15.0, 15.0, 15.0), "ideal"),
            ("coordinated", True, math.radians(0.5), 0.01, 7, (0.0, 0.0, 75.0), "rate-limited"),
            ("paper", False, 0.0, 0.0, 0, (30.0, 0.0, 0.0), "ideal"),
            ("paper", True, math.radians(1.0), 0.02, 3, (30.0, -20.0, 60.0), "rate-limited")]


@pytest.mark.parametrize("plant", ["paper", "tank"])
def test_controller_objects_batch_agrees_with_the_per_trial_engine_bit_for_bit_over_10_s(robot, plant):
    """The coordinated scheme, IMU noise and the controller off (the robot's own controller objects
    inside the batch) against the per-trial engine: every state bit for bit over 10 s, and the stroke
    metrics of the schemes study."""
    from quadruped_control.sim.plants.tank import TankModel
    from quadruped_control.sim.plants.tank_params import load_tank_params
    from quadruped_control.studies.trial import stroke_metrics

    servo_params = load_servo_params()
    base = load_controller_config(None, "experiment")
    tank = load_tank_params() if plant == "tank" else None
    cases = _objects_cases()
    trials, sims = [], []
    for i, (scheme, on, attitude_noise, gyro_noise, seed, rpy, servo) in enumerate(cases):
        config = base.replace(stroke_scheme=scheme)
        initial = rpy_to_rot(*np.radians((5.0 * i, -3.0, 10.0)))
        setpoint = rpy_to_rot(*np.radians(rpy))
        trials.append(BatchTrial(config=config, setpoint=setpoint, initial=initial, servo_model=servo,
                                 servo_params=servo_params, tank=tank, attitude_noise=attitude_noise,
                                 gyro_noise=gyro_noise, seed=seed, controller_enabled=on))
        sims.append(ClosedLoopSimulation(robot, config, make_servo_model(servo, servo_params), initial_R=initial,
                                         setpoint_R=setpoint, seed=seed, attitude_noise=attitude_noise,
                                         gyro_noise=gyro_noise, controller_enabled=on,
                                         model=TankModel(robot, tank) if tank is not None else None))
    result = BatchSimulation(robot, trials).run(10.0, record_states=1001, stroke_metrics=True)
    assert not result.failed.any() and not result.refused.any()
    for i, sim in enumerate(sims):
        out = sim.run(10.0)
        _assert_states_agree(result, i, out, "case %r" % (cases[i],))
        expected = stroke_metrics(out, robot)
        for key, value in expected.items():
            assert result.stroke_metrics[i][key] == pytest.approx(value, rel=1e-9, abs=1e-12), (cases[i], key)
        if cases[i][0] == "coordinated":
            assert 0.0 < expected["power_fraction"] < 1.0 and expected["torque_commanded_mean"] > 0.0


def test_tank_batch_agrees_with_the_per_trial_tank_plant_bit_for_bit_over_10_s(robot):
    """Five Table-1 trials on the tank plant, each with its own tank parameters (the identified set,
    and variations that switch on every candidate effect), against the per-trial engine."""
    import argparse

    from quadruped_control.sim.plants.tank_params import load_tank_params
    from quadruped_control.studies.paper_experiments import experiment_specs
    from quadruped_control.studies.trial import trial_setup

    args = argparse.Namespace(seed=0, tank_yaml=None, robot_yaml=None)
    specs, _ = experiment_specs(args, "tank", "experiment", "rate-limited", 10.0, keep_trace=False)
    specs = specs[::3]
    base = load_tank_params()
    tanks = [base,
             base.with_values(appendage_damping_linear=(0.02, 0.03, 0.01), appendage_damping_quadratic=(0.05, 0.05, 0.1),
                              body_wake_fraction=0.6, body_wake_time_constant=2.0, block_mass=0.3, block_drag=2.0,
                              hook_friction_arm=0.003, hook_friction_angle=0.002, hook_friction_static_ratio=1.8,
                              hook_friction_stribeck_rate=0.05, hook_friction_roll_ratio=2.2,
                              imu_field_residual=(0.2, -0.5, 0.6), tether_stiffness=0.005,
                              tether_relaxing_stiffness=0.03, tether_relaxation_time=5.0),
             base.with_values(rope_torsion_stiffness=0.05, rope_torsion_damping=0.02, paw_drag_scale=0.6,
                              rope_torsion_relaxing_stiffness=0.03, rope_torsion_relaxation_time=4.0,
                              paw_wake_fraction=0.5, paw_wake_time_constant=0.2, paw_wake_body_share=0.3,
                              servo_stall_torque=3.9, paw_buoyancy_offset=0.06, hook_friction_arm=0.002,
                              hook_friction_wrap=0.4, disturbance_torque_std=0.008,
                              disturbance_correlation_time=4.0, disturbance_seed=3),
             base.with_values(added_mass_scale=3.0, paw_added_mass_scale=2.0, net_weight=2.0, servo_stall_torque=1.5,
                              block_mass=1.0, block_drag=10.0, block_tie_stiffness=5.0, servo_dead_band=0.01),
             base.with_values(suspension=False, hydrostatics=False, disturbance_torque_std=0.003,
                              disturbance_correlation_time=0.7)]
    trials, sims = [], []
    for spec, tank in zip(specs, tanks):
        setup = trial_setup(spec)
        from quadruped_control.sim.plants.tank import TankModel
        model = TankModel(setup.robot, tank)
        initial = rpy_to_rot(*np.radians(spec.initial_rpy_deg))
        setpoint = rpy_to_rot(*np.radians(spec.setpoint_rpy_deg))
        # as trial_setup passes a tank's loaded servos and dead band to the servo model
        servo_params = dataclasses.replace(setup.servo_params, stall_torque=tank.servo_stall_torque,
                                           dead_band=tank.servo_dead_band)
        trials.append(BatchTrial(config=setup.config, setpoint=setpoint, initial=initial,
                                 servo_model=spec.servo_model, servo_params=servo_params, tank=tank))
        sims.append(ClosedLoopSimulation(setup.robot, setup.config,
                                         make_servo_model(spec.servo_model, servo_params),
                                         initial_R=initial, setpoint_R=setpoint, model=model))
    result = BatchSimulation(robot, trials).run(10.0, record_states=1001)
    assert not result.failed.any() and not result.refused.any()
    for i, sim in enumerate(sims):
        out = sim.run(10.0)
        _assert_states_agree(result, i, out, "trial %d (%s)" % (i, specs[i].label))
        # the attitude the metrics are taken from: as the IMU reports it (trial 1's heading turned)
        assert np.array_equal(result.rpy[i], out.rpy) and np.array_equal(result.geodesic[i], out.geodesic)
        assert (out.reported_rotation is not None) == (i == 1)
    # and it is not the true attitude there: the heading differs by more than a milliradian somewhere
    assert np.max(np.abs(result.rpy[1, :, 2] - rotations_to_rpy(result.states["rotation"][1])[:, 2])) > 1e-3


@pytest.mark.skipif(not jit.AVAILABLE, reason="numba is not installed: the batch already runs the plain functions")
@pytest.mark.parametrize("plant, plain", [("paper", "plant"), ("tank", "plant"), ("paper", "controller and servos")])
def test_compiled_loops_compute_what_their_plain_python_computes(robot, plant, plain, monkeypatch):
    """Each numba-compiled loop over trials against the same source run as plain Python (``py_func``,
    whose callees are the plain functions), from a mid-manoeuvre state of three trials: 150 steps of
    states and joint targets to 1e-12."""
    from quadruped_control.sim import batch as sim_batch
    from quadruped_control.sim import batch_controller
    from quadruped_control.sim.plants import paper_batch, tank_batch
    from quadruped_control.sim.plants.tank_params import load_tank_params
    from quadruped_control.sim.servo_model import load_servo_params

    config = load_controller_config(None, "experiment")
    # the tank with its loaded servos on (the plant computes the joint loads, the servo step reads them)
    tank = load_tank_params().with_values(servo_stall_torque=2.0, servo_dead_band=0.005, hook_friction_arm=0.002,
                                          hook_friction_static_ratio=1.5, hook_friction_roll_ratio=0.6,
                                          hook_friction_wrap=0.3) \
        if plant == "tank" else None
    servo_params = dataclasses.replace(load_servo_params(), stall_torque=2.0 if plant == "tank" else 0.0,
                                       dead_band=0.005 if plant == "tank" else 0.0)
    trials = [BatchTrial(config=config, setpoint=rpy_to_rot(*np.radians(rpy)), tank=tank, servo_model=servo,
                         servo_params=servo_params)
              for rpy, servo in (((45.0, 0.0, 0.0), "ideal"), ((0.0, 30.0, 20.0), "rate-limited"),
                                 ((10.0, -20.0, 60.0), "rate-limited"))]
    if plain == "plant":
        patched = [(paper_batch, "paper_batch_step")] if plant == "paper" else [(tank_batch, "tank_batch_step")]
    else:
        patched = [(batch_controller, "controller_batch_step"), (sim_batch, "servo_batch_step")]
    runs = []
    for compiled in (True, False):
        if not compiled:
            for module, name in patched:
                monkeypatch.setattr(module, name, getattr(module, name).py_func)
        sim = BatchSimulation(robot, trials)
        for _ in range(150):
            sim.step()
        runs.append(np.concatenate((sim.position, sim.velocity, sim.rotation.reshape(-1, 9), sim.omega,
                                    sim.q.reshape(-1, 12)), axis=1))
    assert np.abs(runs[0]).max() > 0.0
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-12)


@pytest.mark.parametrize("study", ["paper-sim", "table1 paper", "table1 tank"])
def test_every_trial_of_the_paper_studies_agrees_bit_for_bit_over_10_s(robot, study):
    """The issue's agreement: the first 10 s of each paper-sim trial and of each Table-1 trial on both
    plants, every state, batch against per trial."""
    import argparse
    import dataclasses

    from quadruped_control.sim.simulation import load_simulation_tree
    from quadruped_control.studies.paper_experiments import experiment_specs
    from quadruped_control.studies.paper_sim import paper_sim_specs
    from quadruped_control.studies.trial import trial_setup

    args = argparse.Namespace(seed=0, tank_yaml=None, robot_yaml=None, duration_given=False, restoring_offset=None)
    if study == "paper-sim":
        specs = paper_sim_specs(args, load_simulation_tree(), None, keep_trace=False)
    else:
        specs, _ = experiment_specs(args, study.split()[1], "experiment", "rate-limited", 10.0, keep_trace=False)
    specs = [dataclasses.replace(spec, duration=10.0) for spec in specs]
    setups = [trial_setup(spec) for spec in specs]
    trials = [BatchTrial(config=setup.config, setpoint=rpy_to_rot(*np.radians(spec.setpoint_rpy_deg)),
                         initial=rpy_to_rot(*np.radians(spec.initial_rpy_deg)), servo_model=spec.servo_model,
                         servo_params=setup.servo_params,
                         tank=setup.model.tank if setup.model is not None else None)
              for spec, setup in zip(specs, setups)]
    result = BatchSimulation(setups[0].robot, trials).run(10.0, record_states=1001)
    assert not result.failed.any() and not result.refused.any()
    for i, (spec, setup, trial) in enumerate(zip(specs, setups, trials)):
        out = ClosedLoopSimulation(setup.robot, setup.config, make_servo_model(spec.servo_model, setup.servo_params),
                                   initial_R=trial.initial, setpoint_R=trial.setpoint, model=setup.model).run(10.0)
        _assert_states_agree(result, i, out, "%s %s" % (study, spec.label))
