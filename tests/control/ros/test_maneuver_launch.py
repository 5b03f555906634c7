"""The launch files that run a setpoint sequence hand the maneuver node (quadruped_control/ros/maneuver_node.py)
its protocol; what the node commands from its parameters is tested in tests/control/control/
test_setpoint_sequence.py, and its run on the simulated robot in the main job."""
from tests.control.ros.conftest import launch_params


def test_the_step_test_launch_records_and_runs_the_step_test_protocol_on_the_robot(launch_file):
    launch = launch_file("step_test.launch")
    params = launch_params(launch, "/maneuver")
    assert params["protocol"] == "step_test" and params["timeout"] == 600 and params["delay"] == 30
    controller = launch_params(launch, "/attitude_controller")
    assert controller, "robot.launch's controller is part of the step test"


def test_the_sim_maneuver_launch_runs_a_protocol_on_the_tank_it_is_given(launch_file):
    launch = launch_file("sim_maneuver.launch")
    params = launch_params(launch, "/maneuver", "bag_dir:=/tmp", "protocol:=step_test")
    assert params["protocol"] == "step_test"
    sim = launch_params(launch, "/sim_node", "bag_dir:=/tmp", "plant:=tank", "tank_yaml:=/fits/member_00.yaml")
    assert sim["plant"] == "tank" and sim["tank_yaml"] == "/fits/member_00.yaml"
    default = launch_params(launch, "/maneuver", "bag_dir:=/tmp")
    assert default["protocol"] == "" and default["sequence"] == [] and default["roll"] == 45
    given = launch_params(launch, "/maneuver", "bag_dir:=/tmp", "sequence:=[[20, 0, 0, 40], [12, 0, 0, 40.5]]")
    assert given["sequence"] == [[20, 0, 0, 40], [12, 0, 0, 40.5]]
