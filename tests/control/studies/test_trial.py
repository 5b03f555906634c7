"""studies.trial: the batched path (run_batch) gives the summaries of the per-trial path (run_trial)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from quadruped_common.so3 import rotations_to_rpy, rpy_to_rot
from quadruped_control.sim.simulation import SimulationError
from quadruped_control.studies.trial import TrialSpec, batch_unsupported, run_batch, run_trial, trial_setup


def _specs():
    return [TrialSpec(label="roll", setpoint_rpy_deg=(30.0, 0.0, 0.0), duration=6.0, quiet=True, keep_trace=True),
            TrialSpec(label="yaw exp", setpoint_rpy_deg=(0.0, 0.0, 40.0), initial_rpy_deg=(5.0, 0.0, 0.0), duration=6.0,
                      gains="experiment", servo_model="rate-limited", quiet=True, keep_trace=False),
            TrialSpec(label="tank", setpoint_rpy_deg=(0.0, 20.0, 0.0), duration=6.0, plant="tank",
                      tank_overrides=(("paw_drag_scale", 0.7),), gains="experiment", servo_model="rate-limited",
                      quiet=True, keep_trace=False),
            TrialSpec(label="short", setpoint_rpy_deg=(10.0, 10.0, 0.0), duration=3.0, quiet=True, keep_trace=False)]


def test_run_batch_gives_the_per_trial_metrics_for_mixed_plants_and_durations():
    specs = _specs()
    batched = run_batch(specs)
    assert [s["label"] for s in batched] == [s.label for s in specs]
    for spec, summary in zip(specs, batched):
        expected = run_trial(spec)
        assert summary["engine"] == "batch"
        assert summary["metrics"]["samples"] == expected["metrics"]["samples"]
        assert summary["metrics"]["settled"] == expected["metrics"]["settled"]
        for axis in ("roll", "pitch", "yaw"):
            for key in ("t_r", "e_ss", "M_p"):
                a, b = summary["metrics"][axis][key], expected["metrics"][axis][key]
                assert (a is None) == (b is None), (spec.label, axis, key)
                if a is not None:
                    assert a == pytest.approx(b, abs=1e-6), (spec.label, axis, key)
        a = summary["metrics"]["geodesic"]["final_smoothed_deg"]
        assert a == pytest.approx(expected["metrics"]["geodesic"]["final_smoothed_deg"], abs=1e-6)
        assert ("trace" in summary) == spec.keep_trace
    # three groups: paper 6 s (two trials), tank 6 s, paper 3 s
    assert sorted(s["info"]["batch_size"] for s in batched) == [1, 1, 2, 2]


def test_batch_unsupported_names_the_reason_and_run_batch_refuses():
    base = _specs()[0]
    assert batch_unsupported(base) is None
    for change, reason in ((dict(out_dir="/tmp/uq_never_written"), "per-trial files"), (dict(plant="cube"), "plant")):
        spec = dataclasses.replace(base, **change)
        assert reason in batch_unsupported(spec)
        with pytest.raises(ValueError, match="cannot run batched"):
            run_batch([base, spec])


def test_run_batch_runs_noise_controller_off_and_the_coordinated_scheme_as_the_per_trial_engine():
    """These run on the robot's own controller objects inside the batch, with the stroke metrics of the
    schemes study: the same summaries as the per-trial engine."""
    base = dataclasses.replace(_specs()[1], keep_trace=False)
    specs = [dataclasses.replace(base, label="noisy", attitude_noise_deg=0.5, gyro_noise=0.01, seed=4),
             dataclasses.replace(base, label="off", controller="off"),
             dataclasses.replace(base, label="coordinated", scheme="coordinated", scheme_metrics=True),
             dataclasses.replace(base, label="paper metrics", scheme_metrics=True)]
    for spec in specs:
        assert batch_unsupported(spec) is None
    for spec, summary in zip(specs, run_batch(specs)):
        expected = run_trial(spec)
        assert summary["scheme"] == expected["scheme"] and summary["info"]["controller"] == expected["info"]["controller"]
        a, b = summary["metrics"]["geodesic"], expected["metrics"]["geodesic"]
        assert a["final_smoothed_deg"] == pytest.approx(b["final_smoothed_deg"], abs=1e-6), spec.label
        assert ("scheme_metrics" in summary) == spec.scheme_metrics
        if spec.scheme_metrics:
            for key, value in expected["scheme_metrics"].items():
                assert summary["scheme_metrics"][key] == pytest.approx(value, rel=1e-9, abs=1e-12), (spec.label, key)


def test_run_batch_stops_a_trial_the_robots_controller_would_hold():
    """The batch has no hold: a trial whose measurement the controller would refuse (here every motion:
    max_angular_rate 1e-6 rad/s) is an error, never a silently different trial."""
    spec = dataclasses.replace(_specs()[0], config_overrides=(("max_angular_rate", 1e-6),), keep_trace=False)
    with pytest.raises(SimulationError, match="refuse"):
        run_batch([spec])


def test_the_engine_choice_of_a_study():
    from quadruped_common.config import ParameterError
    from quadruped_control.studies.trial import AUTO_BATCH_MIN, use_batch_engine

    spec = _specs()[0]
    many = [dataclasses.replace(spec, label="t%d" % i) for i in range(AUTO_BATCH_MIN)]
    assert use_batch_engine(many, "auto") and not use_batch_engine(many[:-1], "auto")
    assert not use_batch_engine(many, "trial") and use_batch_engine(many[:1], "batch")
    with_files = many[:-1] + [dataclasses.replace(spec, label="files", out_dir="/tmp/uq_never_written")]
    assert not use_batch_engine(with_files, "auto")  # one trial the batch cannot run: all per trial
    with pytest.raises(ParameterError, match="files.*per-trial files"):
        use_batch_engine(with_files, "batch")
    with pytest.raises(ParameterError, match="engine"):
        use_batch_engine(many, "gpu")


def test_a_study_runs_batched_from_the_command_line(tmp_path):
    from quadruped_control import simulate

    out = str(tmp_path / "table1")
    code = simulate.main(["--study", "paper-experiments", "--plant", "paper", "--duration", "3", "--engine", "batch",
                          "--out", out, "--quiet", "--jobs", "1"])
    assert code == 0
    import glob
    import json

    files = glob.glob(out + "/**/trials/*.json", recursive=True)
    assert len(files) == 15
    for path in files:
        with open(path) as stream:
            assert json.load(stream)["engine"] == "batch"


def test_a_trial_starts_where_the_imu_reports_the_specs_attitude_on_both_engines():
    """initial_rpy_deg is what the robot's IMU reported (Table 1's theta_init and psi_init): with a residual
    field at the tank's IMU the plant starts at the true attitude that reports it, so the recorded (reported)
    attitude starts at the spec's on both engines, and the engines agree."""
    spec = TrialSpec(label="turned", setpoint_rpy_deg=(30.0, 0.0, 0.0), initial_rpy_deg=(40.0, -15.0, 75.0),
                     duration=0.5, gains="experiment", servo_model="rate-limited", plant="tank", quiet=True,
                     tank_overrides=(("imu_field_residual", (0.2, -0.4, 0.5)),))
    setup = trial_setup(spec)
    reported = rpy_to_rot(*np.radians(spec.initial_rpy_deg))
    assert np.degrees(np.abs(rotations_to_rpy(setup.initial_R[None])[0][2] - math.radians(75.0))) > 1.0
    per_trial, batched = run_trial(spec), run_batch([spec])[0]
    for summary in (per_trial, batched):
        np.testing.assert_allclose(np.degrees(summary["trace"]["rpy"][0]), spec.initial_rpy_deg, atol=1e-9)
    np.testing.assert_array_equal(per_trial["trace"]["rpy"], batched["trace"]["rpy"])
    plain = trial_setup(dataclasses.replace(spec, tank_overrides=()))
    np.testing.assert_array_equal(plain.initial_R, reported)


