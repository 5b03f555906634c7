"""A register-level fake I2C bus: routes transactions by 7-bit address to attached fake devices.

It has the same interface as Blinka's ``busio.I2C`` (and :class:`~quadruped_drivers.bus_bridge.BridgedI2CBus`),
so the drivers -- and the unchanged adafruit CircuitPython drivers -- run against it byte for byte.

* Device protocol: a fake device has ``write(data: bytes) -> None`` (one write phase, may be empty for
  a probe) and ``read(n: int) -> bytes`` (one read phase). A device may raise ``OSError`` to NACK.
  A device may also define ``also_answers(address) -> bool`` (e.g. the PCA9685 all-call address) and
  ``route(address) -> list of (bus, device)`` (a multiplexer forwarding to its selected channels).
* NACK of an absent address raises ``OSError(ENXIO)`` like Linux i2c-dev; injected faults raise
  ``OSError(ENXIO)`` ('nack') or ``OSError(EIO)`` ('oserror').
* Locking follows Blinka's ``Lockable``: ``try_lock`` is a non-reentrant flag (a second ``try_lock``
  returns False even from the same thread), ``unlock`` releases it. With ``require_lock=True`` a
  transaction without the lock held raises ``RuntimeError`` (to test that drivers lock the bus).
* Every transaction (including NACKed ones) is appended to :attr:`FakeI2CBus.log`; transactions
  forwarded by a multiplexer are logged on the bus where they appear on the wire (the parent).
* Thread-safe: one ``RLock`` serialises transactions, attachment, fault injection and the log.
"""
from __future__ import annotations

import errno
import random
import threading
from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Optional, Tuple

#: Transaction kinds in the log.
WRITE = "write"
READ = "read"
WRITE_READ = "write_read"
SCAN = "scan"

#: Addresses a Linux ``i2cdetect``-style scan probes (0x08..0x77).
SCAN_RANGE = range(0x08, 0x78)


@dataclass(frozen=True)
class Transaction:
    """One bus transaction as it appeared on the wire.

    ``written`` / ``read`` are the data bytes of the write and read phases (address bytes excluded).
    ``ok`` is False when the transaction ended in a NACK or error (then ``read`` is empty).
    """

    kind: str
    address: int
    written: bytes = b""
    read: bytes = b""
    ok: bool = True


def transaction_bits(transaction: Transaction) -> int:
    """Bits on the wire for one transaction, clock-counted as a bus analyser would.

    START = 1, each address byte + ACK = 9, each data byte + ACK/NACK = 9, repeated START = 1,
    STOP = 1. A transaction NACKed at its address costs START + 9 + STOP. A scan probes every address
    of 0x08..0x77 with a zero-length write (START + address + STOP each).
    """
    if transaction.kind == SCAN:
        return len(SCAN_RANGE) * 11
    if not transaction.ok:
        return 1 + 9 + 9 * len(transaction.written) + 1
    if transaction.kind == WRITE:
        return 1 + 9 + 9 * len(transaction.written) + 1
    if transaction.kind == READ:
        return 1 + 9 + 9 * len(transaction.read) + 1
    if transaction.kind == WRITE_READ:
        return 1 + 9 + 9 * len(transaction.written) + 1 + 9 + 9 * len(transaction.read) + 1
    raise ValueError("unknown transaction kind %r" % transaction.kind)


def bits_on_wire(transactions: Iterable[Transaction]) -> int:
    """Total bits on the wire for ``transactions`` (see :func:`transaction_bits`)."""
    return sum(transaction_bits(item) for item in transactions)


FAULT_KINDS = ("nack", "oserror", "abort")


class _Fault:
    __slots__ = ("kind", "remaining", "keep", "probability", "rng")

    def __init__(self, kind: str, remaining: Optional[int], keep: Optional[int] = None,
                 probability: float = 1.0, rng: Optional[random.Random] = None) -> None:
        self.kind = kind
        self.remaining = remaining
        self.keep = keep
        self.probability = probability
        self.rng = rng


