"""VN-100 driver against the byte-level fake: handshake, decoding, corruption, reconnect, pty; the baud
rate search and the reconnection back-off are in test_baud_and_reconnect.py."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from quadruped_common.so3 import quat_to_rot, rot_x, rot_z, rot_to_quat
from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.conversions import vn_to_ros
from quadruped_drivers.vn100.driver import Vn100Driver, Vn100Error, serial_port_factory
from quadruped_drivers.vn100.fake import (FakeVn100, InMemoryPort, ManualClock, NoiseModel,
                                          PtyFakeVn100)

HANDSHAKE = (vp.async_pause_command() + vp.read_model_command() + vp.read_serial_number_command()
             + vp.disable_ascii_output_command()
             + vp.ascii_command("VNWRG,75,1,4,01,0131") + vp.async_resume_command())

TRUTH_Q = rot_to_quat(rot_z(0.7) @ rot_x(0.2))
TRUTH_W = np.array([0.1, -0.2, 0.3])
TRUTH_A = np.array([0.5, -1.0, 9.7])


class Rig:
    """Fake sensor + in-memory port + driver sharing one manual clock.

    ``baud``: the driver's configured rate (with it the port models the rate and the driver searches;
    ``None``: rate not modelled, no search); ``sensor_baud``: the rate stored in the fake (factory
    115200); ``driver_kwargs`` go to the driver, ``fake_kwargs`` to the fake. ``open_times`` /
    ``port_rates``: when and at which rate the driver opened the port; ``log``: the driver's log lines."""

    def __init__(self, rate_hz: float = 200.0, link_clock=None, baud=None, sensor_baud=115200,
                 driver_kwargs=None, clock=None, **fake_kwargs) -> None:
        self.clock = clock if clock is not None else ManualClock(100.0)
        self.device = FakeVn100(boot_time=99.0, baud=sensor_baud, **fake_kwargs)
        self.ports = []
        self.open_attempts = 0
        self.open_times = []
        self.port_rates = []
        self.log = []
        inner = InMemoryPort.factory(self.device, clock=self.clock, sleep=self.clock.sleep)

        def factory(rate=None):
            self.open_attempts += 1
            self.open_times.append(self.clock.now)
            self.port_rates.append(rate)
            port = inner(rate)
            self.ports.append(port)
            return port

        kwargs = dict(reconnect_initial_delay=0.02, reconnect_max_delay=1.0, baud=baud,
                      port_name="/dev/vn100", log=self.log.append)
        kwargs.update(driver_kwargs or {})
        self.driver = Vn100Driver(factory, rate_hz=rate_hz, clock=self.clock, link_clock=link_clock,
                                  **kwargs)

    def run(self, seconds: float, step: float = 0.01):
        out = []
        for _ in range(int(round(seconds / step))):
            self.clock.sleep(step)
            out += self.driver.read_samples()
        return out

    def run_until_sample(self, limit: float, step: float = 0.001):
        """Read every ``step`` until a sample arrives; the clock time then (None within ``limit`` s)."""
        end = self.clock.now + limit
        while self.clock.now < end:
            self.clock.sleep(step)
            if self.driver.read_samples():
                return self.clock.now
        return None


def test_handshake_bytes_exact_and_model_read():
    rig = Rig()
    rig.driver.connect()
    assert bytes(rig.ports[0].bytes_written) == HANDSHAKE
    assert rig.driver.model == "VN-100T-CR"
    assert rig.driver.serial_number == "0100012345"
    assert rig.driver.connected and rig.driver.last_error == ""
    assert rig.device.ascii_output_type == 0
    assert rig.device.binary_config[75] == (1, 4, {1: 0x0131})


def test_samples_decode_to_truth_at_configured_rate():
    rig = Rig()
    rig.device.set_state(TRUTH_Q, TRUTH_W, TRUTH_A)
    samples = rig.run(1.0)
    assert 195 <= len(samples) <= 205
    stamps = np.diff([s.time_startup_ns for s in samples])
    assert np.all(stamps == 5_000_000)
    for s in samples:
        reading = vn_to_ros(s.quaternion_xyzw, s.angular_rate, s.acceleration)
        assert abs(abs(np.dot(reading.orientation_xyzw, TRUTH_Q)) - 1.0) < 1e-6
        np.testing.assert_allclose(reading.angular_velocity, TRUTH_W, atol=1e-6)
        np.testing.assert_allclose(reading.linear_acceleration, TRUTH_A, atol=1e-5)
    assert rig.driver.parser.crc_errors == 0
    # The factory-default VNYMR lines before the pause never reach the caller as samples.
    assert rig.driver.bad_ascii_lines == 0


