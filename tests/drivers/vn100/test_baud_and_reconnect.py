"""The VN-100 driver finds the sensor at any standard baud rate and switches it to the configured one (the
sensor's flash only on request); a short loss of the link costs about itself (first reconnection attempt at
once, then a doubling back-off). Against the byte-level fake, which only understands bytes at its own rate,
on a virtual clock (and once through a pty with pyserial)."""
from __future__ import annotations

import time

import pytest

from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.driver import SEARCH_ORDER, Vn100Driver, Vn100Error, serial_port_factory
from quadruped_drivers.vn100.fake import FakeVn100, InMemoryPort, ManualClock, PtyFakeVn100, garble
from tests.drivers.vn100.test_driver import Rig

CONFIGURED = 921600
NOT_SAVED = "(not saved to flash; set save_baud: true to keep it)"
#: The rates in the order the driver tries them when configured for CONFIGURED.
ORDER = (CONFIGURED,) + tuple(b for b in SEARCH_ORDER if b != CONFIGURED)


def replies(data: bytes):
    """The valid ASCII replies in ``data`` (noise and packets skipped)."""
    parser = vp.BinaryPacketParser()
    parser.feed(data)
    out = []
    for line in parser.pop_ascii_lines():
        try:
            out.append(vp.parse_ascii_response(line))
        except vp.ProtocolError:
            pass
    return out


class EventClock(ManualClock):
    """A manual clock that runs scheduled actions when time passes them (the sensor comes back on its
    own schedule, also while the driver waits inside a connection attempt)."""

    def __init__(self, start: float = 100.0) -> None:
        super().__init__(start)
        self.events = []

    def at(self, when: float, action) -> None:
        self.events.append((when, action))
        self.events.sort(key=lambda event: event[0])

    def sleep(self, seconds: float) -> None:
        super().sleep(seconds)
        while self.events and self.events[0][0] <= self.now:
            self.events.pop(0)[1]()


# ---------------------------------------------------------------------------------------------- the fake
def test_fake_understands_only_bytes_at_its_own_rate():
    device = FakeVn100()  # factory: 115200
    assert device.baud == vp.FACTORY_BAUD == 115200
    device.write(vp.read_model_command(), baud=921600)  # noise to the sensor: no command, no reply
    assert device.read(4096, baud=921600) == b"" and device.commands == []
    device.write(vp.read_model_command(), baud=115200)
    assert device.in_waiting > 0
    raw = device.read(4096, baud=921600)  # the reply, heard at the wrong rate: noise
    assert raw and b"$" not in raw and b"\n" not in raw and replies(raw) == []
    device.write(vp.read_model_command(), baud=115200)
    assert [r.values for r in replies(device.read(4096, baud=115200))] == [("VN-100T-CR",)]
    assert garble(b"$VNRRG,01*72\r\n") != b"$VNRRG,01*72\r\n"
    device.write(vp.read_model_command())  # a host that does not say its rate is not modelled
    assert replies(device.read(4096))[0].values == ("VN-100T-CR",)


def test_fake_answers_register_5_at_the_old_rate_then_switches():
    device = FakeVn100()
    device.write(vp.write_baud_rate_command(921600) + vp.read_model_command(), baud=115200)
    reply, = replies(device.read(4096, baud=115200))  # the read after the switch was noise to it
    assert (reply.command, reply.register, reply.values) == ("VNWRG", 5, ("921600",))
    assert device.baud == 921600 and device.baud_switches == 1
    device.write(vp.read_register_command(5), baud=921600)
    assert replies(device.read(4096, baud=921600))[0].values == ("921600",)
    device.write(vp.ascii_command("VNWRG,05,100000"), baud=921600)
    assert replies(device.read(4096, baud=921600))[0].error_code == 0x07
    # Not in flash: a power cycle brings the stored rate back.
    device.power_cycle()
    assert device.baud == 115200 and device.flash_writes == 0


def test_fake_flash_holds_what_vnwnv_wrote():
    device = FakeVn100(baud=57600)
    device.write(vp.write_baud_rate_command(921600), baud=57600)
    device.write(vp.write_settings_command(), baud=921600)
    assert replies(device.read(4096, baud=921600))[-1].command == "VNWNV"
    assert device.flash_writes == 1 and device.flash["baud"] == 921600
    device.power_cycle()
    assert device.baud == 921600
    with pytest.raises(ValueError):
        FakeVn100(baud=100000)


