"""Tests of quadruped_control.control.controller_config: gains, timing and pairs of the attitude controller."""
import dataclasses
import math

import pytest
import yaml

from quadruped_common.config import ParameterError, load_yaml, config_path
from quadruped_control.control.controller_config import (ControllerConfig, Gains, controller_config_from_dict,
                                                 load_controller_config)

GAINS = Gains(k_p=5.0, k_i=0.15, k_d=1.0, k_aw=0.25)


def test_simulation_gain_set_matches_paper():
    # Paper, section "Simulation Validation": Kp = 5, Ki = 0.15, Kd = 1, Kaw = 0.25, t_rec = 1.5 s.
    config = load_controller_config(gain_set="simulation")
    assert config.gains == Gains(5.0, 0.15, 1.0, 0.25)
    assert config.t_rec == 1.5
    assert config.tau_max == 2.0      # eq. (sat)
    assert config.t_pow_max == 0.5    # section "Power and Recovery Stroke Cycle"
    assert config.dt == 0.01
    assert config.pairs == ((1, 3), (2, 4))
    assert config.normalize_force_direction is False
    assert config.gyroscopic_feedforward and config.buoyancy_feedforward
    assert config.integral_limit == 10.0  # [choice], always on (issue 10)


def test_default_gain_set_is_simulation():
    assert load_controller_config() == load_controller_config(gain_set="simulation")


def test_experiment_gain_set_matches_paper():
    # Paper, section "Experimental Setup": Kp = 10, Ki = 3, Kd = 0.5, Kaw = 0.25, t_rec = 1.5 s.
    config = load_controller_config(gain_set="experiment")
    assert config.gains == Gains(10.0, 3.0, 0.5, 0.25)
    assert config.t_rec == 1.5
    # Pitch 75/90 deg and roll+pitch 60 deg experiments used t_rec = 1.0 s.
    assert load_controller_config(gain_set="experiment_fast_recovery").t_rec == 1.0


def test_unknown_gain_set_lists_the_available_ones():
    with pytest.raises(ParameterError, match="unknown gain set 'lab'.*experiment.*simulation"):
        load_controller_config(gain_set="lab")


def test_defaults_of_the_dataclass_are_the_papers():
    config = ControllerConfig(gains=GAINS)
    assert (config.tau_max, config.t_rec, config.t_pow_max, config.dt) == (2.0, 1.5, 0.5, 0.01)
    assert config.pairs == ((1, 3), (2, 4))
    assert math.isclose(config.max_step, 0.05)


@pytest.mark.parametrize("name", ["k_p", "k_i", "k_d", "k_aw"])
@pytest.mark.parametrize("value", [-0.1, math.nan, math.inf, "5", True, None])
def test_bad_gains_are_rejected(name, value):
    values = dict(k_p=1.0, k_i=1.0, k_d=1.0, k_aw=1.0)
    values[name] = value
    with pytest.raises(ParameterError, match=name):
        Gains(**values)


def test_zero_integral_derivative_and_anti_windup_gains_are_allowed():
    assert Gains(0.1, 0.0, 0.0, 0.0).k_i == 0.0


@pytest.mark.parametrize("name", ["k_p", "tau_max"])
def test_a_configuration_that_disables_the_controller_is_refused(name):
    """K_p = 0 (no proportional action) or tau_max = 0 (no torque at all) would run armed and do nothing."""
    with pytest.raises(ParameterError, match=name):
        Gains(0.0, 0.0, 0.0, 0.0) if name == "k_p" else ControllerConfig(GAINS, tau_max=0.0)


@pytest.mark.parametrize("pairs", [
    ((1, 2), (2, 4)),         # leg 2 twice, leg 3 missing
    ((1, 3), (2, 5)),         # no leg 5
    ((1, 3, 2), (4,)),        # not pairs
    ((1, 3),),                # one pair
    ((1, 3), (2, 4), (1, 2)),
    ((1.0, 3), (2, 4)),       # not integers
    ((True, 3), (2, 4)),
    5,
])
def test_pairs_must_partition_the_legs(pairs):
    with pytest.raises(ParameterError, match="pairs"):
        ControllerConfig(gains=GAINS, pairs=pairs)


def test_pairs_are_normalised_to_tuples():
    config = ControllerConfig(gains=GAINS, pairs=[[2, 4], [3, 1]])
    assert config.pairs == ((2, 4), (3, 1))
    assert isinstance(config.pairs[0], tuple)


