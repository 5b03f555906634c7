"""The check of tests/python38_graph.sh bites: a node that ran on the ROS Python (3.11), that was started
without the 3.8 overlay, or that was respawned fails the rostest even when its test cases passed."""
import importlib.util
import json
import os
import sys
from typing import List

import pytest

from tests.repo import REPO_ROOT

_SPEC = importlib.util.spec_from_file_location("python38_graph_check",
                                               os.path.join(REPO_ROOT, "tests", "python38_graph", "check.py"))
check = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(check)

PY38 = "/root/.pyenv/versions/3.8.18/bin/python3.8"
TEST_FILE = os.path.join(REPO_ROOT, "tests", "rostest", "pwm_watchdog.test")  # one <test>: pwm_watchdog_test.py


def start(name: str, command: str, pid: int, prefix: str = "") -> str:
    args = prefix.split() + [command, "__name:=x"]
    return ("[roslaunch][INFO] 2026-01-01 00:00:00,000: process[%s]: start w/ args [%r]\n"
            "[rostest][INFO] 2026-01-01 00:00:00,001: process[%s]: started with pid [%d]\n" % (name, args, name, pid))


@pytest.fixture
def run(tmp_path, monkeypatch):
    """run(starts, records[, extra, prefix]) -> exit status of check.py on a made-up rostest run whose
    test case passed."""
    overlay = tmp_path / "overlay"
    (tmp_path / "records").mkdir()
    (tmp_path / "log").mkdir()
    results = tmp_path / "results" / "underwater_quadruped"
    results.mkdir(parents=True)
    (results / "rosunit-pwm_watchdog.xml").write_text('<testsuite tests="1" failures="0" errors="0"/>')
    node_dir = str(overlay / "lib" / "underwater_quadruped")

    def _run(starts: List[tuple], records: dict, extra: List[str] = (), prefix: str = "") -> int:
        (tmp_path / "log" / "rostest-host-1.log").write_text("".join(
            start(name, os.path.join(node_dir, node) if via_overlay else "/ws/devel/lib/underwater_quadruped/" + node,
                  pid, prefix)
            for name, node, pid, via_overlay in starts)
            + start("pwm_watchdog_test-9", os.path.join(REPO_ROOT, "tests/rostest/pwm_watchdog_test.py"), 99))
        for pid, (version, exe, node) in records.items():
            (tmp_path / "records" / ("%d.json" % pid)).write_text(json.dumps(
                {"pid": pid, "version": version, "executable": exe, "script": "/repo/nodes/" + node, "argv": []}))
        monkeypatch.setattr(sys, "argv", ["check.py", "--rostest-exit", "0", "--test-file", TEST_FILE,
                                          "--results", str(tmp_path / "results"), "--log-dir", str(tmp_path / "log"),
                                          "--records", str(tmp_path / "records"), "--overlay", str(overlay),
                                          "--keep", "visualization_node"] + list(extra))
        return check.main()

    return _run


def test_nodes_on_3_8_through_the_overlay_pass(run, capsys):
    status = run([("sim_node-1", "sim_node", 11, True), ("pwm_node-2", "pwm_node", 12, True),
                  ("visualization-3", "visualization_node", 13, True)],
                 {11: ("3.8.18", PY38, "sim_node"), 12: ("3.8.18", PY38, "pwm_node")})
    out = capsys.readouterr().out
    assert status == 0, out
    assert "pwm_node-2 pid 12: pwm_node on Python 3.8.18" in out
    assert "visualization_node on the ROS Python, by design" in out
    assert out.rstrip().endswith("cases: 1 passed, 0 failed")


def test_a_node_that_ran_on_3_11_fails(run, capsys):
    status = run([("sim_node-1", "sim_node", 11, True), ("pwm_node-2", "pwm_node", 12, True)],
                 {11: ("3.8.18", PY38, "sim_node"), 12: ("3.11.2", "/usr/bin/python3.11", "pwm_node")})
    assert status == 1
    assert "PROBLEM: pwm_node-2 pid 12: pwm_node on Python 3.11.2" in capsys.readouterr().out


def test_a_node_without_its_record_or_outside_the_overlay_fails(run, capsys):
    status = run([("sim_node-1", "sim_node", 11, True), ("pwm_node-2", "pwm_node", 12, False)],
                 {11: ("3.8.18", PY38, "sim_node")})
    out = capsys.readouterr().out
    assert status == 1
    assert "pwm_node started without the 3.8 overlay" in out
    status = run([("sim_node-1", "sim_node", 11, True), ("pwm_node-2", "pwm_node", 21, True)], {})
    assert status == 1
    assert "pwm_node left no Python 3.8 record" in capsys.readouterr().out


def test_no_node_on_3_8_at_all_fails(run, capsys):
    assert run([("visualization-3", "visualization_node", 13, True)], {}) == 1
    assert "no node ran on Python 3.8" in capsys.readouterr().out


def test_a_respawn_fails_unless_the_test_kills_that_node(run, capsys):
    starts = [("pwm_node-2", "pwm_node", 12, True), ("pwm_node-2", "pwm_node", 22, True)]
    records = {12: ("3.8.18", PY38, "pwm_node"), 22: ("3.8.18", PY38, "pwm_node")}
    assert run(starts, records) == 1
    assert "pwm_node-2 started 2 times" in capsys.readouterr().out
    assert run(starts, records, ["--restarts-ok", "pwm_node"]) == 0


def test_a_launch_prefix_is_looked_through(run, capsys):
    starts = [("pwm_node-2", "pwm_node", 12, True)]
    assert run(starts, {12: ("3.8.18", PY38, "pwm_node")}, prefix="chrt -f 20") == 0
    assert "pwm_node-2 pid 12: pwm_node on Python 3.8.18" in capsys.readouterr().out
    assert run([("pwm_node-2", "pwm_node", 12, False)], {}, prefix="chrt -f 20") == 1
    assert "pwm_node started without the 3.8 overlay" in capsys.readouterr().out