@pytest.mark.parametrize("rate, divisor", [(800, 1), (400, 2), (50, 16), (1, 800)])
def test_rates_dividing_800_accepted(rate, divisor):
    driver = Vn100Driver(lambda: None, rate_hz=rate)
    assert driver.rate_divisor == divisor


@pytest.mark.parametrize("rate", [300.0, 0.0, -1.0, float("nan"), 1000.0])
def test_bad_rate_raises(rate):
    with pytest.raises(ValueError):
        Vn100Driver(lambda: None, rate_hz=rate)


def test_corrupt_and_dropped_packets_counted_and_skipped():
    rig = Rig(corrupt_probability=0.2, drop_probability=0.05, rng=7)
    rig.device.set_state(TRUTH_Q, TRUTH_W, TRUTH_A)
    samples = rig.run(2.0)
    parser = rig.driver.parser
    assert rig.device.packets_corrupted > 20 and rig.device.packets_dropped > 0
    assert parser.crc_errors + parser.unsupported_packets >= 0.5 * rig.device.packets_corrupted
    assert len(samples) >= rig.device.packets_sent - rig.device.packets_corrupted - 2
    for s in samples:  # every delivered sample is an intact one
        np.testing.assert_allclose(s.angular_rate, [0.1, 0.2, -0.3], atol=1e-6)


def test_noise_is_seeded_and_has_the_requested_spread():
    def rates(seed):
        rig = Rig(noise_std=NoiseModel(attitude=0.01, angular_rate=0.05, acceleration=0.2),
                  rng=seed)
        return np.array([s.angular_rate for s in rig.run(2.0)])

    a, b = rates(3), rates(3)
    np.testing.assert_array_equal(a, b)
    assert np.std(a[:, 0]) == pytest.approx(0.05, rel=0.2)


def test_disconnect_and_reconnect_with_injected_clock():
    rig = Rig()
    assert len(rig.run(0.2)) > 30
    rig.device.disconnect()
    assert rig.driver.read_samples() == []
    assert not rig.driver.connected and rig.driver.disconnects == 1
    assert "serial error" in rig.driver.last_error
    attempts = rig.open_attempts
    assert rig.driver.read_samples() == []
    assert rig.open_attempts == attempts + 1  # the first attempt is immediate
    assert rig.driver.connect_failures == 1 and "connect failed" in rig.driver.last_error
    assert rig.driver.read_samples() == []
    assert rig.open_attempts == attempts + 1  # then the back-off (0.02 s, doubling)
    rig.device.reconnect()  # the sensor power-cycled: factory settings, must be reconfigured
    samples = rig.run(0.5)
    assert len(samples) > 80 and rig.driver.connected
    assert rig.device.binary_config[75] == (1, 4, {1: 0x0131})
    assert rig.driver.disconnects == 1 and rig.driver.connects == 2
    assert not rig.ports[0].is_open


class RejectingFake(FakeVn100):
    """Answers the binary output configuration with ``$VNERR,0C`` (insufficient baud rate)."""

    def _write_register(self, args):
        if args and args[0] == "75":
            self._reply("VNERR,0C")
        else:
            super()._write_register(args)


def test_sensor_error_fails_connect_with_reason_and_read_samples_survives():
    clock = ManualClock(5.0)
    device = RejectingFake()
    driver = Vn100Driver(InMemoryPort.factory(device, clock=clock, sleep=clock.sleep),
                         clock=clock)
    with pytest.raises(Vn100Error, match="insufficient baud rate"):
        driver.connect()
    assert not driver.connected
    assert driver.read_samples() == []  # no new attempt before the back-off delay
    assert driver.connect_failures == 1
    clock.sleep(1.5)
    assert driver.read_samples() == []
    assert driver.connect_failures == 2 and "insufficient baud rate" in driver.last_error


class SilentFake(FakeVn100):
    def write(self, data, baud=None):
        self._check_connected()
        return len(data)


def test_silent_device_times_out_after_retries():
    clock = ManualClock()
    device = SilentFake()
    driver = Vn100Driver(InMemoryPort.factory(device, clock=clock, sleep=clock.sleep),
                         clock=clock, probe_timeout=0.2, command_retries=2)
    with pytest.raises(Vn100Error, match="no reply to \\$VNRRG,01"):
        driver.connect()
    assert not driver.connected
    assert 0.2 * 3 <= clock.now < 1.0  # 3 probes ($VNASY,0 + $VNRRG,01) of probe_timeout each


def test_handshake_tolerates_binary_stream_already_running():
    rig = Rig()
    rig.driver.connect()
    rig.run(0.1)
    # A new driver (e.g. node restart) finds binary packets and no ASCII output on the line.
    clock = rig.clock
    port = InMemoryPort(rig.device, clock=clock, sleep=clock.sleep)
    port.reset_input_buffer = None  # a port without the optional method
    driver = Vn100Driver(lambda: port, clock=clock)
    clock.sleep(0.05)
    driver.connect()
    assert driver.model == "VN-100T-CR"
    clock.sleep(0.05)
    assert len(driver.read_samples()) >= 8


