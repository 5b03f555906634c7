"""launch/tank_day.launch: the tank_day node with the plan's parameters, on the robot's stack or, with sim:=true, on
the simulated robot hanging in the tank and going on by itself; its day, end to end, is tests/rostest/tank_day.test."""
from tests.control.ros.conftest import launch_params


def test_on_the_robot_the_day_waits_for_the_operator_on_the_experiment_gains(launch_file):
    launch = launch_file("tank_day.launch")
    day = launch_params(launch, "/tank_day", "day_dir:=/data/tank_day_1")
    assert day["day_dir"] == "/data/tank_day_1" and day["auto_continue"] is False
    assert (day["hang_seconds"], day["repeats"], day["rows"], day["yaw_reference"]) == (660.0, 2, [], "relative")
    assert launch_params(launch, "/attitude_controller")["gain_set"] == "experiment"
    assert launch_params(launch, "/sim_node") == {}


def test_the_simulated_day_hangs_in_a_tank_that_pushes_and_goes_on_by_itself(launch_file):
    launch = launch_file("tank_day.launch")
    args = ("sim:=true", "rows:=[roll 30, pitch 75]", "tank_disturbance:=[0.005, 2.0]", "table1_seconds:=6")
    day = launch_params(launch, "/tank_day", *args)
    assert day["auto_continue"] is True and day["rows"] == ["roll 30", "pitch 75"] and day["table1_seconds"] == 6.0
    sim = launch_params(launch, "/sim_node", *args)
    assert sim["plant"] == "tank" and sim["tank_disturbance"] == [0.005, 2.0]
