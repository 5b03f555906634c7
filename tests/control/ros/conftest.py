"""Fixtures of the ROS-glue tests."""
import os
import shutil

import pytest


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
