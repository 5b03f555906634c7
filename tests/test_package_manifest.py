"""package.xml is complete and minimal for the Python the package runs: every third-party module the
nodes and libraries import has its rosdep key declared, and every declared Python key is imported."""
import ast
import os
import sys
import xml.etree.ElementTree as ET

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIRST_PARTY = {"quadruped_common", "quadruped_control", "quadruped_drivers", "underwater_quadruped"}
#: top-level module -> rosdep key (ROS packages are their own key)
KEYS = {
    "numpy": "python3-numpy", "yaml": "python3-yaml", "serial": "python3-serial",
    "matplotlib": "python3-matplotlib", "rospkg": "python3-rospkg", "tqdm": "python3-tqdm",
    "scipy": "python3-scipy", "rosbags": "python3-rosbags-pip",
    "distributed": "python3-dask-distributed-pip", "dask": "python3-dask-distributed-pip",
    "cma": "python3-cma-pip", "SALib": "python3-salib-pip",
    "adafruit_extended_bus": "python3-adafruit-extended-bus-pip",
    "adafruit_pca9685": "python3-adafruit-circuitpython-pca9685-pip",
    "adafruit_ads1x15": "python3-adafruit-circuitpython-ads1x15-pip",
    "adafruit_tca9548a": "python3-adafruit-circuitpython-tca9548a-pip",
    "Jetson": "python3-jetson-gpio-pip",
}
#: imported where present, with a plain-Python path without them: deliberately not a dependency of the
#: package (numba: the batched simulator's compiled loops, quadruped_common/jit.py; requirements.txt
#: installs it on the development machine, the robot never runs the batch)
OPTIONAL = {"numba"}


def runtime_imports():
    """Top-level modules imported anywhere (also lazily) by the package's runtime code."""
    found = set()
    sources = [os.path.join(ROOT, "nodes", n) for n in os.listdir(os.path.join(ROOT, "nodes"))]
    for package in sorted(FIRST_PARTY - {"underwater_quadruped"}):
        for folder, _dirs, files in os.walk(os.path.join(ROOT, package)):
            sources += [os.path.join(folder, f) for f in files if f.endswith(".py")]
    for path in sources:
        with open(path) as stream:
            tree = ast.parse(stream.read(), path)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                found.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found


def declared(kinds=("exec_depend", "depend")):
    root = ET.parse(os.path.join(ROOT, "package.xml")).getroot()
    return {e.text.strip() for e in root if e.tag in kinds}


@pytest.mark.skipif(not hasattr(sys, "stdlib_module_names"), reason="needs Python >= 3.10 to tell the stdlib apart")
def test_every_imported_module_is_declared():
    third_party = runtime_imports() - set(sys.stdlib_module_names) - FIRST_PARTY - {"__future__"} - OPTIONAL
    keys = {KEYS.get(module, module) for module in third_party}
    assert keys - declared() == set(), "imported but not in package.xml"


def test_every_declared_python_key_is_imported():
    python_keys = {k for k in declared() if k.startswith("python3-")}
    used = {KEYS[m] for m in runtime_imports() if m in KEYS}
    assert python_keys - used == set(), "declared in package.xml but imported nowhere"
