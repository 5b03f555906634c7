"""config/diagnostics_analyzers.yaml: valid for diagnostic_aggregator, and every node's diagnostic_updater
status lands in exactly one analyzer, with or without a namespace."""
import subprocess

import pytest

from quadruped_common.config import ParameterError
from quadruped_control.ros.diagnostics_analyzers import load_analyzers, matching_paths, validate_analyzers

# "<node>: <task>" as diagnostic_updater names them (node names from launch/*.launch, tasks from the nodes)
STATUSES = {
    "vn100_node: imu": "/Sensors/IMU (VN-100)",
    "servo_feedback_node: servo feedback": "/Sensors/Servo feedback (ADS1115 x12)",
    "servo_feedback_node: battery": "/Sensors/Servo feedback (ADS1115 x12)",
    "ms5837_node: depth sensor": "/Sensors/Depth (MS5837)",
    "pwm_node: servo output": "/Actuators (PCA9685)",
    "attitude_controller: control loop": "/Attitude controller",
    "attitude_controller: inputs": "/Attitude controller",
    "sim_node: simulation": "/Simulated robot",
    "visualization: inputs": "/Visualization",
}


@pytest.mark.parametrize("namespace", ["", "uq1/", "/fleet/uq2/"])
def test_every_status_lands_in_exactly_one_analyzer(namespace):
    analyzers = load_analyzers()
    for status, path in STATUSES.items():
        assert matching_paths(namespace + status, analyzers) == [path], status


def test_foreign_statuses_are_left_to_other_analyzers():
    assert matching_paths("camera_node: frames", load_analyzers()) == []


@pytest.mark.parametrize("tree, message", [
    ({}, "non-empty mapping"),
    ({"a": {"type": "diagnostic_aggregator/GenericAnalyzer", "path": "A"}}, "matches nothing"),
    ({"a": {"type": "diagnostic_aggregator/GenericAnalyzer", "contains": ["x"]}}, "needs a 'path'"),
    ({"a": {"type": "Other", "path": "A", "contains": ["x"]}}, "type must be"),
    ({"a": {"type": "diagnostic_aggregator/GenericAnalyzer", "path": "A", "regex": ["("]}}, "bad regex"),
    ({"g": {"type": "diagnostic_aggregator/AnalyzerGroup", "path": "G", "analyzers": {}}}, "g.analyzers"),
])
def test_bad_analyzer_files_are_refused(tree, message):
    with pytest.raises(ParameterError, match=message):
        validate_analyzers(tree)


def test_monitor_launch_starts_the_tether_tools(launch_file):
    """launch/monitor.launch parses and names its nodes: one rqt window with the perspective, or rqt_robot_monitor
    and rqt_reconfigure apart (the GUI packages are Noetic's, not Debian's, so only the launch file is checked
    here, not the programs)."""
    launch = launch_file("monitor.launch")

    def nodes(*args):
        out = subprocess.run(["roslaunch", "--nodes", launch] + list(args), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, universal_newlines=True, timeout=60)
        assert out.returncode == 0, out.stderr
        return set(out.stdout.split())

    assert nodes() == {"/diagnostic_aggregator", "/tuning_gui", "/robot_state_publisher", "/visualization", "/rviz",
                       "/heartbeat"}
    assert nodes("rviz:=false", "description:=false", "aggregator:=false", "perspective:=false") == {
        "/robot_monitor", "/reconfigure", "/heartbeat"}
    assert "/heartbeat" not in nodes("heartbeat:=false")
