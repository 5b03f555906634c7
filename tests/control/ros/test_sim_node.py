"""launch/sim.launch hands sim_node (quadruped_control/ros/sim_node.py) the tank the operator names; the node's
closed loop itself runs in the rostests (tests/rostest/sim_*.test)."""
import subprocess

import yaml


def _sim_node_params(launch: str, *args: str) -> dict:
    """sim_node's private parameters as ``roslaunch --dump-params LAUNCH ARGS`` resolves them."""
    out = subprocess.run(["roslaunch", "--dump-params", launch, "description:=false"] + list(args),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=60)
    assert out.returncode == 0, out.stderr
    params = yaml.safe_load(out.stdout)
    return {key[len("/sim_node/"):]: value for key, value in params.items() if key.startswith("/sim_node/")}


def test_sim_launch_passes_a_tank_yaml_to_the_tank_plant_and_none_by_default(launch_file):
    launch = launch_file("sim.launch")
    params = _sim_node_params(launch, "plant:=tank", "tank_yaml:=/fits/member_00.yaml")
    assert params["plant"] == "tank" and params["tank_yaml"] == "/fits/member_00.yaml"
    default = _sim_node_params(launch)
    assert default["plant"] == "paper" and default["tank_yaml"] == ""  # sim_node reads "" as config/tank.yaml
