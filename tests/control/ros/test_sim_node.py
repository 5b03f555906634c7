"""launch/sim.launch hands sim_node (quadruped_control/ros/sim_node.py) the tank the operator names; the node's
closed loop itself runs in the rostests (tests/rostest/sim_*.test)."""
from tests.control.ros.conftest import launch_params


def _sim_node_params(launch: str, *args: str) -> dict:
    return launch_params(launch, "/sim_node", "description:=false", *args)


def test_sim_launch_passes_a_tank_yaml_to_the_tank_plant_and_none_by_default(launch_file):
    launch = launch_file("sim.launch")
    params = _sim_node_params(launch, "plant:=tank", "tank_yaml:=/fits/member_00.yaml")
    assert params["plant"] == "tank" and params["tank_yaml"] == "/fits/member_00.yaml"
    default = _sim_node_params(launch)
    assert default["plant"] == "paper" and default["tank_yaml"] == ""  # sim_node reads "" as config/tank.yaml
