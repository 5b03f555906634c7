"""Installs the package's Python modules; called by catkin_python_setup() in CMakeLists.txt."""
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(
    packages=[
        "quadruped_common",
        "quadruped_common.ros",
        "quadruped_control",
        "quadruped_control.analysis",
        "quadruped_control.control",
        "quadruped_control.control.strokes",
        "quadruped_control.model",
        "quadruped_control.ros",
        "quadruped_control.sim",
        "quadruped_control.sim.plants",
        "quadruped_control.studies",
        "quadruped_drivers",
        "quadruped_drivers.i2c",
        "quadruped_drivers.vn100",
    ],
    package_dir={"": "."},
))