#: an inertia a thousandth of the robot's: the paper plant's 10 ms step diverges within two steps
_DIVERGING = (("inertia", ((1e-4, 0.0, 0.0), (0.0, 1e-4, 0.0), (0.0, 0.0, 1e-4))),)


def test_a_trial_that_cannot_go_on_raises_or_is_recorded_as_its_spec_says():
    base = dataclasses.replace(_specs()[0], duration=2.0, keep_trace=False)
    diverging = dataclasses.replace(base, label="diverging", robot_overrides=_DIVERGING)
    for run in (run_trial, lambda spec: run_batch([spec])[0]):
        with pytest.raises(SimulationError, match="plant step"):
            run(diverging)
    recorded = dataclasses.replace(diverging, on_failure="record")
    alone = run_batch([base])[0]
    per_trial, (batched, beside) = run_trial(recorded), run_batch([recorded, base])
    for summary, engine in ((per_trial, "trial"), (batched, "batch")):
        assert summary["label"] == "diverging" and summary["engine"] == engine and summary["metrics"] is None
        assert "plant step" in summary["failed"] and "non-finite" in summary["failed"]
    # the other trials of the batch run on, as they would alone
    assert "failed" not in beside and beside["metrics"] == alone["metrics"]
    # a held measurement on the batch is recorded the same way, with its reason
    held = dataclasses.replace(base, config_overrides=(("max_angular_rate", 1e-6),), on_failure="record")
    assert "refuse" in run_batch([held])[0]["failed"]
    for run in (run_trial, run_batch):
        with pytest.raises(ValueError, match="on_failure"):
            run(dataclasses.replace(base, on_failure="ignore") if run is run_trial
                else [dataclasses.replace(base, on_failure="ignore")])


