"""The operator's tools: ``uq``'s pure part (quadruped_control.ros.operator_cli: arguments, answers, the setpoint
check), the rqt perspective of monitor.launch and the recording of the controller's telemetry. ``uq`` against
the simulated robot: tests/rostest/operator_cli.test."""
import ast
import json
import math
import os
import re
import shlex
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from quadruped_common.so3 import rot_z, rpy_to_rot
from quadruped_control.ros import operator_cli as cli
from tests.repo import REPO_ROOT
from tests.test_readme import check_rqt_plot, documented_commands

PERSPECTIVE = os.path.join(REPO_ROOT, "config", "rqt", "tuning.perspective")


def parse(line):
    return cli.parse_args(shlex.split(line))


def test_every_command_parses():
    assert parse("arm").command == "arm" and parse("--timeout 2 disarm").timeout == 2.0
    assert [parse(c).command for c in ("stop", "reset", "status")] == ["stop", "reset", "status"]
    args = parse("setpoint -10 5.5 90 --tilt")
    assert (args.roll, args.pitch, args.yaw, args.frame) == (-10.0, 5.5, 90.0, "tilt")
    assert parse("setpoint 30 0 0").frame == "" and parse("setpoint 0 0 90 --absolute").frame == "absolute"
    assert parse("sequence step_test").name == "step_test"


@pytest.mark.parametrize("line", ["", "fly", "setpoint 30 0", "setpoint 181 0 0", "setpoint nan 0 0",
                                  "setpoint 0 0 0 --relative --tilt", "sequence no_such_sequence",
                                  "--timeout 0 status", "arm true"])
def test_bad_arguments_exit_2(line, capsys):
    with pytest.raises(SystemExit) as stop:
        parse(line)
    assert stop.value.code == 2 and "usage: uq" in capsys.readouterr().err


def test_every_documented_uq_command_parses():
    lines = [words[3:] for _, _, words in documented_commands() if words[:3] == ["rosrun", "underwater_quadruped",
                                                                                "uq"]]
    assert len(lines) >= 8
    for words in lines:
        cli.parse_args(words)


def test_the_status_line():
    disarmed = cli.Status(armed=False, holding=True, hold_reason="disarmed", rpy=(0.04, -1.0, 12.3),
                          setpoint=(0.0, 0.0, 0.0), heading=math.nan, estop=True,
                          arming="arming refused: e-stop: latched")
    assert cli.format_status(disarmed) == ("disarmed | E-STOP LATCHED | attitude roll 0.0 pitch -1.0 yaw 12.3 deg | "
                                           "setpoint roll 0.0 pitch 0.0 yaw 0.0 deg | arming refused: e-stop: latched")
    armed = cli.Status(armed=True, holding=False, hold_reason="", rpy=(29.0, 0.0, 100.0),
                       setpoint=(30.0, 0.0, -170.0), heading=170.0, estop=False, arming="ready to arm")
    assert cli.format_status(armed) == (
        "armed, stroking | e-stop clear | attitude roll 29.0 pitch 0.0 yaw 100.0 deg | setpoint roll 30.0 pitch 0.0 "
        "yaw -170.0 deg (yaw 20.0 from the heading at arming 170.0)")
    holding = cli.Status(armed=True, holding=True, hold_reason="soft start: legs to the nominal pose")
    assert cli.format_status(holding) == ("armed, holding (soft start: legs to the nominal pose) | e-stop unknown (no "
                                          "estop_state) | attitude unknown | setpoint unknown")


def test_a_setpoint_is_taken_when_the_controller_tracks_what_its_yaw_reference_makes_of_it():
    rpy = (20.0, -10.0, 30.0)
    given = rpy_to_rot(*np.radians(rpy))
    relative = cli.expected_setpoint(rpy, "relative", 90.0)
    assert cli.setpoint_taken(rot_z(math.radians(90.0)) @ given, relative)
    assert not cli.setpoint_taken(given, relative)
    assert cli.setpoint_taken(given, cli.expected_setpoint(rpy, "relative", math.nan))  # not armed yet: as given
    assert cli.setpoint_taken(given, cli.expected_setpoint(rpy, "absolute", 90.0))
    tilt = cli.expected_setpoint(rpy, "tilt", 90.0)
    assert tilt.yaw_free and cli.setpoint_taken(rot_z(1.0) @ given, tilt)  # yaw free: any yaw with that tilt
    assert not cli.setpoint_taken(rpy_to_rot(math.radians(25.0), math.radians(-10.0), 0.0), tilt)


