"""The floors of the code base (README "Layout", contracts in .importlinter) hold, and the check bites:
an import that runs the wrong way, or an import circle, makes `lint-imports` fail."""
import os
import shutil
import subprocess
import sys

import pytest

from tests.repo import REPO_ROOT

pytest.importorskip("importlinter")
PACKAGES = ("quadruped_common", "quadruped_drivers", "quadruped_control")
CONTRACTS = os.path.join(REPO_ROOT, ".importlinter")
#: the console script of the interpreter running the tests (the venv's), else the one on PATH
LINT_IMPORTS = os.path.join(os.path.dirname(sys.executable), "lint-imports")
if not os.path.exists(LINT_IMPORTS):
    LINT_IMPORTS = shutil.which("lint-imports") or "lint-imports"


def lint_imports(root: str) -> subprocess.CompletedProcess:
    """`lint-imports` with the project's contracts on the packages below ``root``."""
    env = dict(os.environ, PYTHONPATH=root)
    return subprocess.run([LINT_IMPORTS, "--config", CONTRACTS, "--no-cache"],
                          cwd=root, env=env, capture_output=True, text=True, timeout=120)


def copy_of_the_tree(tmp_path) -> str:
    for package in PACKAGES:
        shutil.copytree(os.path.join(REPO_ROOT, package), str(tmp_path / package),
                        ignore=shutil.ignore_patterns("__pycache__"))
    return str(tmp_path)


def add_import(root: str, module: str, statement: str) -> None:
    path = os.path.join(root, *module.split(".")) + ".py"
    with open(path, "a") as stream:
        stream.write("\n%s  # the wrong way\n" % statement)


def test_the_tree_keeps_every_contract():
    result = lint_imports(REPO_ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "3 kept, 0 broken" in result.stdout


@pytest.mark.parametrize("module, statement, contract", [
    # a model module using the simulator: model is the bottom floor of quadruped_control
    ("quadruped_control.model.kinematics", "from quadruped_control.sim import simulation",
     "quadruped_control: model < control"),
    # control and analysis are independent of each other
    ("quadruped_control.analysis.metrics", "from quadruped_control.control import allocation",
     "quadruped_control: model < control"),
    # a driver borrowing from the controller package
    ("quadruped_drivers.calibration", "from quadruped_control.model import params",
     "Packages: quadruped_common below quadruped_drivers"),
    # a circle inside one floor: robot <-> so3 in quadruped_common
    ("quadruped_common.so3", "from quadruped_common import robot", "No import circle"),
])
def test_a_reversed_import_breaks_a_contract(tmp_path, module, statement, contract):
    root = copy_of_the_tree(tmp_path)
    if contract == "No import circle":
        add_import(root, "quadruped_common.robot", "from quadruped_common import so3")
    add_import(root, module, statement)
    result = lint_imports(root)
    assert result.returncode == 1, result.stdout + result.stderr
    broken = [line for line in result.stdout.splitlines() if line.endswith("BROKEN")]
    assert any(line.startswith(contract) for line in broken), result.stdout
