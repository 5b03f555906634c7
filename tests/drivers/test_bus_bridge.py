"""The socket bridge that carries I2C transactions from driver processes to the simulated devices."""
import errno
import os
import tempfile
import threading

import pytest

from quadruped_drivers.bus_bridge import BridgedI2CBus, BusBridgeServer


class RegisterBus:
    """A minimal bus: one device at 0x40 with a register pointer and 256 byte registers."""

    def __init__(self):
        self.registers = bytearray(256)
        self.pointer = 0
        self.log = []

    def _check(self, address):
        if address != 0x40:
            raise OSError(errno.ENXIO, "no device")

    def writeto(self, address, data):
        self._check(address)
        self.log.append(("w", address, bytes(data)))
        self.pointer = data[0]
        for offset, value in enumerate(data[1:]):
            self.registers[(self.pointer + offset) & 0xFF] = value

    def readfrom_into(self, address, buffer):
        self._check(address)
        for index in range(len(buffer)):
            buffer[index] = self.registers[(self.pointer + index) & 0xFF]

    def writeto_then_readfrom(self, address, out, into):
        self._check(address)
        self.log.append(("wr", address, bytes(out)))
        self.pointer = out[0]
        self.readfrom_into(address, into)

    def scan(self):
        return [0x40]


@pytest.fixture
def bridge():
    directory = tempfile.mkdtemp(prefix="uqbb")
    path = os.path.join(directory, "i2c.sock")
    bus = RegisterBus()
    server = BusBridgeServer(bus, path)
    client = BridgedI2CBus(path)
    yield bus, server, client
    client.deinit()
    server.close()
    os.rmdir(directory)


def test_write_then_read_reaches_the_far_registers(bridge):
    bus, _, client = bridge
    assert client.try_lock()
    client.writeto(0x40, bytes([0x06, 1, 2, 3, 4]))
    into = bytearray(4)
    client.writeto_then_readfrom(0x40, bytes([0x06]), into)
    client.unlock()
    assert bytes(into) == bytes([1, 2, 3, 4])
    assert bus.registers[6:10] == bytes([1, 2, 3, 4])
    # the combined transaction stays one transaction on the far side (repeated start)
    assert bus.log[-1] == ("wr", 0x40, bytes([0x06]))


def test_slices_like_busio(bridge):
    bus, _, client = bridge
    client.writeto(0x40, bytearray([0xFF, 0x10, 9, 9, 0xFF]), start=1, end=4)
    assert bus.registers[0x10:0x12] == bytes([9, 9])
    into = bytearray(6)
    client.writeto_then_readfrom(0x40, bytes([0x10]), into, in_start=2, in_end=4)
    assert bytes(into) == bytes([0, 0, 9, 9, 0, 0])


def test_nack_travels_as_oserror(bridge):
    _, _, client = bridge
    with pytest.raises(OSError) as info:
        client.writeto(0x41, b"\x00")
    assert info.value.errno == errno.ENXIO
    # and the connection stays usable afterwards
    client.writeto(0x40, b"\x00\x07")
    assert client.scan() == [0x40]


def test_lock_is_exclusive(bridge):
    _, _, client = bridge
    assert client.try_lock()
    results = []
    thread = threading.Thread(target=lambda: results.append(client.try_lock()))
    thread.start()
    thread.join()
    assert results == [False]
    client.unlock()


def test_server_gone_gives_eio_then_reconnects():
    directory = tempfile.mkdtemp(prefix="uqbb")
    path = os.path.join(directory, "i2c.sock")
    client = BridgedI2CBus(path, timeout=0.2)
    with pytest.raises(OSError) as info:
        client.writeto(0x40, b"\x00")  # nobody listening yet
    assert info.value.errno == errno.EIO
    bus = RegisterBus()
    server = BusBridgeServer(bus, path)
    client.writeto(0x40, b"\x00\x05")
    server.close()
    with pytest.raises(OSError):
        client.writeto(0x40, b"\x00\x06")
    server = BusBridgeServer(bus, path)
    client.writeto(0x40, b"\x00\x07")
    assert bus.registers[0] == 7
    client.deinit()
    server.close()
    os.rmdir(directory)


def test_bad_address_is_rejected_locally(bridge):
    _, _, client = bridge
    with pytest.raises(ValueError):
        client.writeto(0x80, b"\x00")


def test_a_stuck_bus_times_out_every_transaction_without_touching_the_devices(bridge):
    bus, server, client = bridge
    client.writeto(0x40, b"\x00\x01")
    server.stuck_timeout_s = 0.02
    server.set_stuck(True)
    assert server.stuck
    for attempt in range(3):
        with pytest.raises(OSError) as info:
            client.writeto(0x40, b"\x00\x09")
        assert info.value.errno == errno.ETIMEDOUT
    with pytest.raises(OSError):
        client.writeto_then_readfrom(0x40, b"\x00", bytearray(1))
    assert bus.registers[0] == 1 and server.stuck_transactions == 4
    server.set_stuck(False)
    client.writeto(0x40, b"\x00\x02")  # the same connection works again
    assert bus.registers[0] == 2


def test_stuck_timeout_must_stay_below_the_clients_socket_timeout():
    with pytest.raises(ValueError):
        BusBridgeServer(RegisterBus(), os.path.join(tempfile.mkdtemp(prefix="uqbb"), "x.sock"), stuck_timeout_s=0.5)
