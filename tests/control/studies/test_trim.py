"""The model's restoring torque and the trim matching a static pull (quadruped_control.studies.trim)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from quadruped_common.so3 import rpy_to_rot
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.tank import TankModel
from quadruped_control.sim.plants.tank_params import TankParams
from quadruped_control.sim.simulation import nominal_joint_angles
from quadruped_control.studies import trim


def restoring_torque(robot, tank, R, q):
    return TankModel(robot, tank).restoring_torque(R, q)


def test_the_torque_is_the_plants_hydrostatics_and_rope_at_rest() -> None:
    """Each term against its closed form: the torso buoyancy's arm and the rope's tension at the hook."""
    robot = load_robot_params()
    q = nominal_joint_angles(robot)
    base = TankParams(center_of_buoyancy=(0.0, 0.0, 0.001))
    higher = base.with_values(center_of_buoyancy=(0.0, 0.0, 0.003))
    theta = math.radians(40.0)
    R = rpy_to_rot(theta, 0.0, 0.0)
    buoyancy = TankModel(robot, base).torso_buoyancy
    # r_cb x (B R^T z): with R^T z = (0, sin, cos) about x, a higher centre of buoyancy restores by -dz B sin
    difference = restoring_torque(robot, higher, R, q) - restoring_torque(robot, base, R, q)
    np.testing.assert_allclose(difference, [-0.002 * buoyancy * math.sin(theta), 0.0, 0.0], atol=1e-12)
    hanging = TankModel(robot, base)
    free = base.with_values(suspension=False)
    rope = restoring_torque(robot, base, R, q) - restoring_torque(robot, free, R, q)
    np.testing.assert_allclose(rope, [-base.hook[2] * hanging.static_rope_tension() * math.sin(theta), 0.0, 0.0],
                               atol=1e-9)
    # a symmetric stance with the centre of buoyancy on the z axis: no torque when level
    np.testing.assert_allclose(restoring_torque(robot, base, np.eye(3), q), 0.0, atol=1e-12)


def test_a_pull_gives_back_the_centre_of_buoyancy_it_was_made_with() -> None:
    robot = load_robot_params()
    truth = TankParams(center_of_buoyancy=(0.0, 0.0, -0.002))
    for axis, tilt in (("roll", 30.0), ("pitch", 75.0)):
        held = -trim.restoring_curve(robot, truth, axis, [tilt])[0]
        guess = truth.with_values(center_of_buoyancy=(0.0, 0.0, 0.003))
        assert trim.cob_z_for_pull(robot, guess, axis, tilt, held) == pytest.approx(-0.002, abs=1e-12)
    no_buoyancy = TankParams(hydrostatics=False)
    with pytest.raises(ValueError, match="does not depend on the centre of buoyancy"):
        trim.cob_z_for_pull(robot, no_buoyancy, "roll", 30.0, 0.01)
    with pytest.raises(ValueError, match="finite"):
        trim.cob_z_for_pull(robot, truth, "roll", 30.0, math.nan)
    with pytest.raises(ValueError, match="tilt"):
        trim.restoring_curve(robot, truth, "roll", [0.0])


def test_cli_prints_the_curve_and_the_matching_trim(capsys, tmp_path) -> None:
    assert trim.main(["--pull", "pitch", "90", "0.02"]) == 0
    out = capsys.readouterr().out
    assert "| roll |" in out and "| pitch |" in out and "center_of_buoyancy: [" in out
    assert "Note: the tank plant is not yet a validated model" in out  # the curve is the model's, not the robot's
    for bad in (["--pull", "yaw", "30", "0.1"], ["--pull", "roll", "0", "0.1"], ["--pull", "roll", "30", "nan"],
                ["--pull", "roll", "x", "0.1"]):
        with pytest.raises(SystemExit) as exit_info:
            trim.main(bad)
        assert exit_info.value.code == 2
    assert trim.main(["--tank-yaml", str(tmp_path / "missing.yaml")]) == 1
    assert "trim:" in capsys.readouterr().err
