"""vn100_node's reader loop never dies: per-read exceptions and absurd packets are counted, good samples
keep flowing (a colliding packet with a ~1e19 ns stamp used to kill the thread)."""
import pytest

rospy = pytest.importorskip("rospy")
pytest.importorskip("diagnostic_updater")
import rospy.rostime  # noqa: E402

from quadruped_common.monitoring import RateMonitor  # noqa: E402
from quadruped_drivers import vn100_node  # noqa: E402
from quadruped_drivers.vn100.conversions import SensorLimits  # noqa: E402
from quadruped_drivers.vn100.protocol import Vn100Sample  # noqa: E402
from quadruped_drivers.vn100.sample_gate import SampleGate  # noqa: E402


def sample(ns, rate=0.1):
    return Vn100Sample(ns, (0.0, 0.0, 0.0, 1.0), (rate, 0.0, 0.0), (0.0, 0.0, -9.81))


class Driver:
    """Reads scripted results: a list of samples, or an exception to raise."""

    connected = True
    reconnect_max_delay = 1.0

    def __init__(self, script):
        self.script = list(script)
        self.closed = False
        self.connects = 1
        self.disconnects = 0
        self.connect_failures = 0
        self.last_error = ""

    def read_samples(self):
        item = self.script.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    def close(self):
        self.closed = True


class Publisher:
    def __init__(self):
        self.messages = []

    def publish(self, msg):
        self.messages.append(msg)


def test_reader_survives_exceptions_and_absurd_packets(monkeypatch):
    rospy.rostime.set_rostime_initialized(True)
    script = [[sample(5_000_000)], TypeError("unsupported operand"), [sample(10_000_000), sample(10**19)],
              [sample(20_000_000, rate=3.4e38)], ValueError("decoder bug"), [sample(25_000_000), sample(30_000_000)]]
    node = vn100_node.Vn100Node.__new__(vn100_node.Vn100Node)
    node.driver = Driver(script)
    node.gate = SampleGate(SensorLimits(), max_backdate=0.1)
    node.publisher = Publisher()
    node.monitor = RateMonitor(2.0)
    node.published = 0
    node.reader_errors = 0
    node.last_reader_error = ""
    node.last_stamp = None
    node.logged_connects, node.logged_disconnects, node.logged_failures = 1, 0, 0
    node.frame_id = "imu_link"
    node.covariances = {key: [0.0] * 9 for key in ("orientation", "angular_velocity", "linear_acceleration")}
    calls = {"n": 0}

    def is_shutdown():
        calls["n"] += 1
        return calls["n"] > len(script)

    monkeypatch.setattr(vn100_node.rospy, "is_shutdown", is_shutdown)
    node._run()
    assert node.reader_errors == 2 and "ValueError" in node.last_reader_error
    assert len(node.publisher.messages) == 5  # every good sample, none of the out-of-range one
    assert node.gate.counts["angular rate range"] == 1
    stamps = [m.header.stamp for m in node.publisher.messages]
    assert all(a < b for a, b in zip(stamps, stamps[1:]))
    assert node.driver.closed


def test_each_connection_and_each_loss_of_the_link_is_logged_once(monkeypatch):
    """The diagnostics count disconnects; the log says when and why, once per change."""
    lines = []
    monkeypatch.setattr(vn100_node.rospy, "loginfo", lambda fmt, *args: lines.append(("info", fmt % args)))
    monkeypatch.setattr(vn100_node.rospy, "logwarn", lambda fmt, *args: lines.append(("warn", fmt % args)))
    monkeypatch.setattr(vn100_node.rospy, "logerr_throttle", lambda period, msg: lines.append(("error", msg)))
    node = vn100_node.Vn100Node.__new__(vn100_node.Vn100Node)
    node.driver = Driver([])
    node.port = "/dev/vn100"
    node.logged_connects, node.logged_disconnects, node.logged_failures = 0, 0, 0
    node._log_link_changes()
    node._log_link_changes()
    assert lines == [("info", "vn100_node: sensor configured on /dev/vn100 (connection 1)")]
    node.driver.disconnects, node.driver.last_error = 1, "no valid packet for 0.12 s"
    node._log_link_changes()
    node._log_link_changes()
    assert lines[1:] == [("warn", "vn100_node: link lost (no valid packet for 0.12 s); reconnecting at once, "
                                  "then backing off up to 1 s")]
    # A failed attempt to connect (here: no sensor at any rate) is an error in the log (throttled).
    node.driver.connected = False
    node.driver.connect_failures = 1
    node.driver.last_error = "connect failed: no VN-100 answered on /dev/vn100 at 921600, 115200 baud"
    node._log_link_changes()
    node._log_link_changes()
    assert lines[2:] == [("error", "vn100_node: connect failed: no VN-100 answered on /dev/vn100 at 921600, "
                                   "115200 baud")]


def test_every_setting_the_node_reads_is_in_the_schema():
    """The node builds the driver from vn100.yaml's keys (a renamed key must not fail only on the robot)."""
    import inspect
    import re

    from quadruped_drivers.vn100.settings import VN100_KEYS

    used = set(re.findall(r'param\("(\w+)"\)', inspect.getsource(vn100_node.Vn100Node.__init__)))
    assert {"baud", "save_baud", "probe_timeout", "reconnect_initial_delay", "reconnect_max_delay"} <= used
    assert used <= set(VN100_KEYS)