class FakeI2CBus:
    """Fake I2C bus with address routing, Blinka lock semantics, a transaction log and fault injection."""

    def __init__(self, require_lock: bool = False, name: str = "fake-i2c") -> None:
        self.name = name
        self.require_lock = require_lock
        self.lock = threading.RLock()
        self.log: List[Transaction] = []
        self.log_enabled = True
        self._devices: Dict[int, Any] = {}
        self._faults: Dict[int, _Fault] = {}
        self._locked = False

    # --- topology ------------------------------------------------------------------------------
    def attach(self, address: int, device: Any) -> Any:
        """Attach ``device`` at 7-bit ``address``; returns the device. One device per address."""
        _check_address(address)
        if not (hasattr(device, "write") and hasattr(device, "read")):
            raise TypeError("a fake I2C device needs write(data) and read(n) methods")
        with self.lock:
            if address in self._devices:
                raise ValueError("%s: address 0x%02x is already taken" % (self.name, address))
            self._devices[address] = device
        return device

    def detach(self, address: int) -> None:
        """Remove the device at ``address`` (as if it lost power); later transactions NACK."""
        with self.lock:
            self._devices.pop(address, None)

    def device_at(self, address: int) -> Optional[Any]:
        """The device attached directly at ``address`` (not through a multiplexer), if any."""
        with self.lock:
            return self._devices.get(address)

    # --- fault injection -----------------------------------------------------------------------
    def inject_fault(self, address: int, kind: str = "nack", count: Optional[int] = 1,
                     keep: Optional[int] = None, probability: float = 1.0,
                     rng: Optional[random.Random] = None) -> None:
        """Make the next ``count`` transactions addressed to ``address`` on this bus fail.

        ``kind`` 'nack' raises ``OSError(ENXIO)`` (address not acknowledged), 'oserror' raises
        ``OSError(EIO)`` (e.g. arbitration lost, timeout), 'abort' is a write that breaks off after
        ``keep`` written bytes (register pointer included; ``None``: a random number from ``rng``): the
        device takes that prefix, then ``OSError(EIO)`` is raised (reads simply fail). ``count=None``
        makes the fault permanent until :meth:`clear_faults`. With ``probability`` < 1 each
        transaction fails only with that probability (drawn from ``rng``), and only failures use up
        ``count``. Faults on a multiplexer channel bus apply to transactions that reach that channel
        through the multiplexer.
        """
        _check_address(address)
        if kind not in FAULT_KINDS:
            raise ValueError("fault kind must be one of %s, got %r" % (FAULT_KINDS, kind))
        if count is not None and count < 1:
            raise ValueError("fault count must be >= 1 or None (permanent), got %r" % count)
        if not 0.0 <= probability <= 1.0:
            raise ValueError("fault probability must be in [0, 1], got %r" % (probability,))
        if keep is not None and keep < 0:
            raise ValueError("keep must be >= 0 or None, got %r" % (keep,))
        with self.lock:
            self._faults[address] = _Fault(kind, count, keep, probability, rng or random.Random(0))

    def clear_faults(self, address: Optional[int] = None) -> None:
        """Remove injected faults (all, or those of ``address``)."""
        with self.lock:
            if address is None:
                self._faults.clear()
            else:
                self._faults.pop(address, None)

    def _take_fault(self, address: int, written: int = 0) -> Optional[int]:
        """Raise the injected fault for ``address``, or return how many of the ``written`` bytes an
        aborting write delivers first (None: no fault)."""
        fault = self._faults.get(address)
        if fault is None:
            return None
        if fault.probability < 1.0 and fault.rng.random() >= fault.probability:  # type: ignore[union-attr]
            return None
        if fault.remaining is not None:
            fault.remaining -= 1
            if fault.remaining <= 0:
                del self._faults[address]
        if fault.kind == "nack":
            raise OSError(errno.ENXIO, "%s: injected NACK at 0x%02x" % (self.name, address))
        if fault.kind == "abort" and written > 0:
            keep = fault.keep if fault.keep is not None else fault.rng.randrange(written)  # type: ignore[union-attr]
            return min(keep, written - 1)
        raise OSError(errno.EIO, "%s: injected I/O error at 0x%02x" % (self.name, address))

    # --- log -----------------------------------------------------------------------------------
    def clear_log(self) -> None:
        """Empty :attr:`log`."""
        with self.lock:
            self.log.clear()

    def _record(self, transaction: Transaction) -> None:
        if self.log_enabled:
            self.log.append(transaction)

    # --- locking (Blinka Lockable semantics) ---------------------------------------------------
    def try_lock(self) -> bool:
        """Take the bus lock if free; False if anyone (this thread included) holds it."""
        with self.lock:
            if self._locked:
                return False
            self._locked = True
            return True

    def unlock(self) -> None:
        """Release the bus lock (no-op when not locked, as in Blinka)."""
        with self.lock:
            self._locked = False

    @property
    def locked(self) -> bool:
        """True while someone holds the bus lock."""
        return self._locked

    # --- routing -------------------------------------------------------------------------------
    def resolve(self, address: int) -> List[Tuple["FakeI2CBus", Any]]:
        """All (owning bus, device) pairs that acknowledge ``address`` on this bus right now."""
        targets: List[Tuple[FakeI2CBus, Any]] = []
        direct = self._devices.get(address)
        if direct is not None:
            targets.append((self, direct))
        for device_address, device in self._devices.items():
            if device is direct:
                continue
            also = getattr(device, "also_answers", None)
            if also is not None and device_address != address and also(address):
                targets.append((self, device))
            route = getattr(device, "route", None)
            if route is not None and device_address != address:
                targets.extend(route(address))
        return targets

    def _targets(self, address: int, written: int = 0) -> Tuple[List[Tuple["FakeI2CBus", Any]], Optional[int]]:
        """(devices acknowledging ``address``, bytes an injected abort lets through or None)."""
        _check_address(address)
        if self.require_lock and not self._locked:
            raise RuntimeError("%s: transaction to 0x%02x without holding the bus lock" % (self.name, address))
        keep = self._take_fault(address, written)
        targets = self.resolve(address)
        if not targets:
            raise OSError(errno.ENXIO, "%s: no device acknowledged address 0x%02x" % (self.name, address))
        for owner, _ in targets:
            if owner is not self:
                routed = owner._take_fault(address, written)
                keep = routed if keep is None else keep
        return targets, keep

    @staticmethod
    def _read_all(targets: List[Tuple["FakeI2CBus", Any]], count: int) -> bytes:
        # Several devices driving SDA at once: open-drain wired-AND of their bytes.
        result = bytearray([0xFF] * count)
        for _, device in targets:
            data = bytes(device.read(count))
            if len(data) != count:
                raise RuntimeError("fake device %r returned %d bytes, %d requested" % (device, len(data), count))
            for index, value in enumerate(data):
                result[index] &= value
        return bytes(result)

    # --- transactions --------------------------------------------------------------------------
    def writeto(self, address: int, buffer: Any, *, start: int = 0, end: Optional[int] = None) -> None:
        """Write ``buffer[start:end]`` to ``address`` (one START ... STOP transaction)."""
        data = bytes(buffer[start:end])
        with self.lock:
            try:
                targets, keep = self._targets(address, len(data))
                for _, device in targets:
                    device.write(data if keep is None else data[:keep])
                if keep is not None:
                    raise OSError(errno.EIO, "%s: injected abort after %d of %d bytes at 0x%02x"
                                  % (self.name, keep, len(data), address))
            except OSError:
                self._record(Transaction(WRITE, address, data, b"", ok=False))
                raise
            self._record(Transaction(WRITE, address, data))

    def readfrom_into(self, address: int, buffer: Any, *, start: int = 0, end: Optional[int] = None) -> None:
        """Read ``len(buffer[start:end])`` bytes from ``address`` into the buffer."""
        end = len(buffer) if end is None else end
        count = end - start
        with self.lock:
            try:
                targets, _ = self._targets(address)
                data = self._read_all(targets, count)
            except OSError:
                self._record(Transaction(READ, address, b"", b"", ok=False))
                raise
            buffer[start:end] = data
            self._record(Transaction(READ, address, b"", data))

    def writeto_then_readfrom(self, address: int, buffer_out: Any, buffer_in: Any, *, out_start: int = 0,
                              out_end: Optional[int] = None, in_start: int = 0,
                              in_end: Optional[int] = None) -> None:
        """Write then read with a repeated START in between: one atomic transaction."""
        data = bytes(buffer_out[out_start:out_end])
        in_end = len(buffer_in) if in_end is None else in_end
        count = in_end - in_start
        with self.lock:
            try:
                targets, _ = self._targets(address)  # an abort fails the whole exchange: nothing delivered
                for _, device in targets:
                    device.write(data)
                result = self._read_all(targets, count)
            except OSError:
                self._record(Transaction(WRITE_READ, address, data, b"", ok=False))
                raise
            buffer_in[in_start:in_end] = result
            self._record(Transaction(WRITE_READ, address, data, result))

    def scan(self) -> List[int]:
        """Addresses in 0x08..0x77 that acknowledge (devices behind a multiplexer included when selected)."""
        with self.lock:
            found = [address for address in SCAN_RANGE
                     if address not in self._faults and self.resolve(address)]
            self._record(Transaction(SCAN, 0))
            return found

    def deinit(self) -> None:
        """Nothing to release (the bus-device ``deinit`` name)."""


def _check_address(address: int) -> None:
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 0x7F:
        raise ValueError("I2C address must be a 7-bit integer, got %r" % (address,))


__all__ = ["Transaction", "FakeI2CBus", "FAULT_KINDS", "bits_on_wire", "transaction_bits", "WRITE", "READ", "WRITE_READ",
           "SCAN", "SCAN_RANGE"]
