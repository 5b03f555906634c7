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
    reconnect_interval = 1.0

    def __init__(self, script):
        self.script = list(script)
        self.closed = False
        self.connects = 1
        self.disconnects = 0
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
    node.logged_connects, node.logged_disconnects = 1, 0
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
    node = vn100_node.Vn100Node.__new__(vn100_node.Vn100Node)
    node.driver = Driver([])
    node.port = "/dev/vn100"
    node.logged_connects, node.logged_disconnects = 0, 0
    node._log_link_changes()
    node._log_link_changes()
    assert lines == [("info", "vn100_node: sensor configured on /dev/vn100 (connection 1)")]
    node.driver.disconnects, node.driver.last_error = 1, "no valid packet for 0.12 s"
    node._log_link_changes()
    node._log_link_changes()
    assert lines[1:] == [("warn", "vn100_node: link lost (no valid packet for 0.12 s); reconnecting every 1 s")]