def test_in_memory_port_passes_its_rate_and_the_factory_takes_one():
    device = FakeVn100(baud=230400)
    clock = ManualClock()
    factory = InMemoryPort.factory(device, clock=clock, baud=115200)
    assert factory().baudrate == 115200 and factory(230400).baudrate == 230400
    port = factory(230400)
    port.write(vp.read_model_command())
    assert replies(port.read(4096))[-1].values == ("VN-100T-CR",)
    port = factory()
    port.write(vp.read_model_command())
    assert replies(port.read(4096)) == []


# ---------------------------------------------------------------------------------------------- search
@pytest.mark.parametrize("sensor_baud", vp.BAUD_RATES)
def test_found_at_each_standard_rate_and_switched_to_the_configured_one(sensor_baud):
    rig = Rig(baud=CONFIGURED, sensor_baud=sensor_baud)
    start = rig.clock.now
    rig.driver.connect()
    assert rig.driver.connected and rig.driver.found_baud == sensor_baud
    assert rig.device.baud == CONFIGURED and rig.driver.port_baud == CONFIGURED
    assert rig.driver.model == "VN-100T-CR" and rig.driver.serial_number == "0100012345"
    if sensor_baud == CONFIGURED:
        assert rig.port_rates == [CONFIGURED] and rig.log == [] and rig.driver.baud_switches == 0
    else:
        # each rate once, in order, up to the sensor's; then the configured one again
        assert rig.port_rates == list(ORDER[:ORDER.index(sensor_baud) + 1]) + [CONFIGURED]
        assert rig.log == ["VN-100 found at %d baud, switched to %d %s" % (sensor_baud, CONFIGURED, NOT_SAVED)]
        assert rig.driver.baud_switches == 1 and rig.device.baud_switches == 1
    # The flash is untouched: never a $VNWNV, the sensor keeps its stored rate.
    assert rig.device.flash_writes == 0 and rig.device.flash["baud"] == sensor_baud
    assert not any(c.startswith(b"$VNWNV") for c in rig.device.commands)
    # The search costs well under 2 s even from 9600 baud (the probes' waits on the virtual clock).
    assert rig.clock.now - start < 1.2
    assert len(rig.run(0.5)) > 80
    # The noise of the wrong rates went to the search's own parser: the link's counters are clean.
    assert rig.driver.parser.crc_errors == 0 and rig.driver.bad_ascii_lines == 0
    assert rig.device.binary_config[75] == (1, 4, {1: 0x0131})


def test_the_factory_rate_is_tried_right_after_the_configured_one():
    assert SEARCH_ORDER[0] == vp.FACTORY_BAUD == 115200
    assert sorted(SEARCH_ORDER) == sorted(vp.BAUD_RATES)
    rig = Rig(baud=CONFIGURED, sensor_baud=115200)
    rig.driver.connect()
    assert rig.port_rates == [CONFIGURED, 115200, CONFIGURED]


def test_flash_written_only_when_save_baud_asks_for_it():
    rig = Rig(baud=CONFIGURED, sensor_baud=115200, driver_kwargs={"save_baud": True})
    rig.driver.connect()
    assert rig.log == ["VN-100 found at 115200 baud, switched to 921600 (saved to flash)"]
    assert rig.device.flash_writes == 1 and rig.device.flash["baud"] == CONFIGURED
    assert [c for c in rig.device.commands if c.startswith(b"$VNWNV")] == [b"$VNWNV*57"]
    # At the configured rate after a power cycle: found there, nothing switched or written again.
    rig.device.power_cycle()
    assert rig.device.baud == CONFIGURED
    rig.driver.connect()
    assert rig.device.flash_writes == 1 and len(rig.log) == 1 and rig.driver.found_baud == CONFIGURED


def test_without_save_baud_a_power_cycled_sensor_is_switched_again():
    rig = Rig(baud=CONFIGURED, sensor_baud=57600, driver_kwargs={"stale_timeout": 0.1})
    assert len(rig.run(0.3)) > 40 and rig.driver.baud_switches == 1
    rig.device.power_cycle()  # back at its stored 57600 baud, output off
    assert rig.device.baud == 57600
    back = rig.run_until_sample(3.0)
    assert back is not None and rig.driver.connects == 2 and rig.driver.baud_switches == 2
    assert rig.log == ["VN-100 found at 57600 baud, switched to 921600 %s" % NOT_SAVED] * 2
    assert rig.device.flash_writes == 0


