"""Installs the package's Python modules; called by catkin_python_setup() in CMakeLists.txt."""
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(
    packages=[
        "quadruped_common",
        "quadruped_control",
        "quadruped_control.plants",
        "quadruped_control.studies",
        "quadruped_control.strokes",
        "quadruped_drivers",
        "quadruped_drivers.i2c",
        "quadruped_drivers.vn100",
    ],
    package_dir={"": "."},
))
