"""docs/configuration.md holds each configuration file's table exactly as its schema declares it.

Each table sits between ``<!-- schema: FILE -->`` and ``<!-- end schema -->``; when a schema changes, rewrite
them with ``.venv/bin/python -m tests.test_configuration_docs``.
"""
from __future__ import annotations

import importlib
import os
import re
from typing import Dict

import pytest

from quadruped_common.config import config_path, load_yaml
from tests.repo import REPO_ROOT

DOC = os.path.join(REPO_ROOT, "docs", "configuration.md")
#: file -> "module:attribute" of its Schema
SCHEMAS = {
    "robot.yaml": "quadruped_common.robot:ROBOT_SCHEMA",
    "hardware.yaml": "quadruped_drivers.hardware_config:HARDWARE_SCHEMA",
    "servo_calibration.yaml": "quadruped_drivers.calibration:CALIBRATION_SCHEMA",
    "vn100.yaml": "quadruped_drivers.vn100.settings:VN100_SCHEMA",
    "controller.yaml": "quadruped_control.control.controller_config:CONTROLLER_SCHEMA",
    "simulation.yaml": "quadruped_control.sim.simulation:SIMULATION_SCHEMA",
    "safety.yaml": "quadruped_control.control.safety_config:SAFETY_SCHEMA",
}
_BLOCK = re.compile(r"(<!-- schema: (\S+) -->\n)(.*?)(<!-- end schema -->)", re.S)


def schema(name: str):
    module, attribute = SCHEMAS[name].split(":")
    return getattr(importlib.import_module(module), attribute)


def tables_in_doc() -> Dict[str, str]:
    with open(DOC, encoding="utf-8") as f:
        return {m.group(2): m.group(3) for m in _BLOCK.finditer(f.read())}


@pytest.mark.parametrize("name", sorted(SCHEMAS))
def test_docs_table_is_the_schema(name):
    assert tables_in_doc().get(name) == schema(name).table(), (
        "docs/configuration.md's table of %s differs from its schema: run .venv/bin/python -m "
        "tests.test_configuration_docs" % name)


@pytest.mark.parametrize("name", sorted(SCHEMAS))
def test_shipped_file_reads_and_declares_only_schema_keys(name):
    values = schema(name).read(load_yaml(config_path(name)))
    assert values and schema(name).file == name


def test_every_schema_is_in_the_doc():
    assert sorted(tables_in_doc()) == sorted(SCHEMAS)


def main() -> None:
    """Rewrite the doc's tables from the schemas."""
    with open(DOC, encoding="utf-8") as f:
        text = f.read()
    text = _BLOCK.sub(lambda m: m.group(1) + schema(m.group(2)).table() + m.group(4), text)
    with open(DOC, "w", encoding="utf-8") as f:
        f.write(text)


if __name__ == "__main__":
    main()