def test_stale_stream_triggers_reconfiguration():
    rig = Rig()
    rig.driver.stale_timeout = 0.25
    assert rig.run(0.2)
    rig.device.power_cycle()  # watchdog reset: output back to ASCII, no binary packets
    start = rig.clock.now
    while rig.driver.disconnects == 0 and rig.clock.now < start + 1.0:
        assert rig.driver.read_samples() == []
        rig.clock.sleep(0.001)
    assert rig.driver.disconnects == 1 and "no valid packet" in rig.driver.last_error
    assert 0.25 < rig.clock.now - start < 0.3
    back = rig.run_until_sample(0.1)  # reconfigured at once
    assert back is not None and back - start < 0.3
    assert rig.driver.connects == 2 and rig.driver.disconnects == 1
    assert len(rig.run(0.2)) > 20


def test_fake_answers_errors_and_checksum_bypass():
    device = FakeVn100()
    device.write(b"$VNFOO*%02X\r\n" % vp.xor_checksum(b"VNFOO"))
    device.write(b"$VNRRG,01*00\r\n")
    device.write(vp.read_register_command(99))
    device.write(vp.write_register_command(1, ["X"]))
    device.write(vp.ascii_command("VNWRG,75,1,0,01,0131"))
    device.write(b"$VNRRG,01*XX\r\n")
    lines = device.read(4096).split(b"\r\n")[:-1]
    replies = [vp.parse_ascii_response(line) for line in lines]
    assert [r.error_code for r in replies[:5]] == [0x04, 0x03, 0x08, 0x09, 0x07]
    assert replies[5].values == ("VN-100T-CR",)


def test_close_is_idempotent_and_port_closed():
    rig = Rig()
    rig.driver.connect()
    rig.driver.close()
    rig.driver.close()
    assert not rig.driver.connected and not rig.ports[0].is_open
    with pytest.raises(OSError):
        rig.ports[0].read(1)


def test_pty_end_to_end_with_pyserial(tmp_path):
    pytest.importorskip("serial")
    device = FakeVn100(boot_time=time.monotonic(), baud=921600)
    device.set_state(TRUTH_Q, TRUTH_W, TRUTH_A)
    link = str(tmp_path / "vn100")
    with PtyFakeVn100(device, symlink_path=link) as pty:
        driver = Vn100Driver(serial_port_factory(link, 921600, timeout=0.01), rate_hz=200.0,
                             command_timeout=1.0, baud=921600)
        try:
            driver.connect()
            assert driver.model == "VN-100T-CR"
            samples = []
            deadline = time.monotonic() + 5.0
            while len(samples) < 40 and time.monotonic() < deadline:
                samples += driver.read_samples()
            assert len(samples) >= 40, driver.counters()
            assert driver.parser.crc_errors == 0
            reading = vn_to_ros(samples[-1].quaternion_xyzw, samples[-1].angular_rate,
                                samples[-1].acceleration)
            np.testing.assert_allclose(quat_to_rot(reading.orientation_xyzw),
                                       quat_to_rot(TRUTH_Q), atol=1e-6)
            np.testing.assert_allclose(reading.linear_acceleration, TRUTH_A, atol=1e-5)
            stamps = np.diff([s.time_startup_ns for s in samples])
            assert np.all(stamps % 5_000_000 == 0) and np.all(stamps > 0)
        finally:
            driver.close()
        assert pty.error is None
    assert not (tmp_path / "vn100").exists()


def test_config_file_is_consistent():
    from quadruped_common.config import config_path, load_yaml

    cfg = load_yaml(config_path("vn100.yaml"))
    assert vp.rate_divisor_for(cfg["rate_hz"]) == 4
    assert cfg["baud"] == 921600 and cfg["frame_id"] == "imu_link"
    assert 0 < cfg["stale_timeout"] < 1.0
    assert 0 < cfg["reconnect_initial_delay"] <= cfg["stale_timeout"] < cfg["reconnect_max_delay"]
    assert cfg["save_baud"] is False  # the sensor's flash is written only on request
    for key in ("orientation", "angular_velocity", "linear_acceleration"):
        values = cfg[key + "_covariance_diagonal"]
        assert len(values) == 3 and all(0 < v < 1 for v in values)
    # Datasheet-derived: 1 deg roll/pitch, 2 deg heading (see the comments in the file).
    assert cfg["orientation_covariance_diagonal"][2] == pytest.approx(math.radians(2) ** 2, rel=0.01)


