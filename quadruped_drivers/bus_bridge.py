"""Carry I2C transactions between processes over a Unix stream socket.

In simulation the fake devices (PCA9685, ADS1115s, TCA9548A) live in the simulated robot's process
(``sim_node``) while the unchanged driver nodes run in their own processes. :class:`BusBridgeServer`
exposes any bus object (normally the fake bus) on a socket; :class:`BridgedI2CBus` is a bus object for
the drivers with the same interface as the real one (the adafruit bus-device subset: ``try_lock``,
``unlock``, ``writeto``, ``readfrom_into``, ``writeto_then_readfrom``, ``scan``). Each call is one
request and one answer, so a ``writeto_then_readfrom`` stays one atomic transaction (repeated start) on
the far side, exactly as on a real bus, and every byte the drivers produce reaches the fake registers.

A stuck bus (a device holding SDA low, so every transaction ends in the adapter's timeout) is a fault of
the wire, so it is injected here: :meth:`BusBridgeServer.set_stuck` makes every transaction wait
``stuck_timeout_s`` and fail with ``ETIMEDOUT``, without touching the devices, until it is released.

Wire format (little-endian), request: ``op u8, address u8, write_len u16, read_len u16, write bytes``;
answer: ``errno u8`` (0 = ACK) followed by ``read_len`` bytes when errno is 0. Device errors travel as
their errno and are raised as ``OSError(errno)`` by the client, like Linux i2c-dev reports a NACK.
"""
from __future__ import annotations

import errno
import os
import socket
import struct
import threading
import time
from typing import List, Optional

_OP_WRITE = 1
_OP_READ = 2
_OP_WRITE_READ = 3
_OP_SCAN = 4
_HEADER = struct.Struct("<BBHH")
_MAX_LEN = 4096


def _recv_exact(conn: socket.socket, count: int) -> bytes:
    chunks = []
    while count:
        chunk = conn.recv(count)
        if not chunk:
            raise ConnectionError("bus bridge peer closed the connection")
        chunks.append(chunk)
        count -= len(chunk)
    return b"".join(chunks)


class BusBridgeServer:
    """Serve ``bus`` (an object with the bus-device interface) on the Unix socket ``path``.

    Transactions from all clients are executed one at a time under ``lock`` (pass the lock the owner
    of the fake devices also takes, so physics updates and bus traffic never interleave mid-register).
    ``stuck_timeout_s``: how long a transaction on a stuck bus (:meth:`set_stuck`) takes before it fails
    with ``ETIMEDOUT``, as the I2C adapter's transfer timeout; it must stay below the client's socket
    timeout (0.5 s), which would otherwise report a dead bridge instead.
    """

    def __init__(self, bus, path: str, lock: Optional[threading.Lock] = None,
                 stuck_timeout_s: float = 0.025) -> None:
        if not 0.0 <= stuck_timeout_s < 0.5:
            raise ValueError("stuck_timeout_s must be in [0, 0.5) s, got %r" % (stuck_timeout_s,))
        self._bus = bus
        self._path = path
        self._lock = lock or threading.Lock()
        self._stuck = threading.Event()
        self.stuck_timeout_s = float(stuck_timeout_s)
        #: Transactions failed with ETIMEDOUT while the bus was stuck.
        self.stuck_transactions = 0
        self._stop = threading.Event()
        self._threads: List[threading.Thread] = []
        self._connections: List[socket.socket] = []
        if os.path.exists(path):
            os.unlink(path)
        directory = os.path.dirname(path)
        if directory:
            os.makedirs(directory, exist_ok=True)
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._listener.bind(path)
        self._listener.listen(8)
        self._listener.settimeout(0.2)
        self._accept_thread = threading.Thread(target=self._accept_loop, name="bus-bridge-accept", daemon=True)
        self._accept_thread.start()

    @property
    def path(self) -> str:
        return self._path

    @property
    def stuck(self) -> bool:
        """True while every transaction times out (:meth:`set_stuck`)."""
        return self._stuck.is_set()

    def set_stuck(self, stuck: bool) -> None:
        """Hold the bus (every transaction waits ``stuck_timeout_s``, then fails with ``ETIMEDOUT``, and no
        device sees it) or release it; the devices keep their registers either way."""
        if stuck:
            self._stuck.set()
        else:
            self._stuck.clear()

    def close(self) -> None:
        """Stop serving, close every connection and remove the socket file."""
        self._stop.set()
        self._accept_thread.join(timeout=2.0)
        for conn in list(self._connections):
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            conn.close()
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._listener.close()
        if os.path.exists(self._path):
            os.unlink(self._path)

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            conn.setblocking(True)
            self._connections.append(conn)
            thread = threading.Thread(target=self._serve, args=(conn,), name="bus-bridge-client", daemon=True)
            self._threads.append(thread)
            thread.start()

    def _serve(self, conn: socket.socket) -> None:
        try:
            while not self._stop.is_set():
                op, address, write_len, read_len = _HEADER.unpack(_recv_exact(conn, _HEADER.size))
                data = _recv_exact(conn, write_len) if write_len else b""
                conn.sendall(self._execute(op, address, data, read_len))
        except (ConnectionError, OSError, struct.error):
            pass
        finally:
            conn.close()
            if conn in self._connections:
                self._connections.remove(conn)

    def _execute(self, op: int, address: int, data: bytes, read_len: int) -> bytes:
        if read_len > _MAX_LEN:
            return bytes([errno.EINVAL])
        if self._stuck.is_set():
            # Waited outside the device lock: a stuck wire stalls the drivers, not the simulated robot.
            time.sleep(self.stuck_timeout_s)
            self.stuck_transactions += 1
            return bytes([errno.ETIMEDOUT])
        buffer = bytearray(read_len)
        try:
            with self._lock:
                if op == _OP_WRITE:
                    self._bus.writeto(address, data)
                elif op == _OP_READ:
                    self._bus.readfrom_into(address, buffer)
                elif op == _OP_WRITE_READ:
                    self._bus.writeto_then_readfrom(address, data, buffer)
                elif op == _OP_SCAN:
                    found = bytes(self._bus.scan())
                    return bytes([0]) + struct.pack("<H", len(found)) + found
                else:
                    return bytes([errno.EINVAL])
        except OSError as exc:
            return bytes([(exc.errno or errno.EIO) & 0xFF])
        return bytes([0]) + bytes(buffer)


