"""End-to-end tests of the offline simulator CLI (python3 -m quadruped_control.simulate)."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys

import pytest

from quadruped_control import simulate
from quadruped_control.sim.plants import VALIDITY_NOTE
from quadruped_control.sim.simulation import SimulationResult
from tests.repo import REPO_ROOT as ROOT



def test_single_trial_writes_csv_metrics_and_figure(tmp_path, capsys) -> None:
    out = str(tmp_path / "trial")
    code = simulate.main(["--rpy", "20", "-10", "30", "--duration", "4", "--out", out, "--quiet"])
    assert code == 0
    for name in ("timeseries.csv", "metrics.json", "attitude.png"):
        assert os.path.getsize(os.path.join(out, name)) > 0
    with open(os.path.join(out, "timeseries.csv")) as stream:
        rows = list(csv.reader(stream))
    header = rows[0]
    for column in SimulationResult.CSV_COLUMNS:
        assert column in header
    assert "phase_pair1" in header and "phase_pair2" in header
    assert len(rows) == 1 + 401
    assert float(rows[1][header.index("roll_setpoint_deg")]) == pytest.approx(20.0)
    assert rows[1][header.index("phase_pair1")] in ("power", "recovery", "hold")
    with open(os.path.join(out, "metrics.json")) as stream:
        metrics = json.load(stream)
    for axis in ("roll", "pitch", "yaw"):
        assert set(metrics[axis]) >= {"t_r", "t_s", "e_ss", "M_p"}
    assert {"theta_init_deg", "settled"} <= set(metrics)
    assert metrics["settled"] is False  # 4 s is shorter than the 30 s criterion
    with open(os.path.join(out, "attitude.png"), "rb") as stream:
        assert stream.read(8) == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "t_r[s]" in printed and "roll" in printed


def test_options_reach_the_trial(tmp_path) -> None:
    out = str(tmp_path / "opts")
    code = simulate.main(["--rpy", "10", "0", "0", "--initial-rpy", "0", "5", "0", "--duration", "1",
                          "--gains", "experiment", "--servo-model", "rate-limited", "--normalize-force",
                          "--restoring-offset", "0", "0", "0.01", "--seed", "3", "--attitude-noise", "0.1",
                          "--out", out, "--quiet"])
    assert code == 0
    with open(os.path.join(out, "metrics.json")) as stream:
        info = json.load(stream)["info"]
    assert info["gains"]["k_p"] == 10.0 and info["gains"]["k_i"] == 3.0
    assert info["servo_model"] == "rate-limited"
    assert info["normalize_force_direction"] is True
    assert info["restoring_offset"] == [0.0, 0.0, 0.01]
    assert info["seed"] == 3 and info["attitude_noise_deg"] == pytest.approx(0.1)


def test_bad_arguments_exit_with_usage_error(tmp_path) -> None:
    with pytest.raises(SystemExit) as exc:
        simulate.main(["--duration", "-1", "--out", str(tmp_path)])
    assert exc.value.code == 2
    with pytest.raises(SystemExit):
        simulate.main(["--gains", "magic"])
    with pytest.raises(SystemExit):
        simulate.main(["--rpy", "nan", "0", "0", "--out", str(tmp_path)])


def test_module_runs_as_a_script_without_ros(tmp_path) -> None:
    out = str(tmp_path / "script")
    env = dict(os.environ, PYTHONPATH=ROOT)
    proc = subprocess.run([sys.executable, "-m", "quadruped_control.simulate", "--duration", "0.5", "--out", out],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "settled" in proc.stdout
    # The CLI never imports rospy (usable without ROS).
    check = subprocess.run([sys.executable, "-c", "import sys, quadruped_control.simulate; "
                            "sys.exit(1 if 'rospy' in sys.modules else 0)"], cwd=ROOT, env=env, timeout=60)
    assert check.returncode == 0


def _robot_yaml_with_foot(tmp_path, z: float) -> str:
    """A copy of config/robot.yaml whose nominal foot height is ``z`` (m)."""
    from quadruped_common.config import config_path, load_yaml
    import yaml

    tree = load_yaml(config_path("robot.yaml"))
    tree["nominal_foot_leg"] = [tree["nominal_foot_leg"][0], tree["nominal_foot_leg"][1], z]
    path = str(tmp_path / ("robot_z%g.yaml" % z))
    with open(path, "w") as stream:
        yaml.safe_dump(tree, stream)
    return path


def test_robot_yaml_reaches_plant_controller_and_studies(tmp_path) -> None:
    from quadruped_common.config import config_path
    from quadruped_control.model.params import load_robot_params

    default_z = float(load_robot_params().nominal_foot_leg[2])
    other_z = default_z + 0.005
    path = _robot_yaml_with_foot(tmp_path, other_z)
    # Single trial: a different nominal foot gives a different closed-loop response (plant and controller
    # both take the file), the default file reproduces itself.
    runs = {}
    for name, extra in (("default", []), ("other", ["--robot-yaml", path])):
        out = str(tmp_path / name)
        assert simulate.main(["--rpy", "30", "0", "0", "--duration", "2", "--out", out, "--quiet"] + extra) == 0
        with open(os.path.join(out, "timeseries.csv")) as stream:
            runs[name] = list(csv.reader(stream))
    header = runs["default"][0]
    column = header.index("roll_deg")
    assert runs["default"][-1][column] != runs["other"][-1][column]
    # Studies record which file and which nominal foot they used.
    out = str(tmp_path / "study")
    simulate.main(["--study", "paper-sim", "--duration", "1", "--out", out, "--quiet", "--jobs", "1",
                   "--robot-yaml", path])
    with open(os.path.join(out, "study.json")) as stream:
        study = json.load(stream)
    assert study["robot_yaml"] == os.path.abspath(path)
    assert all(t["nominal_foot_leg"][2] == pytest.approx(other_z) for t in study["trials"])
    out = str(tmp_path / "robust")
    assert simulate.main(["--study", "robustness", "--duration", "0.3", "--out", out, "--quiet", "--jobs", "2",
                          "--robot-yaml", path]) == 0
    with open(os.path.join(out, "robustness.json")) as stream:
        robust = json.load(stream)
    assert robust["nominal_foot_leg"][2] == pytest.approx(other_z)
    assert robust["robot_yaml"] == os.path.abspath(path) != config_path("robot.yaml")


def test_bad_robot_yaml_is_a_clear_error(tmp_path, capsys) -> None:
    missing = str(tmp_path / "nope.yaml")
    assert simulate.main(["--duration", "0.5", "--out", str(tmp_path / "o"), "--quiet", "--robot-yaml", missing]) == 1
    assert "nope.yaml" in capsys.readouterr().err
    unreachable = _robot_yaml_with_foot(tmp_path, -0.5)  # 50 cm below the hip: out of the leg's reach
    code = simulate.main(["--study", "paper-sim", "--duration", "0.5", "--out", str(tmp_path / "s"), "--quiet",
                          "--jobs", "1", "--robot-yaml", unreachable])
    assert code == 1
    assert "unreachable" in capsys.readouterr().err
    assert not os.path.exists(str(tmp_path / "s" / "study.json"))


@pytest.mark.parametrize("study", ["paper-sim", "robustness", "schemes"])
def test_a_study_on_the_tank_plant_ends_with_its_validity_note(study, tmp_path, capsys, monkeypatch) -> None:
    """The studies that run on the plant --plant names print the note after their report on the tank, not on
    the paper's model; the status is the study's."""
    ran = []

    class Study:
        @staticmethod
        def main_study(args):
            ran.append(args.plant)
            return 2

    monkeypatch.setitem(simulate.STUDIES, study, Study)
    assert simulate.main(["--study", study, "--plant", "tank", "--out", str(tmp_path), "--quiet"]) == 2
    assert capsys.readouterr().out.strip().endswith("note: %s" % VALIDITY_NOTE)
    assert simulate.main(["--study", study, "--out", str(tmp_path), "--quiet"]) == 2
    assert VALIDITY_NOTE not in capsys.readouterr().out and ran == ["tank", None]


@pytest.mark.parametrize("study", ["paper-experiments", "identify"])
def test_the_studies_that_report_on_the_tank_themselves_print_no_second_note(study, tmp_path, capsys,
                                                                              monkeypatch) -> None:
    """paper-experiments writes the note into its own report and identify measures the tank plant: simulate
    adds nothing after them."""
    class Study:
        @staticmethod
        def main_study(args):
            return 0

    monkeypatch.setitem(simulate.STUDIES, study, Study)
    assert simulate.main(["--study", study, "--plant", "tank", "--out", str(tmp_path), "--quiet"]) == 0
    assert VALIDITY_NOTE not in capsys.readouterr().out


def test_tank_plant_controller_off_and_com_columns(tmp_path, capsys) -> None:
    out = str(tmp_path / "tank")
    assert simulate.main(["--plant", "tank", "--controller", "off", "--initial-rpy", "20", "0", "0",
                          "--duration", "2", "--out", out, "--quiet"]) == 0
    with open(os.path.join(out, "timeseries.csv")) as stream:
        rows = list(csv.DictReader(stream))
    assert {"com_x", "com_y", "com_z"} <= set(rows[0])
    assert float(rows[-1]["roll_deg"]) < 20.0  # swung back, passively
    with open(os.path.join(out, "metrics.json")) as stream:
        info = json.load(stream)["info"]
    assert info["plant"] == "tank" and info["controller"] == "off"
    assert "note: %s" % VALIDITY_NOTE in capsys.readouterr().out  # no result on it is the robot's
    assert simulate.main(["--duration", "0.5", "--out", str(tmp_path / "paper"), "--quiet"]) == 0
    assert VALIDITY_NOTE not in capsys.readouterr().out
    with pytest.raises(SystemExit):
        simulate.main(["--plant", "tank", "--restoring-offset", "0", "0", "0.01", "--out", out])