def test_no_answer_at_any_rate_names_the_port_and_the_rates_tried():
    rig = Rig(baud=CONFIGURED)
    rig.device.set_silent(True)  # the adapter is there, the sensor says nothing
    start = rig.clock.now
    with pytest.raises(Vn100Error) as info:
        rig.driver.connect()
    message = str(info.value)
    assert message == ("no VN-100 answered on /dev/vn100 at %s baud (no valid reply to $VNRRG,01)"
                       % ", ".join(str(b) for b in ORDER))
    assert rig.port_rates == list(ORDER) and not rig.driver.connected
    assert all(not port.is_open for port in rig.ports)
    assert rig.clock.now - start < 1.5
    assert rig.driver.connect_failures == 1 and message in rig.driver.last_error
    assert rig.device.commands == [] and rig.log == []


def test_an_unplugged_adapter_fails_at_once_without_a_search():
    rig = Rig(baud=CONFIGURED)
    rig.device.disconnect()
    with pytest.raises(OSError):
        rig.driver.connect()
    assert rig.port_rates == [CONFIGURED]


def test_a_rate_the_adapter_refuses_is_skipped_and_named():
    rig = Rig(baud=CONFIGURED, sensor_baud=9600)
    inner = rig.driver._port_factory

    def factory(rate=None):
        if rate == 128000:
            raise ValueError("Invalid baud rate: 128000")
        return inner(rate)

    rig.driver._port_factory = factory
    rig.driver.connect()
    assert rig.driver.found_baud == 9600 and 128000 not in rig.port_rates
    rig.device.set_silent(True)
    with pytest.raises(Vn100Error, match=r"230400, 128000 \(cannot open: Invalid baud rate: 128000\), 57600"):
        rig.driver.connect()


class StubbornFake(FakeVn100):
    """Acknowledges register 5 but keeps its rate (e.g. firmware that wants the port number too)."""

    def _write_register(self, args):
        if args and args[0] == "05":
            self._reply("VNWRG,05,%s" % args[1])
        else:
            super()._write_register(args)


def test_a_switch_that_does_not_take_is_an_error_and_nothing_is_logged():
    clock = ManualClock(100.0)
    device = StubbornFake(baud=115200)
    driver = Vn100Driver(InMemoryPort.factory(device, clock=clock, sleep=clock.sleep), clock=clock,
                         baud=CONFIGURED, port_name="/dev/vn100", log=pytest.fail)
    with pytest.raises(Vn100Error, match="found at 115200 baud on /dev/vn100 and switched to 921600 "
                                         r"\(register 5\), but it does not answer at 921600"):
        driver.connect()
    assert not driver.connected and driver.baud_switches == 0


def test_driver_arguments_are_checked():
    for kwargs in ({"baud": 100000}, {"search_bauds": (115200, 12345)}, {"reconnect_initial_delay": 2.0},
                   {"probe_timeout": 0.0}):
        with pytest.raises(ValueError):
            Vn100Driver(lambda rate=None: None, **kwargs)


def test_pty_search_with_pyserial_switches_a_factory_sensor(tmp_path):
    """The pty carries no real baud rate: the bridge reads the rate pyserial set on it and the fake only
    understands bytes at its own. A factory-fresh fake (115200) is found and switched to 921600."""
    pytest.importorskip("serial")
    device = FakeVn100(boot_time=time.monotonic())
    link = str(tmp_path / "vn100")
    log = []
    with PtyFakeVn100(device, symlink_path=link) as pty:
        driver = Vn100Driver(serial_port_factory(link, CONFIGURED, timeout=0.01), rate_hz=200.0,
                             baud=CONFIGURED, log=log.append, probe_timeout=0.2)
        try:
            driver.connect()
            assert pty.host_baud() == CONFIGURED and device.baud == CONFIGURED
            assert log == ["VN-100 found at 115200 baud, switched to 921600 %s" % NOT_SAVED]
            samples = []
            deadline = time.monotonic() + 5.0
            while len(samples) < 40 and time.monotonic() < deadline:
                samples += driver.read_samples()
            assert len(samples) >= 40 and driver.parser.crc_errors == 0
        finally:
            driver.close()
        # A port at another rate than the sensor's hears noise only.
        port = serial_port_factory(link, CONFIGURED, timeout=0.05)(115200)
        try:
            assert pty.host_baud() == 115200
            port.write(vp.read_model_command())
            time.sleep(0.1)
            assert replies(port.read(4096)) == []
        finally:
            port.close()
        assert pty.error is None