def test_the_setpoint_answer_shows_the_world_angles_and_the_relative_yaw():
    assert cli.setpoint_answer((30.0, 0.0, 0.0), "relative", (30.0, 0.0, 87.0), 87.0) == (
        "setpoint taken: roll 30.0 pitch 0.0 yaw 0.0 deg, relative; world roll 30.0 pitch 0.0 yaw 87.0 deg "
        "(yaw 0.0 from the heading at arming 87.0)")
    assert cli.setpoint_answer((20.0, 0.0, 0.0), "tilt", (20.0, 0.0, 3.0), None).endswith("tilt (yaw free)")
    assert cli.format_rpy((-0.01, -0.04, 0.0)) == "roll 0.0 pitch 0.0 yaw 0.0 deg"


# --- the rqt perspective and the recorded telemetry -------------------------------------------------------------

def perspective_value(entry):
    """A perspective key's value, as qt_gui's import reads it (eval of a repr; literal_eval suffices here)."""
    assert entry["type"] == "repr", entry
    return ast.literal_eval(entry["repr"])


def test_the_perspective_parses_and_starts_the_tuning_plugins():
    with open(PERSPECTIVE) as stream:
        data = json.load(stream)
    manager = data["groups"]["pluginmanager"]
    plugins = perspective_value(manager["keys"]["running-plugins"])
    assert set(plugins) == {"rqt_reconfigure/Param", "rqt_robot_monitor/RobotMonitor", "rqt_plot/Plot"}
    plots = [manager["groups"]["plugin__rqt_plot__Plot__%d" % n]["groups"]["plugin"]["keys"]
             for n in plugins["rqt_plot/Plot"]]
    topics = [topic for plot in plots for topic in perspective_value(plot["topics"])]
    assert all(perspective_value(plot["autoscroll"]) is True for plot in plots)
    for field in ("x", "y", "z"):
        for name in ("rpy_deg", "setpoint_rpy_deg", "error_rpy_deg"):
            assert "/telemetry/%s/vector/%s" % (name, field) in topics


def test_every_topic_the_perspective_plots_is_a_number_the_package_publishes():
    pytest.importorskip("geometry_msgs.msg")  # the fields of ROS's own messages (not in the Python 3.8 venv)
    with open(PERSPECTIVE) as stream:
        groups = json.load(stream)["groups"]["pluginmanager"]["groups"]
    topics = [t for name, group in groups.items() if name.startswith("plugin__rqt_plot__Plot__")
              for t in perspective_value(group["groups"]["plugin"]["keys"]["topics"])]
    check_rqt_plot(["rqt_plot"] + topics)


def test_monitor_launch_opens_the_perspective_of_the_package():
    root = ET.parse(os.path.join(REPO_ROOT, "launch", "monitor.launch")).getroot()
    default = next(arg.get("default") for arg in root.iter("arg") if arg.get("name") == "perspective_file")
    assert default == "$(find underwater_quadruped)/config/rqt/tuning.perspective" and os.path.exists(PERSPECTIVE)


def test_the_controllers_telemetry_is_recorded():
    with open(os.path.join(REPO_ROOT, "quadruped_control", "ros", "attitude_controller_node.py")) as stream:
        published = set(re.findall(r"Publisher\(\s*\"(telemetry/\w+)\"", stream.read()))
    assert len(published) == 4
    node = ET.parse(os.path.join(REPO_ROOT, "launch", "record.launch")).getroot().find("node")
    assert published <= set(shlex.split(node.get("args")))