@pytest.mark.parametrize("changes, match", [
    (dict(t_rec=0.0), "t_rec"),
    (dict(t_rec=-1.0), "t_rec"),
    (dict(t_rec=math.nan), "t_rec"),
    (dict(t_pow_max=0.0), "t_pow_max"),
    (dict(t_rec=0.9, t_pow_max=0.5), "2 t_pow_max"),
    (dict(tau_max=-0.5), "tau_max"),
    (dict(tau_max=math.inf), "tau_max"),
    (dict(dt=0.0), "dt"),
    (dict(dt=0.2, t_pow_max=0.1, t_rec=1.0), "shorter than one control period"),
    (dict(integral_limit=0.0), "integral_limit"),
    (dict(integral_limit=-1.0), "integral_limit"),
    (dict(normalize_force_direction=1), "normalize_force_direction"),
    (dict(buoyancy_feedforward="yes"), "buoyancy_feedforward"),
    (dict(max_step_factor=0.5), "max_step_factor"),
    (dict(rotation_tolerance=0.0), "rotation_tolerance"),
    (dict(gains=(5.0, 0.15, 1.0, 0.25)), "Gains"),
])
def test_invalid_config_values_are_rejected(changes, match):
    with pytest.raises(ParameterError, match=match):
        ControllerConfig(**dict(dict(gains=GAINS), **changes))


def test_t_rec_exactly_twice_t_pow_max_is_accepted():
    # The paper's experiments ran t_rec = 1.0 s with t_pow_max = 0.5 s.
    assert ControllerConfig(gains=GAINS, t_rec=1.0, t_pow_max=0.5).t_rec == 1.0


def test_config_is_immutable_and_helpers_validate():
    config = ControllerConfig(gains=GAINS)
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.t_rec = 2.0  # type: ignore[misc]
    faster = config.replace(t_rec=1.0)
    assert faster.t_rec == 1.0 and config.t_rec == 1.5
    with pytest.raises(ParameterError, match="2 t_pow_max"):
        config.replace(t_rec=0.5)
    tuned = config.with_gains(k_p=10.0)
    assert tuned.gains == Gains(10.0, 0.15, 1.0, 0.25) and config.gains.k_p == 5.0
    assert config.with_gains(Gains(1.0, 2.0, 3.0, 4.0)).gains == Gains(1.0, 2.0, 3.0, 4.0)
    with pytest.raises(ParameterError, match="k_d"):
        config.with_gains(k_d=-1.0)
    assert GAINS.replace(k_i=3.0).k_i == 3.0


def _tree():
    return load_yaml(config_path("controller.yaml"))


def _load(tmp_path, tree, gain_set="simulation"):
    path = tmp_path / "controller.yaml"
    path.write_text(yaml.safe_dump(tree))
    return load_controller_config(str(path), gain_set)


def test_gain_set_may_override_timing(tmp_path):
    tree = _tree()
    tree["gain_sets"]["simulation"]["tau_max"] = 1.5
    tree["gain_sets"]["simulation"]["t_pow_max"] = 0.4
    config = _load(tmp_path, tree)
    assert config.tau_max == 1.5 and config.t_pow_max == 0.4
    assert _load(tmp_path, tree, "experiment").tau_max == 2.0


@pytest.mark.parametrize("mutate, match", [
    (lambda t: t["gain_sets"]["simulation"].pop("k_i"), "gain_sets.simulation.k_i"),
    (lambda t: t["gain_sets"]["simulation"].update(k_x=1.0), "unknown parameter .gain_sets.simulation.k_x."),
    (lambda t: t.update(gain=1.0), r"unknown parameter 'gain' \(allowed: "),
    (lambda t: t.pop("gain_sets"), "gain_sets"),
    (lambda t: t.update(pairs=[[1, 2], [1, 4]]), "partition"),
    (lambda t: t.update(normalize_force_direction="no"), "normalize_force_direction"),
    (lambda t: t["gain_sets"]["simulation"].update(k_p=-5.0), "k_p"),
    (lambda t: t["gain_sets"]["simulation"].update(t_rec=0.6), "2 t_pow_max"),
    (lambda t: t.update(tau_max=0.0), "tau_max"),
    (lambda t: t["gain_sets"]["experiment"].update(tau_max=0), "gain_sets.experiment.tau_max"),
    (lambda t: t["gain_sets"]["simulation"].update(k_p=0.0), "k_p"),
])
def test_bad_files_name_the_problem(tmp_path, mutate, match):
    tree = _tree()
    mutate(tree)
    with pytest.raises(ParameterError, match=match) as info:
        _load(tmp_path, tree)
    assert "controller.yaml" in str(info.value)


def test_missing_file_and_non_mapping(tmp_path):
    with pytest.raises(ParameterError, match="cannot read"):
        load_controller_config(str(tmp_path / "nope.yaml"))
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(ParameterError, match="mapping"):
        load_controller_config(str(path))


def test_dict_loader_accepts_minimal_tree():
    config = controller_config_from_dict({"gain_sets": {"g": {"k_p": 1, "k_i": 0, "k_d": 0, "k_aw": 0}}}, "g")
    assert config.gains == Gains(1.0, 0.0, 0.0, 0.0)
    assert config.pairs == ((1, 3), (2, 4))
