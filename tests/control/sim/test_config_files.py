"""The table of configuration files (quadruped_control/sim/config_files.py) and the fitted tank plants the
repository ships in config/tank_ensemble/ (every file is loaded by tests/common/test_config.py)."""
import dataclasses
import os
import re

from quadruped_common.config import config_dir, config_path
from quadruped_control.sim.config_files import LOADERS, TANK_ENSEMBLE
from quadruped_control.sim.plants import load_tank_params
from quadruped_control.studies import identify_parameters as idp


def test_the_ensemble_folder_holds_exactly_the_files_the_table_loads() -> None:
    folder = os.path.join(config_dir(), "tank_ensemble")
    assert sorted("tank_ensemble/" + name for name in os.listdir(folder)) == sorted(TANK_ENSEMBLE)
    assert all(LOADERS[name] is load_tank_params for name in TANK_ENSEMBLE)


def _fitted_parameters(text: str) -> list:
    """The parameters the member's header says its identification fitted (its command's --parameters)."""
    command = " ".join(line.lstrip("# ").strip() for line in text.splitlines() if line.startswith("#     "))
    match = re.search(r"--parameters ((?:[a-z_]+ ?)+)", command)
    assert match, "the header names the command with its --parameters"
    return match.group(1).split()


def test_each_member_names_what_produced_it_and_differs_from_tank_yaml_only_where_it_was_fitted() -> None:
    """A member is config/tank.yaml with the fitted parameters replaced: a value the fit held is tank.yaml's,
    so a member tells its reader exactly what was fitted (and a tank.yaml changed since the fit shows here)."""
    base = dataclasses.asdict(load_tank_params(config_path("tank.yaml")))
    for name in TANK_ENSEMBLE:
        with open(config_path(name)) as stream:
            text = stream.read()
        assert re.search(r"at commit [0-9a-f]{7}", text)
        assert "python -m quadruped_control.simulate --study identify" in text
        fitted = _fitted_parameters(text)
        assert set(fitted) <= {p[0] for p in idp.PARAMETERS}
        tank = load_tank_params(config_path(name))
        member = dataclasses.asdict(tank)
        fields = {field for field, _ in idp.tank_overrides({n: 1.0 for n in fitted})}
        assert {field for field in base if member[field] != base[field]} <= fields, name
        bounds = {parameter: (low, high) for parameter, low, high in idp.PARAMETERS}
        for parameter in fitted:  # inside the bounds docs/identification.md reasons (read without clipping)
            spec, fit = idp.PLACES[parameter]
            value = getattr(tank, spec.name)
            value = idp.field_value(parameter, value[fit.components[0]] if fit.components else value)
            assert bounds[parameter][0] <= value <= bounds[parameter][1], (name, parameter, value)
