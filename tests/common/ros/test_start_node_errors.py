"""quadruped_common.ros.node_startup.start_node: a start-up error a restart cannot fix is one FATAL line and
exit status 78 (no traceback); any other error keeps its traceback (re-raised: exit status 1, restarted)."""
import contextlib

import pytest

pytest.importorskip("rospy")

from quadruped_common.config import ParameterError  # noqa: E402
from quadruped_common.ros import node_startup  # noqa: E402
from quadruped_common.startup_errors import EX_CONFIG  # noqa: E402
from quadruped_drivers.i2c.real_bus import I2CBackendError, open_i2c_bus  # noqa: E402


@pytest.fixture
def ros(monkeypatch):
    """rospy's side of start_node recorded instead of done (no master, no heap freeze in the test run)."""
    calls = {"init": [], "fatal": [], "hooks": 0}
    monkeypatch.setattr(node_startup.rospy, "init_node", lambda name: calls["init"].append(name))
    monkeypatch.setattr(node_startup.rospy, "logfatal", lambda *args: calls["fatal"].append(args))
    monkeypatch.setattr(node_startup, "frozen_startup_heap", contextlib.nullcontext)

    def hook():
        calls["hooks"] += 1
    monkeypatch.setattr(node_startup, "stop_xmlrpc_server_on_shutdown", hook)
    return calls


def test_a_missing_i2c_bus_is_one_fatal_line_and_exit_78(ros):
    def build():
        return open_i2c_bus(250)
    with pytest.raises(SystemExit) as stop:
        node_startup.start_node("pwm_node", build)
    assert stop.value.code == EX_CONFIG
    assert stop.value.__cause__ is None and stop.value.__suppress_context__  # no chained traceback
    assert ros["init"] == ["pwm_node"] and ros["hooks"] == 0
    assert len(ros["fatal"]) == 1 and len(ros["fatal"][0]) == 1  # one preformatted line
    line = ros["fatal"][0][0]
    assert line.startswith("pwm_node cannot start: /dev/i2c-250 does not exist. Fix: enable the I2C controller")
    assert "\n" not in line


def test_a_configuration_refused_is_exit_78(ros):
    def build():
        raise ParameterError("hardware.yaml: pwm.frequency_hz: must be at most 1526, got 5000")
    with pytest.raises(SystemExit) as stop:
        node_startup.start_node("pwm_node", build)
    assert stop.value.code == EX_CONFIG
    assert ros["fatal"] == [("pwm_node cannot start: hardware.yaml: pwm.frequency_hz: must be at most 1526, got 5000."
                             " Fix: correct the value named above (in the configuration file or the launch "
                             "argument) and start the launch again",)]


@pytest.mark.parametrize("exc", [RuntimeError("crash while starting"), I2CBackendError("opening /dev/i2c-7 failed: x"),
                                 ConnectionRefusedError(111, "Connection refused")])
def test_other_errors_keep_their_traceback(ros, exc):
    def build():
        raise exc
    with pytest.raises(type(exc)) as raised:
        node_startup.start_node("pwm_node", build)
    assert raised.value is exc
    assert ros["fatal"] == [] and ros["hooks"] == 0


def test_extra_configuration_errors(ros):
    class Refused(Exception):
        pass

    def build():
        raise Refused("no")
    with pytest.raises(SystemExit) as stop:
        node_startup.start_node("x", build, errors=(Refused,))
    assert stop.value.code == EX_CONFIG


def test_a_node_that_starts_is_returned(ros):
    node = object()
    assert node_startup.start_node("pwm_node", lambda: node) is node
    assert ros["hooks"] == 1 and ros["fatal"] == []