def test_a_batch_trial_the_plant_refuses_mid_run_is_recorded_with_the_plants_reason(monkeypatch):
    """Where the tank plant says why a trial failed (TankPlantBatch.failure_reasons: a wound tether past the
    turn its set can be stepped at, tests/control/sim/plants/test_tank_batch.py), the batch's summary gives
    that reason, not the generic one; the trial beside it runs on. The plant's refusal is stood in for at
    its own interface, after a real step: reaching it for real takes a body turned past half a turn."""
    from quadruped_control.sim.plants.tank_batch import TankPlantBatch

    tank = dataclasses.replace(_specs()[2], duration=1.0)
    step = TankPlantBatch.step

    def refusing(self, *args):
        out = step(self, *args)
        self.failed[0] = True
        self.failure_reasons[0] = "tank parameters a 0.01 s step cannot resolve: the hook friction's test"
        return out

    monkeypatch.setattr(TankPlantBatch, "step", refusing)
    refused, beside = run_batch([dataclasses.replace(tank, label="refused", on_failure="record"), tank])
    assert refused["failed"] == "tank parameters a 0.01 s step cannot resolve: the hook friction's test"
    assert refused["metrics"] is None and beside["metrics"] is not None
    with pytest.raises(SimulationError, match="hook friction's test"):
        run_batch([tank])


def test_each_trial_seed_is_another_draw_of_a_disturbed_tanks_disturbance_on_both_engines():
    """A tank that is not still: trial seed 0 runs the tank's own disturbance, another seed another draw (the
    same seed the same draw), in the per-trial and the batched engine alike; a still tank ignores the seed."""
    pushed = (("disturbance_torque_std", 0.01), ("disturbance_correlation_time", 2.0), ("disturbance_seed", 5))
    spec = TrialSpec(label="pushed", setpoint_rpy_deg=(20.0, 0.0, 0.0), duration=4.0, gains="experiment",
                     servo_model="rate-limited", plant="tank", quiet=True, keep_trace=True, tank_overrides=pushed)
    seeds = [trial_setup(dataclasses.replace(spec, seed=seed)).model.tank.disturbance_seed for seed in (0, 3, 3, 4)]
    assert seeds[0] == 5 and seeds[1] == seeds[2] and len({seeds[0], seeds[1], seeds[3]}) == 3
    still = dataclasses.replace(spec, tank_overrides=(), seed=3)
    assert trial_setup(still).model.tank == trial_setup(dataclasses.replace(still, seed=0)).model.tank
    runs = [dataclasses.replace(spec, seed=seed) for seed in (0, 3)]
    per_trial, batched = [run_trial(s) for s in runs], run_batch(runs)
    for a, b in zip(per_trial, batched):
        np.testing.assert_array_equal(a["trace"]["rpy"], b["trace"]["rpy"])
    assert not np.array_equal(per_trial[0]["trace"]["rpy"], per_trial[1]["trace"]["rpy"])
