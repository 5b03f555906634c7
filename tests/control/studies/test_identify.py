"""Identification helpers: design, objective, config update, and a tiny end-to-end run."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from quadruped_common.config import config_path
from quadruped_control import simulate
from quadruped_control.sim.plants import TankParams, load_tank_params
from quadruped_control.studies import identify as idf


def test_latin_hypercube_has_one_point_per_stratum_within_bounds() -> None:
    points = idf.latin_hypercube(8, seed=3)
    for name, _, low, high in idf.PARAMETERS:
        values = np.array([p[name] for p in points])
        assert np.all((values >= low) & (values <= high))
        strata = np.floor((values - low) / (high - low) * 8).astype(int)
        assert sorted(strata.tolist()) == list(range(8))
    assert idf.latin_hypercube(8, seed=3) == points  # seeded


def test_case_cost_terms() -> None:
    row = {"settled_paper": True, "settled_sim": True,
           "paper": {"t_s": 50.0, "t_r": 20.0, "e_ss": 1.0, "M_p": 10.0},
           "sim": {"t_s": 50.0, "t_r": 20.0, "e_ss": 1.0, "M_p": 10.0}}
    assert idf.case_cost(row) == 0.0
    row["sim"] = {"t_s": 100.0, "t_r": 10.0, "e_ss": 6.0, "M_p": 60.0}
    assert idf.case_cost(row) == pytest.approx(2 * np.log(2.0) + 1.0 + 1.0)
    row["settled_sim"] = False
    row["sim"]["t_s"] = None
    assert idf.case_cost(row) == pytest.approx(1.0 + np.log(2.0) + 2.0)


def test_spearman() -> None:
    assert idf.spearman([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert idf.spearman([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert idf.spearman([1, 2], [1, 2]) == 0.0


def test_update_tank_yaml_round_trips_through_the_loader(tmp_path) -> None:
    values = {"cob_z": -0.0012, "hook_z": 0.06, "net_weight": 0.5, "rope_length": 0.8, "added_mass_scale": 1.5,
              "servo_speed_scale": 0.7, "paw_drag_scale": 1.1}
    with open(config_path("tank.yaml")) as stream:
        text = idf.update_tank_yaml(stream.read(), values, "test")
    path = str(tmp_path / "tank.yaml")
    with open(path, "w") as stream:
        stream.write(text)
    tank = load_tank_params(path)
    assert tank.center_of_buoyancy == (0.0, 0.0, -0.0012) and tank.hook == (0.0, 0.0, 0.06)
    assert (tank.net_weight, tank.rope_length, tank.added_mass_scale, tank.servo_speed_scale,
            tank.paw_drag_scale) == (0.5, 0.8, 1.5, 0.7, 1.1)
    assert text.count("[identified] test") == 7
    assert TankParams(**dict(idf.tank_overrides(values))) == tank.with_values(
        suspension=True, hydrostatics=True, torso_added_mass=True, paw_added_mass=True, drag=True,
        rope_stiffness=TankParams().rope_stiffness, rope_damping=TankParams().rope_damping,
        paw_added_mass_scale=1.0)


def test_identify_cli_tiny_run(tmp_path) -> None:
    out = str(tmp_path / "id")
    assert simulate.main(["--study", "identify", "--points", "2", "--refine", "1", "--duration", "0.5",
                          "--out", out, "--quiet", "--jobs", "1"]) == 0
    with open(os.path.join(out, "identify.json")) as stream:
        report = json.load(stream)
    assert report["trials"] == 15 * 4
    assert set(report["sensitivity_rank"]) == {p[0] for p in idf.PARAMETERS}
    assert os.path.exists(os.path.join(out, "tank_identified.yaml"))
