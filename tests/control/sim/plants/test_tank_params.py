"""The tank parameters' one schema (quadruped_control/sim/plants/tank_params.py): each parameter declared once,
and the yaml keys, the dataclass fields, the range checks and the identification's table read from it."""
import dataclasses
import math
import os

import pytest
import yaml

from quadruped_common.config import ParameterError, config_path
from quadruped_control.sim.plants.tank_params import (SCHEMA, SECTIONS, TankParams, fit_coordinates, load_tank_params,
                                                      yaml_path)
from quadruped_control.studies import identify_parameters as idp


def _shipped_tree() -> dict:
    with open(config_path("tank.yaml")) as stream:
        return yaml.safe_load(stream)


def test_every_field_is_declared_once_with_its_section_unit_and_meaning() -> None:
    assert [spec.name for spec in SCHEMA] == [f.name for f in dataclasses.fields(TankParams)]
    for spec in SCHEMA:
        assert spec.section in SECTIONS and spec.meaning, spec.name
        assert yaml_path(spec.name) == "%s.%s" % (spec.section, spec.name)
        assert spec.default == getattr(TankParams(), spec.name)


def test_the_shipped_tank_yaml_holds_every_parameter_under_its_schema_name() -> None:
    """One name: tank.yaml's keys are the dataclass fields, each in the section the schema gives it."""
    tree = _shipped_tree()
    assert list(tree) == list(SECTIONS)
    keys = {(section, key) for section, values in tree.items() for key in values}
    assert keys == {(spec.section, spec.name) for spec in SCHEMA}


def _outside(spec) -> list:
    """Values just outside a numeric parameter's range (none for a switch)."""
    if isinstance(spec.default, bool):
        return []
    values = []
    if math.isfinite(spec.low):
        values.append(spec.low if spec.low_open else spec.low - max(1e-6, abs(spec.low) * 1e-3))
    if math.isfinite(spec.high):
        values.append(spec.high + max(1e-6, abs(spec.high) * 1e-3))
    if isinstance(spec.default, int):
        values = [int(math.floor(v)) if v < spec.low else int(math.ceil(v)) + 1 for v in values]
    return values


@pytest.mark.parametrize("spec", SCHEMA, ids=[spec.name for spec in SCHEMA])
def test_the_loader_and_the_dataclass_refuse_the_same_values_naming_the_key(spec) -> None:
    for value in _outside(spec):
        given = tuple(value if i == 0 else spec.default[i] for i in range(len(spec.default))) \
            if isinstance(spec.default, tuple) else value
        tree = _shipped_tree()
        tree[spec.section][spec.name] = list(given) if isinstance(given, tuple) else given
        with pytest.raises(ParameterError, match=yaml_path(spec.name).replace(".", r"\.")):
            load_tank_params(tree=tree)
        with pytest.raises(ParameterError, match=spec.name):
            TankParams(**{spec.name: given})
    tree = _shipped_tree()
    tree[spec.section][spec.name] = list(spec.default) if isinstance(spec.default, tuple) else spec.default
    assert getattr(load_tank_params(tree=tree), spec.name) == spec.default


def test_a_switch_is_a_boolean_and_a_missing_optional_key_is_its_default() -> None:
    tree = _shipped_tree()
    tree["effects"]["drag"] = 1
    with pytest.raises(ParameterError, match=r"effects\.drag"):
        load_tank_params(tree=tree)
    tree = _shipped_tree()
    del tree["servos"]["servo_dead_band"], tree["disturbance"]
    assert load_tank_params(tree=tree) == load_tank_params()
    tree = _shipped_tree()
    del tree["suspension"]["rope_length"]
    with pytest.raises(ParameterError, match=r"missing parameter 'suspension\.rope_length'"):
        load_tank_params(tree=tree)


def test_the_identification_table_is_read_from_the_schema() -> None:
    """Each coordinate is named after its parameter (axes, or _inverse for a fitted reciprocal), its bounds lie in
    the parameter's range, and the order is the schema's."""
    names = [name for name, _, _ in idp.PARAMETERS]
    assert names == [name for name, _, _ in fit_coordinates()] and len(set(names)) == len(names)
    for name, low, high in idp.PARAMETERS:
        spec, fit = idp.PLACES[name]
        assert name.startswith(spec.name) and (name.endswith("_inverse") == fit.reciprocal)
        for bound in (low, high):
            value = idp.field_value(name, bound)
            assert spec.low <= value <= spec.high, (name, bound)
        if fit.reciprocal:  # a coordinate near 0 is a huge value, which the schema takes
            spec.read(idp.field_value(name, low + 1e-9 * (high - low)), name)
    assert "servo_stall_torque_inverse" in names and "center_of_buoyancy_z" in names and "hook_z" in names


def test_the_docs_table_of_parameters_is_the_schema() -> None:
    """docs/tank_model.md reads its parameter table from the one declaration (regenerate it with
    tank_params.parameter_table() when a parameter changes)."""
    from tests.repo import REPO_ROOT
    from quadruped_control.sim.plants.tank_params import parameter_table
    with open(os.path.join(REPO_ROOT, "docs", "tank_model.md"), encoding="utf-8") as stream:
        text = stream.read()
    begin, end = "<!-- parameter table: begin -->\n", "<!-- parameter table: end -->"
    assert text[text.index(begin) + len(begin):text.index(end)] == parameter_table()