class BridgedI2CBus:
    """Client end: a bus object whose transactions run on a :class:`BusBridgeServer`.

    Connects lazily and reconnects on the next transaction after the server went away; until then each
    transaction raises ``OSError(EIO)``, which the drivers treat like any bus error.
    """

    def __init__(self, path: str, timeout: float = 0.5) -> None:
        self._path = path
        self._timeout = timeout
        self._sock: Optional[socket.socket] = None
        self._lock = threading.Lock()
        self._io_lock = threading.Lock()

    # --- locking, as busio.I2C -------------------------------------------------------------
    def try_lock(self) -> bool:
        return self._lock.acquire(blocking=False)

    def unlock(self) -> None:
        self._lock.release()

    # --- transactions ------------------------------------------------------------------------
    def writeto(self, address: int, buffer, *, start: int = 0, end: Optional[int] = None) -> None:
        self._transact(_OP_WRITE, address, bytes(buffer[start:end]), 0)

    def readfrom_into(self, address: int, buffer, *, start: int = 0, end: Optional[int] = None) -> None:
        end = len(buffer) if end is None else end
        buffer[start:end] = self._transact(_OP_READ, address, b"", end - start)

    def writeto_then_readfrom(self, address: int, buffer_out, buffer_in, *, out_start: int = 0,
                              out_end: Optional[int] = None, in_start: int = 0,
                              in_end: Optional[int] = None) -> None:
        in_end = len(buffer_in) if in_end is None else in_end
        buffer_in[in_start:in_end] = self._transact(
            _OP_WRITE_READ, address, bytes(buffer_out[out_start:out_end]), in_end - in_start)

    def scan(self) -> List[int]:
        with self._io_lock:
            sock = self._connect()
            try:
                sock.sendall(_HEADER.pack(_OP_SCAN, 0, 0, 0))
                status = _recv_exact(sock, 1)[0]
                if status:
                    raise OSError(status, os.strerror(status))
                (count,) = struct.unpack("<H", _recv_exact(sock, 2))
                return list(_recv_exact(sock, count))
            except (ConnectionError, socket.timeout, OSError) as exc:
                self._drop()
                raise OSError(errno.EIO, "bus bridge %s: %s" % (self._path, exc)) from exc

    def deinit(self) -> None:
        """Close the connection (the bus-device ``deinit`` name)."""
        with self._io_lock:
            self._drop()

    def _connect(self) -> socket.socket:
        if self._sock is None:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.settimeout(self._timeout)
            try:
                sock.connect(self._path)
            except OSError:
                sock.close()
                raise
            self._sock = sock
        return self._sock

    def _drop(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _transact(self, op: int, address: int, data: bytes, read_len: int) -> bytes:
        if not 0 <= address <= 0x7F:
            raise ValueError("I2C address 0x%x out of range" % address)
        with self._io_lock:
            try:
                sock = self._connect()
                sock.sendall(_HEADER.pack(op, address, len(data), read_len) + data)
                status = _recv_exact(sock, 1)[0]
            except (ConnectionError, socket.timeout, OSError) as exc:
                self._drop()
                raise OSError(errno.EIO, "bus bridge %s: %s" % (self._path, exc)) from exc
            if status:
                raise OSError(status, os.strerror(status))
            try:
                return _recv_exact(sock, read_len) if read_len else b""
            except (ConnectionError, socket.timeout, OSError) as exc:
                self._drop()
                raise OSError(errno.EIO, "bus bridge %s: %s" % (self._path, exc)) from exc