def test_no_sensor_on_the_pty_names_the_port_and_the_rates(tmp_path):
    pytest.importorskip("serial")
    device = FakeVn100()
    device.disconnect()  # the pty is there, the sensor silent
    link = str(tmp_path / "vn100")
    with PtyFakeVn100(device, symlink_path=link):
        driver = Vn100Driver(serial_port_factory(link, CONFIGURED, timeout=0.01), baud=CONFIGURED,
                             probe_timeout=0.01, command_retries=0)
        with pytest.raises(Vn100Error, match="no VN-100 answered on %s at 921600, 115200, 460800, 230400, "
                                             "128000, 57600, 38400, 19200, 9600 baud" % link):
            driver.connect()
        assert not driver.connected


# ---------------------------------------------------------------------------------------------- reconnect
def glitch(kind: str, duration: float = 0.1):
    """Stream, lose the link for ``duration`` s, and return (seconds from the start of the loss to the
    first sample after it, rig). ``kind``: "silent" (no bytes either way, the port stays open: the
    driver notices by ``stale_timeout``) or "unplug" (I/O errors, the port cannot be opened)."""
    clock = EventClock()
    rig = Rig(baud=CONFIGURED, sensor_baud=CONFIGURED, clock=clock, driver_kwargs={"stale_timeout": 0.1})
    assert len(rig.run(0.3, step=0.005)) > 40
    start = clock.now
    if kind == "silent":
        rig.device.set_silent(True)
        clock.at(start + duration, lambda: rig.device.set_silent(False))
    else:
        rig.device.disconnect()
        clock.at(start + duration, lambda: rig.device.reconnect(power_cycle=False))
    back = rig.run_until_sample(5.0)
    assert back is not None
    return back - start, rig


@pytest.mark.parametrize("kind, duration", [("silent", 0.1), ("silent", 0.15), ("unplug", 0.1)])
def test_a_short_glitch_costs_about_itself(kind, duration):
    recovery, rig = glitch(kind, duration)
    print("VN-100 link lost for %.2f s (%s): samples again %.3f s after the loss began (%d reconnection)"
          % (duration, kind, recovery, rig.driver.disconnects))
    assert duration <= recovery <= duration + 0.1  # a 0.1 s loss cost 1.1 s with a fixed 1 s interval
    if duration > 0.1 or kind == "unplug":  # longer than stale_timeout, or an I/O error: a reconnection
        assert rig.driver.disconnects == 1 and rig.driver.connects == 2
    assert rig.driver.baud_switches == 0 and rig.port_rates[-1] == CONFIGURED


def test_a_long_outage_ends_within_the_back_off_cap():
    recovery, rig = glitch("unplug", 3.0)
    assert 3.0 <= recovery <= 3.0 + 1.0 + 0.05


def test_reconnect_at_once_then_doubling_up_to_the_cap():
    rig = Rig(baud=CONFIGURED, sensor_baud=CONFIGURED)
    assert rig.run(0.1)
    rig.device.disconnect()
    rig.run(6.0, step=0.001)
    gaps = [round(b - a, 3) for a, b in zip(rig.open_times[1:], rig.open_times[2:])]
    assert gaps[:8] == [0.02, 0.04, 0.08, 0.16, 0.32, 0.64, 1.0, 1.0]
    assert set(gaps[6:]) == {1.0}
    # The first attempt was at once (the read after the error); the failures were counted.
    assert rig.open_times[1] - rig.open_times[0] < 0.2 + 0.002
    assert rig.driver.connect_failures == len(rig.open_times) - 1


class MuteFake(FakeVn100):
    """Accepts the configuration but never sends a packet (a sensor that cannot stream)."""

    def _emit_packet(self, tick, selection):
        pass


def test_a_sensor_that_configures_but_never_streams_is_backed_off():
    clock = ManualClock(100.0)
    device = MuteFake(baud=CONFIGURED)
    connects = []
    inner = InMemoryPort.factory(device, clock=clock, sleep=clock.sleep)

    def factory(rate=None):
        connects.append(clock.now)
        return inner(rate)

    driver = Vn100Driver(factory, clock=clock, baud=CONFIGURED, stale_timeout=0.1)
    for _ in range(4000):
        clock.sleep(0.001)
        driver.read_samples()
    gaps = [b - a for a, b in zip(connects, connects[1:])]
    assert driver.connects >= 4 and driver.disconnects >= 4
    # Each loss came before a sample: no immediate reconfiguration, the waits grow.
    assert all(later > earlier for earlier, later in zip(gaps[:4], gaps[1:5]))