def test_next_output_time_follows_the_configured_outputs():
    device = FakeVn100(boot_time=10.0)
    # Factory state: ASCII $VNYMR at 40 Hz (every 20th 800 Hz tick), binary off.
    assert device.next_output_time() == pytest.approx(10.0)
    device.advance(10.0)
    assert device.next_output_time() == pytest.approx(10.025)
    device.write(vp.ascii_command("VNWRG,06,0"))  # ASCII output off
    device.write(vp.ascii_command("VNWRG,75,1,4,01,0131"))  # binary at 200 Hz
    device.read(1 << 16)
    assert device.next_output_time() == pytest.approx(10.005)
    device.advance(10.005)
    assert device.next_output_time() == pytest.approx(10.010)
    device.disconnect()
    assert device.next_output_time() is None


def test_pty_on_a_simulated_clock_sends_only_what_is_due_when_woken(tmp_path):
    pytest.importorskip("serial")
    clock = ManualClock(0.0)
    device = FakeVn100(boot_time=0.0, baud=921600)
    link = str(tmp_path / "vn100")
    with PtyFakeVn100(device, clock=clock, symlink_path=link, realtime=False, period=0.01) as pty:
        driver = Vn100Driver(serial_port_factory(link, 921600, timeout=0.01), rate_hz=200.0,
                             command_timeout=1.0, baud=921600)
        try:
            driver.connect()  # the handshake runs while the simulated clock stands still
            samples = []
            for k in range(1, 21):
                clock.now = 0.01 * k
                pty.wake()
                deadline = time.monotonic() + 2.0
                while len(samples) < 2 * k and time.monotonic() < deadline:
                    samples += driver.read_samples()
                assert len(samples) == 2 * k  # two 200 Hz packets per 10 ms of simulated time
            assert [s.time_startup_ns for s in samples] == [5_000_000 * (i + 1) for i in range(40)]
        finally:
            driver.close()
        assert pty.error is None


def test_unplugged_time_is_not_sent_after_replug():
    device = FakeVn100(boot_time=0.0)
    device.write(vp.ascii_command("VNWRG,06,0") + vp.ascii_command("VNWRG,75,1,4,01,0131"))
    device.advance(0.01)
    device.read(1 << 16)
    sent = device.packets_sent
    device.disconnect()
    device.advance(0.5)  # half a second unplugged
    device.reconnect(power_cycle=False)
    device.advance(0.51)
    assert device.packets_sent - sent == 2  # only the 0.505 and 0.510 s packets


def test_link_silence_is_judged_on_the_link_clock_only():
    """Lock-step: the node judges the link on simulated time. Wall time passing without packets while
    simulated time stands still (a slow step on a loaded machine) is no silence; simulated time passing
    without packets is."""
    simulated = ManualClock(5.0)
    rig = Rig(link_clock=simulated)
    rig.driver.stale_timeout = 0.1
    assert rig.run(0.2)
    rig.device.power_cycle()  # no more binary packets
    for _ in range(50):  # 0.5 s of wall time, simulated time held
        rig.clock.sleep(0.01)
        assert rig.driver.read_samples() == []
    assert rig.driver.disconnects == 0
    simulated.sleep(0.11)
    rig.driver.read_samples()
    assert rig.driver.disconnects == 1 and "no valid packet" in rig.driver.last_error


def test_a_link_set_up_before_the_link_clock_has_a_time_is_not_silent_when_it_gets_one():
    """Lock-step start: the node configures the sensor while ROS time still reads 0 (no /clock yet);
    the simulation's first /clock then says t_0 = 1 s. That jump is no silence: the link stays up and
    the packets that follow are read. Counting silence from 0 dropped the link at that moment and the
    first samples of the run were lost (the lock-step determinism check failed now and then)."""
    simulated = ManualClock(0.0)
    rig = Rig(link_clock=simulated)
    rig.driver.stale_timeout = 0.1
    rig.device.async_paused = True  # no output until the simulation starts (its clock holds at t_0)
    rig.driver.connect()
    rig.device.async_paused = True
    rig.driver.read_samples()
    simulated.sleep(1.0)  # the first /clock: t_0
    for _ in range(5):
        rig.clock.sleep(0.01)
        assert rig.driver.read_samples() == []
    assert rig.driver.disconnects == 0 and rig.driver.connected
    rig.device.async_paused = False
    samples = rig.run(0.05)
    assert samples and rig.driver.disconnects == 0
    # Silence is judged from then on, as before.
    rig.device.power_cycle()
    simulated.sleep(0.11)
    rig.driver.read_samples()
    assert rig.driver.disconnects == 1 and "no valid packet" in rig.driver.last_error


def test_without_a_link_clock_the_link_is_judged_on_the_clock():
    rig = Rig()
    rig.driver.stale_timeout = 0.1
    assert rig.run(0.2)
    rig.device.power_cycle()
    rig.run(0.15)
    assert rig.driver.disconnects == 1
