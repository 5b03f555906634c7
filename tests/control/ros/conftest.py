"""Fixtures of the ROS-glue tests."""
import os
import shutil
import subprocess

import pytest
import yaml


@pytest.fixture
def launch_file():
    """``launch_file(NAME)``: the path of the package's launch/NAME as roslaunch finds it; skips the test when
    the workspace's devel/setup.bash is not sourced or roslaunch is not installed."""
    rospkg = pytest.importorskip("rospkg")
    try:
        share = rospkg.RosPack().get_path("underwater_quadruped")
    except rospkg.ResourceNotFound:
        pytest.skip("the workspace's devel/setup.bash is not sourced")
    if shutil.which("roslaunch") is None:
        pytest.skip("roslaunch not installed")
    return lambda name: os.path.join(share, "launch", name)


def launch_params(launch: str, node: str, *args: str) -> dict:
    """The private parameters of ``node`` (its resolved name, e.g. /sim_node) as ``roslaunch --dump-params
    LAUNCH ARGS`` resolves them."""
    out = subprocess.run(["roslaunch", "--dump-params", launch] + list(args),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=60)
    assert out.returncode == 0, out.stderr
    params = yaml.safe_load(out.stdout)
    return {key[len(node) + 1:]: value for key, value in params.items() if key.startswith(node + "/")}
