"""The strokes' torque on a clamped robot against the held command (quadruped_control.studies.torque_map)."""
from __future__ import annotations

import math

import pytest

from quadruped_common.config import config_path
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.model.params import load_robot_params
from quadruped_control.sim.plants.tank_params import load_tank_params
from quadruped_control.sim.servo_model import load_servo_params, tank_servo_params
from quadruped_control.studies import torque_map
from quadruped_control.studies.torque_map import MapPoint


@pytest.fixture(scope="module")
def bench():
    robot, tank = load_robot_params(), load_tank_params()
    config = load_controller_config(None, torque_map.BENCH_GAINS)
    return robot, tank, config, tank_servo_params(load_servo_params(), tank)


def test_the_bench_gain_set_is_the_experiment_gains_proportional_term_alone() -> None:
    bench, experiment = (load_controller_config(None, name).gains for name in (torque_map.BENCH_GAINS, "experiment"))
    assert bench.k_p == experiment.k_p and bench.k_i == 0.0 and bench.k_d == 0.0


def test_the_held_command_is_kp_sin_e_and_the_strokes_push_towards_the_setpoint(bench) -> None:
    robot, tank, config, servo = bench
    yaw = torque_map.clamped_torque(robot, tank, config, servo, "yaw", 4.0, duration=14.0, settle=4.0)
    # no buoyancy feedforward about the vertical of a level robot: exactly K_p e_R, |e_R| = sin(e)
    assert yaw.commanded == pytest.approx(config.gains.k_p * math.sin(math.radians(4.0)), rel=1e-9)
    assert 0.0 < yaw.delivered < yaw.commanded
    plus, minus = (torque_map.clamped_torque(robot, tank, config, servo, "roll", e, duration=14.0, settle=4.0)
                   for e in (4.0, -4.0))
    assert plus.delivered > 0.0 > minus.delivered and plus.commanded > 0.0 > minus.commanded


def test_the_map_saturates_with_the_command(bench) -> None:
    """The delivered torque grows with the error and flattens where the controller saturates (2 N m at
    11.5 deg): beyond it the command, and the strokes, stay the same."""
    robot, tank, config, servo = bench
    points = torque_map.torque_map(robot, tank, config, servo, ["pitch"], [0.5, 2.0, 20.0, 40.0], 14.0, 4.0)
    delivered = [p.delivered for p in points]
    assert delivered[0] < delivered[1] < delivered[2]
    assert points[2].commanded == pytest.approx(2.0) and points[3].commanded == pytest.approx(2.0)
    assert delivered[3] == pytest.approx(delivered[2], rel=0.05)


def test_half_ceiling_error() -> None:
    points = [MapPoint("roll", e, 0.0, d) for e, d in ((0.5, 0.002), (1.0, 0.004), (2.0, 0.006), (4.0, 0.008))]
    assert torque_map.half_ceiling_error(points) == 1.0
    assert torque_map.half_ceiling_error(points[:1]) == 0.5
    assert torque_map.half_ceiling_error([]) is None
    assert torque_map.half_ceiling_error([MapPoint("roll", 1.0, 0.1, -0.001)]) is None


@pytest.mark.parametrize("axis, error, duration, settle, match", [
    ("twist", 2.0, 20.0, 5.0, "axis"), ("roll", 0.0, 20.0, 5.0, "non-zero"), ("roll", 90.0, 20.0, 5.0, "90"),
    ("roll", math.nan, 20.0, 5.0, "finite"), ("roll", 2.0, 5.0, 5.0, "settle"), ("roll", 2.0, 20.0, -1.0, "settle"),
    ("roll", 2.0, math.inf, 5.0, "settle")])
def test_bad_points_are_refused(bench, axis, error, duration, settle, match) -> None:
    robot, tank, config, servo = bench
    with pytest.raises(ValueError, match=match):
        torque_map.clamped_torque(robot, tank, config, servo, axis, error, duration, settle)


def test_cli_prints_the_map_and_a_measured_point(capsys) -> None:
    assert torque_map.main(["--axes", "yaw", "--errors", "1", "3", "--duration", "12", "--settle", "2",
                            "--measured", "yaw", "2", "0.004"]) == 0
    out = capsys.readouterr().out
    assert "| yaw | 1 |" in out and "| yaw | 3 |" in out
    assert "yaw: half of the largest delivered torque" in out
    assert "Measured yaw 2 deg: 0.004 N m held; the model delivers" in out
    assert "Note: the tank plant is not yet a validated model" in out  # the map is the model's, not the robot's


@pytest.mark.parametrize("argv", [["--errors", "0"], ["--errors", "95"], ["--duration", "5", "--settle", "5"],
                                  ["--measured", "roll", "2", "nan"], ["--measured", "twist", "2", "0.01"],
                                  ["--axes", "twist"]])
def test_cli_refuses_bad_input(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        torque_map.main(argv)
    assert exc.value.code == 2
    assert "error" in capsys.readouterr().err


def test_cli_reports_a_bad_config(tmp_path, capsys) -> None:
    bad = tmp_path / "tank.yaml"
    with open(config_path("tank.yaml")) as stream:
        text = stream.read()
    assert "\n  rope_length: 0.5\n" in text
    bad.write_text(text.replace("\n  rope_length: 0.5\n", "\n  rope_length: -0.5\n"))
    assert torque_map.main(["--tank-yaml", str(bad), "--axes", "yaw", "--errors", "1", "--duration", "12"]) == 1
    err = capsys.readouterr().err
    assert "torque_map:" in err and "length" in err
