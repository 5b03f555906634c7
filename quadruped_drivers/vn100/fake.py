"""A byte-level fake VN-100 for tests and simulation, an in-memory serial port and a pty bridge.

:class:`FakeVn100` speaks the subset of the VN-100 serial protocol the driver uses (UM001 Sec. 3.8,
3.9, 4.2-4.4): ASCII commands ``$VNRRG``, ``$VNWRG`` (registers 1, 3, 5, 6, 7, 75-77), ``$VNASY``,
``$VNWNV``, with checksum verification (8-bit XOR, 16-bit CRC, or the ``XX`` bypass) and ``$VNERR``
replies; and the binary output message of register 75 at 800 Hz / RateDivisor. Like a factory-fresh
sensor it starts with ASCII asynchronous output on (``$VNYMR`` at 40 Hz) and binary output off, and it
returns to the settings in its flash (factory ones unless ``$VNWNV`` wrote others) after a power cycle,
so the driver's configuration handshake is exercised every time.

Baud rate: the fake talks at one rate (register 5; power-up: the rate in its flash, ``baud=`` of the
constructor, factory 115200). The host passes the rate its port is set to with every read and write;
bytes only pass intact when both agree, otherwise each side sees noise (never a ``$`` or a line end,
so no command or reply can form), as two UARTs at different rates do. ``$VNWRG,05`` is answered at the
old rate, then the fake switches. A host that passes no rate (``baud=None``) is not modelled: its bytes
always pass.

The simulator feeds it ROS-frame truth with :meth:`FakeVn100.set_state` (ENU world, FLU body,
REP-145 specific force); :func:`~quadruped_drivers.vn100.conversions.ros_to_vn` turns that into the
sensor's NED/FRD conventions, so a correct driver reproduces the truth exactly (up to float32).

:class:`InMemoryPort` makes the fake look like a pyserial port in-process (tests, with an injected
clock); :class:`PtyFakeVn100` exposes it on a pseudo-terminal so the unchanged driver opens a real
serial device path through pyserial (simulated robot).
"""
from __future__ import annotations

import collections
import errno
import math
import os
import select
import threading
import time
import tty
from dataclasses import dataclass
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.so3 import exp_so3, quat_multiply, rot_to_quat
from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.conversions import ros_to_vn

try:  # Linux only: the pty's configured speed (the pty bridge works without it, unmodelled)
    import array
    import fcntl
    import termios
except ImportError:  # pragma: no cover - not Linux
    fcntl = None  # type: ignore[assignment]

GRAVITY = 9.80665
DEFAULT_MODEL = "VN-100T-CR"
DEFAULT_SERIAL_NUMBER = "0100012345"
_DEFAULT_ASCII_RATE_HZ = 40
_ADOR_YMR = 14  # Async Data Output Type "VNYMR" (factory default)

#: What a byte sent at one baud rate looks like to a UART listening at another: noise. Never a printable
#: character or a line end (no '$', no '\n': no command or reply can form from it), now and then 0xFA (a
#: false binary sync byte, which the parser must reject by its CRC).
_GARBLE = bytes(0x80 | ((b * 37 + 0x5B) & 0x7F) for b in range(256))


def garble(data: bytes) -> bytes:
    """``data`` as received by a UART set to another baud rate than the sender's (one byte per byte)."""
    return bytes(data).translate(_GARBLE)


def _factory_settings() -> Dict[str, Any]:
    """The settings of a factory-fresh VN-100 (its flash before any ``$VNWNV``)."""
    return {"baud": vp.FACTORY_BAUD, "ascii_output_type": _ADOR_YMR, "ascii_rate_hz": _DEFAULT_ASCII_RATE_HZ,
            "binary_config": {register: (0, 0, {1: vp.DEFAULT_GROUP1_FIELDS}) for register in (75, 76, 77)}}


class ManualClock:
    """A clock for deterministic tests: ``clock()`` returns ``now``; ``sleep(dt)`` advances it."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = float(start)

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(0.0, float(seconds))

    advance = sleep


@dataclass
class NoiseModel:
    """Standard deviations of white noise added to each packet: ``attitude`` (rad, small-angle
    rotation applied to the quaternion), ``angular_rate`` (rad/s), ``acceleration`` (m/s^2)."""

    attitude: float = 0.0
    angular_rate: float = 0.0
    acceleration: float = 0.0


class FakeVn100:
    """Fake VN-100 byte stream (thread-safe: the simulator and a pty pump may share it).

    Host side: :meth:`write` (commands in), :meth:`read` / :attr:`in_waiting` (replies and binary
    packets out). Device side: :meth:`set_state`, :meth:`advance` (generate the output due up to
    ``now``), :meth:`disconnect` / :meth:`reconnect` (unplug: host I/O raises ``OSError``).

    ``noise_std``: a :class:`NoiseModel` or one number used for all three; ``corrupt_probability``:
    per binary packet, one byte is flipped; ``drop_probability``: per binary packet, it is lost.
    ``rng``: a ``numpy.random.Generator`` or a seed (deterministic by default).
    """

    OUTPUT_LIMIT = 1 << 16  # bytes; like a UART nobody reads, further output is lost

    def __init__(self, model: str = DEFAULT_MODEL, serial_number: str = DEFAULT_SERIAL_NUMBER,
                 noise_std: Union[NoiseModel, float] = 0.0,
                 corrupt_probability: float = 0.0, drop_probability: float = 0.0,
                 rng: Union[np.random.Generator, int, None] = 0,
                 boot_time: float = 0.0, baud: int = vp.FACTORY_BAUD) -> None:
        for name, p in (("corrupt_probability", corrupt_probability),
                        ("drop_probability", drop_probability)):
            if not 0.0 <= p <= 1.0:
                raise ValueError("%s must be in [0, 1], got %r" % (name, p))
        if baud not in vp.BAUD_RATES:
            raise ValueError("baud must be one of %s, got %r" % (vp.BAUD_RATES, baud))
        self.model = model
        self.serial_number = serial_number
        self.noise = noise_std if isinstance(noise_std, NoiseModel) else \
            NoiseModel(float(noise_std), float(noise_std), float(noise_std))
        self.corrupt_probability = corrupt_probability
        self.drop_probability = drop_probability
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self._lock = threading.RLock()
        # Output not yet read by the host, as (baud rate it was sent at, bytes) runs, oldest first.
        self._out: Deque[Tuple[int, bytearray]] = collections.deque()
        self._out_len = 0
        self._in = bytearray()
        self.connected = True
        self.silent = False  # link interrupted: no bytes either way, the port stays open
        self.commands: List[bytes] = []  # every command line received (for tests / diagnostics)
        self.flash_writes = 0
        self.baud_switches = 0
        # Non-volatile settings ($VNWNV writes them; a power cycle reads them back).
        self.flash: Dict[str, Any] = dict(_factory_settings(), baud=int(baud))
        self.packets_sent = 0
        self.packets_dropped = 0
        self.packets_corrupted = 0
        self._now: Optional[float] = None
        self._q_vn = np.array([0.0, 0.0, 0.0, 1.0])
        self._rate_vn = np.zeros(3)
        self._accel_vn = np.array([0.0, 0.0, -GRAVITY])
        self.set_state([0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)], [0.0, 0.0, 0.0],
                       [0.0, 0.0, GRAVITY])  # level, at rest, facing North
        self._power_on(boot_time)

    # ------------------------------------------------------------------ device state
    def _power_on(self, now: float) -> None:
        self.boot_time = float(now)
        self.async_paused = False
        self.ascii_output_type = int(self.flash["ascii_output_type"])
        self.ascii_rate_hz = int(self.flash["ascii_rate_hz"])
        self.baud = int(self.flash["baud"])
        self.binary_config = dict(self.flash["binary_config"])
        self._next_tick = 0  # next 800 Hz IMU tick index to consider for output
        self._in = bytearray()

    def _settings(self) -> Dict[str, Any]:
        return {"baud": self.baud, "ascii_output_type": self.ascii_output_type,
                "ascii_rate_hz": self.ascii_rate_hz, "binary_config": dict(self.binary_config)}

    def _clear_output(self) -> None:
        self._out.clear()
        self._out_len = 0

    def set_state(self, orientation_xyzw_ros: Sequence[float],
                  angular_velocity_ros: Sequence[float],
                  linear_acceleration_ros: Sequence[float]) -> None:
        """Truth in ROS frames (ENU/FLU, REP-145 specific force); ValueError for invalid input."""
        q, w, a = ros_to_vn(orientation_xyzw_ros, angular_velocity_ros, linear_acceleration_ros)
        with self._lock:
            self._q_vn, self._rate_vn, self._accel_vn = q, w, a

    def power_cycle(self, now: Optional[float] = None) -> None:
        """Reset to the settings in flash (factory: ASCII async on, binary off, 115200 baud), clearing
        queues."""
        with self._lock:
            self._clear_output()
            if now is None:
                now = self._now if self._now is not None else self.boot_time
            self._power_on(now)

    def disconnect(self) -> None:
        """Unplug: host reads and writes raise ``OSError`` until :meth:`reconnect`."""
        with self._lock:
            self.connected = False
            self._clear_output()
            self._in = bytearray()

    def set_silent(self, silent: bool) -> None:
        """Interrupt (True) or restore (False) the link without unplugging: while silent no byte passes
        either way (host writes are lost, reads find nothing, the output due meanwhile is gone) but the
        port stays open and keeps its configuration, as with a loose wire or a stalled adapter. (Behind
        a pty, :meth:`disconnect` looks the same to the host: the bridge swallows the errors.)"""
        with self._lock:
            self.silent = bool(silent)
            if self.silent:
                self._clear_output()
                self._in = bytearray()

    def reconnect(self, power_cycle: bool = True) -> None:
        """Plug back in; by default the sensor has lost power and forgotten its configuration."""
        with self._lock:
            self.connected = True
            if power_cycle:
                self.power_cycle()

    # ------------------------------------------------------------------ host side
    def _check_connected(self) -> None:
        if not self.connected:
            raise OSError(errno.EIO, "VN-100 disconnected")

    @property
    def in_waiting(self) -> int:
        with self._lock:
            self._check_connected()
            return 0 if self.silent else self._out_len

    def read(self, n: int, baud: Optional[int] = None) -> bytes:
        """Up to ``n`` queued output bytes (never blocks), as a host port set to ``baud`` receives them:
        intact if they were sent at that rate, noise otherwise (``None``: always intact)."""
        with self._lock:
            self._check_connected()
            if self.silent:
                return b""
            data = bytearray()
            while self._out and len(data) < n:
                sent_at, run = self._out[0]
                part = bytes(run[:n - len(data)])
                del run[:len(part)]
                if not run:
                    self._out.popleft()
                data += part if baud is None or baud == sent_at else garble(part)
            self._out_len -= len(data)
            return bytes(data)

    def write(self, data: bytes, baud: Optional[int] = None) -> int:
        """Receive host bytes sent at ``baud`` (``None``: at the fake's rate, whatever it is); complete
        command lines are answered immediately. Bytes at another rate arrive as noise."""
        with self._lock:
            self._check_connected()
            if self.silent:
                return len(data)
            self._in += data if baud is None or baud == self.baud else garble(data)
            while True:
                end = self._in.find(b"\n")
                if end < 0:
                    break
                line = bytes(self._in[:end + 1])
                del self._in[:end + 1]
                rate = self.baud
                self._handle_line(line)
                if self.baud != rate:  # switched: the rest was sent at the old rate
                    self._in = bytearray(garble(self._in))
            if len(self._in) > 256:  # UM001 Sec. 3.8: 256 character input buffer
                self._in = bytearray()
                self._reply("VNERR,02")
            return len(data)

    def _reply(self, body: str) -> None:
        self._emit(vp.ascii_command(body))

    def _emit(self, data: bytes) -> None:
        if self._out_len + len(data) > self.OUTPUT_LIMIT:
            return
        if self._out and self._out[-1][0] == self.baud:
            self._out[-1][1].extend(data)
        else:
            self._out.append((self.baud, bytearray(data)))
        self._out_len += len(data)

    def _handle_line(self, raw: bytes) -> None:
        text = raw.strip(b"\r\n")
        start = text.rfind(b"$")
        if start < 0:
            return  # noise without a start character is ignored, like the sensor does
        text = text[start:]
        self.commands.append(text)
        star = text.rfind(b"*")
        if star < 0:
            self._reply("VNERR,03")
            return
        body, check = text[1:star], text[star + 1:]
        if check.upper() not in (b"XX", b"XXXX"):
            try:
                parse_ok = vp.parse_ascii_response(text) is not None
            except vp.ProtocolError:
                parse_ok = False
            if not parse_ok:
                self._reply("VNERR,03")
                return
        try:
            body_text = body.decode("ascii")
        except UnicodeDecodeError:
            self._reply("VNERR,04")
            return
        parts = body_text.split(",")
        command, args = parts[0], parts[1:]
        if command == "VNASY":
            if len(args) != 1 or args[0] not in ("0", "1"):
                self._reply("VNERR,07")
                return
            self.async_paused = args[0] == "0"
            self._reply("VNASY,%s" % args[0])
        elif command == "VNRRG":
            self._read_register(args)
        elif command == "VNWRG":
            self._write_register(args)
        elif command == "VNWNV":
            if args:
                self._reply("VNERR,06")
                return
            self.flash = self._settings()
            self.flash_writes += 1
            self._reply("VNWNV")
        else:
            self._reply("VNERR,04")

    def _register_values(self, register: int) -> Optional[List[str]]:
        if register == 1:
            return [self.model]
        if register == 3:
            return [self.serial_number]
        if register == 5:
            return [str(self.baud)]
        if register == 6:
            return [str(self.ascii_output_type)]
        if register == 7:
            return [str(self.ascii_rate_hz)]
        if register in self.binary_config:
            mode, divisor, selection = self.binary_config[register]
            group_byte = 0
            for group in selection:
                group_byte |= 1 << (group - 1)
            return [str(mode), str(divisor), "%02X" % group_byte] + \
                ["%04X" % selection[g] for g in sorted(selection)]
        return None

    def _read_register(self, args: List[str]) -> None:
        if len(args) != 1:
            self._reply("VNERR,05" if not args else "VNERR,06")
            return
        try:
            register = int(args[0], 10)
        except ValueError:
            self._reply("VNERR,07")
            return
        values = self._register_values(register)
        if values is None:
            self._reply("VNERR,08")
            return
        self._reply(",".join(["VNRRG", "%02d" % register] + values))

    def _write_register(self, args: List[str]) -> None:
        if len(args) < 2:
            self._reply("VNERR,05")
            return
        try:
            register = int(args[0], 10)
        except ValueError:
            self._reply("VNERR,07")
            return
        values = args[1:]
        try:
            if register in (1, 3):
                self._reply("VNERR,09")  # model and serial number are read-only
                return
            if register == 5:
                baud = int(values[0])
                if baud not in vp.BAUD_RATES or len(values) > 1:
                    raise ValueError(baud)
                self._reply("VNWRG,%02d,%d" % (register, baud))  # still at the old rate
                if baud != self.baud:
                    self.baud = baud
                    self.baud_switches += 1
                return
            elif register == 6:
                self.ascii_output_type = int(values[0])
                if not 0 <= self.ascii_output_type <= 30:
                    raise ValueError(values[0])
            elif register == 7:
                rate = int(values[0])
                if rate not in (1, 2, 4, 5, 10, 20, 25, 40, 50, 100, 200):
                    raise ValueError(rate)
                self.ascii_rate_hz = rate
            elif register in self.binary_config:
                mode, divisor, selection = vp.parse_binary_output_config(values)
                if mode not in (0, 1, 2, 3) or not 1 <= divisor <= 0xFFFF:
                    raise ValueError(values)
                vp.encode_binary_packet(vp.Vn100Sample(0, (0.0, 0.0, 0.0, 1.0), (0.0,) * 3,
                                                       (0.0,) * 3), selection)  # validates
                self.binary_config[register] = (mode, divisor, selection)
            else:
                self._reply("VNERR,08")
                return
        except (ValueError, IndexError, vp.ProtocolError):
            self._reply("VNERR,07")
            return
        self._reply(",".join(["VNWRG", "%02d" % register] + (self._register_values(register)
                                                              or [])))

    # ------------------------------------------------------------------ output generation
    def advance(self, now: float) -> None:
        """Queue the output due in (last call, ``now``] (at most one second of it after a gap)."""
        with self._lock:
            if self._now is not None and now <= self._now:
                return
            self._now = now
            tick_now = int(math.floor((now - self.boot_time) * vp.IMU_RATE_HZ + 1e-9))
            if tick_now < 0:
                return
            if not self.connected or self.silent:
                self._next_tick = tick_now + 1  # unplugged: that output is gone, not sent on replug
                return
            first = max(self._next_tick, tick_now - int(vp.IMU_RATE_HZ) + 1)
            self._next_tick = tick_now + 1
            if self.async_paused:
                return
            mode, divisor, selection = self.binary_config[75]
            binary = mode in (1, 3) and divisor > 0
            ascii_divisor = int(vp.IMU_RATE_HZ) // self.ascii_rate_hz \
                if self.ascii_output_type == _ADOR_YMR else 0
            for tick in range(first, tick_now + 1):
                if binary and tick % divisor == 0:
                    self._emit_packet(tick, selection)
                if ascii_divisor and tick % ascii_divisor == 0:
                    self._emit_ymr()

    def next_output_time(self) -> Optional[float]:
        """Device time of the next output (binary packet or ASCII line) :meth:`advance` would queue,
        or ``None`` when nothing is due (unplugged, output paused or off). A pump sleeps until then."""
        with self._lock:
            if not self.connected or self.silent or self.async_paused:
                return None
            mode, divisor, _selection = self.binary_config[75]
            divisors = [divisor] if mode in (1, 3) and divisor > 0 else []
            if self.ascii_output_type == _ADOR_YMR and self.ascii_rate_hz:
                divisors.append(int(vp.IMU_RATE_HZ) // self.ascii_rate_hz)
            if not divisors:
                return None
            tick = min(-(-self._next_tick // d) * d for d in divisors)  # next multiple >= _next_tick
            return self.boot_time + tick / vp.IMU_RATE_HZ

    def _noisy_state(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        q, w, a = self._q_vn, self._rate_vn, self._accel_vn
        if self.noise.attitude > 0.0:
            dq = rot_to_quat(exp_so3(self.rng.normal(0.0, self.noise.attitude, 3)))
            q = quat_multiply(q, dq)
        if self.noise.angular_rate > 0.0:
            w = w + self.rng.normal(0.0, self.noise.angular_rate, 3)
        if self.noise.acceleration > 0.0:
            a = a + self.rng.normal(0.0, self.noise.acceleration, 3)
        return q, w, a

    def _emit_packet(self, tick: int, selection) -> None:
        if self.drop_probability > 0.0 and self.rng.random() < self.drop_probability:
            self.packets_dropped += 1
            return
        q, w, a = self._noisy_state()
        sample = vp.Vn100Sample(
            time_startup_ns=tick * 1250000,  # 1 / 800 Hz = 1.25 ms
            quaternion_xyzw=tuple(float(v) for v in q),
            angular_rate=tuple(float(v) for v in w),
            acceleration=tuple(float(v) for v in a))
        packet = bytearray(vp.encode_binary_packet(sample, selection))
        if self.corrupt_probability > 0.0 and self.rng.random() < self.corrupt_probability:
            index = int(self.rng.integers(0, len(packet)))
            packet[index] ^= int(self.rng.integers(1, 256))
            self.packets_corrupted += 1
        self.packets_sent += 1
        self._emit(bytes(packet))

    def _emit_ymr(self) -> None:
        """``$VNYMR``: yaw, pitch, roll (deg), mag (Gauss), accel (m/s^2), rate (rad/s)."""
        x, y, z, w = self._q_vn
        yaw = math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
        pitch = math.degrees(math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x)))))
        roll = math.degrees(math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)))
        values = [yaw, pitch, roll, 0.25, 0.0, 0.4] + list(self._accel_vn) + list(self._rate_vn)
        self._reply("VNYMR," + ",".join("%+.4f" % v for v in values))


class InMemoryPort:
    """pyserial-like port onto a :class:`FakeVn100` (``read``, ``write``, ``in_waiting``,
    ``reset_input_buffer``, ``close``, ``is_open``, ``timeout``, ``baudrate``).

    Each I/O call first lets the device catch up to ``clock()``. A read that finds fewer bytes than
    asked "blocks" for ``timeout`` by calling ``sleep`` (with a :class:`ManualClock` this advances
    simulated time; with ``sleep=None`` reads never block). ``baud``: the rate the port is set to; bytes
    only pass intact while the device talks at the same rate (``None``: always, rate not modelled).
    """

    def __init__(self, device: FakeVn100, clock: Callable[[], float] = time.monotonic,
                 sleep: Optional[Callable[[float], None]] = None, timeout: float = 0.01,
                 baud: Optional[int] = None) -> None:
        device._check_connected()
        self.device = device
        self.clock = clock
        self.sleep = sleep
        self.timeout = timeout
        self.baudrate = baud
        self.is_open = True
        self.bytes_written = bytearray()

    @classmethod
    def factory(cls, device: FakeVn100, clock: Callable[[], float] = time.monotonic,
                sleep: Optional[Callable[[float], None]] = None,
                timeout: float = 0.01, baud: Optional[int] = None) -> Callable[..., "InMemoryPort"]:
        """A port factory for :class:`~quadruped_drivers.vn100.driver.Vn100Driver`: ``factory()``
        opens at ``baud``, ``factory(rate)`` at ``rate`` (as :func:`~quadruped_drivers.vn100.driver.
        serial_port_factory`'s). Opening fails with ``OSError`` while the device is unplugged, like a
        missing ``/dev`` node."""
        def open_port(rate: Optional[int] = None) -> "InMemoryPort":
            return cls(device, clock=clock, sleep=sleep, timeout=timeout,
                       baud=baud if rate is None else rate)

        return open_port

    def _check_open(self) -> None:
        if not self.is_open:
            raise OSError(errno.EBADF, "port is closed")

    @property
    def in_waiting(self) -> int:
        self._check_open()
        self.device.advance(self.clock())
        return self.device.in_waiting

    def read(self, size: int = 1) -> bytes:
        self._check_open()
        self.device.advance(self.clock())
        data = self.device.read(size, self.baudrate)
        if len(data) < size and self.sleep is not None and self.timeout:
            self.sleep(self.timeout)
            self.device.advance(self.clock())
            data += self.device.read(size - len(data), self.baudrate)
        return data

    def write(self, data: bytes) -> int:
        self._check_open()
        self.device.advance(self.clock())
        self.bytes_written += data
        return self.device.write(bytes(data), self.baudrate)

    def reset_input_buffer(self) -> None:
        self._check_open()
        self.device.advance(self.clock())
        self.device.read(1 << 30, self.baudrate)

    def close(self) -> None:
        self.is_open = False


_TCGETS2 = 0x802C542A  # _IOR('T', 0x2A, struct termios2), asm-generic (x86, ARM); else tcgetattr below
#: termios speed constant -> baud, for the fallback without TCGETS2.
_TERMIOS_SPEEDS: Dict[int, int] = {}
if fcntl is not None:
    for _rate in vp.BAUD_RATES:
        _code = getattr(termios, "B%d" % _rate, None)
        if _code is not None:
            _TERMIOS_SPEEDS[_code] = _rate


class PtyFakeVn100:
    """Serve a :class:`FakeVn100` on a pseudo-terminal so a real serial driver can open it.

    ``start()`` creates the pty pair (raw mode), optionally a symlink ``symlink_path`` -> slave
    device (e.g. ``/tmp/sim/vn100``), and a thread that advances the fake to ``clock()``, writes its
    output to the master and feeds bytes read from the master (host commands) to it. The thread is
    paced by the device: it sleeps until the fake's next output is due on ``clock`` (so a 200 Hz
    stream costs 200 wake-ups a second and each packet leaves on time), until host bytes arrive, or
    until :meth:`wake` (the owner moved a simulated ``clock``), but never longer than ``period``.
    With ``realtime=False`` (``clock`` is a simulated clock that only the owner advances) it sleeps
    until :meth:`wake` or host bytes, ``period`` at most. ``stop()`` ends the thread and removes the pty
    and the symlink.

    Baud rate: the kernel does not clock a pty's bytes at its termios speed, so the bridge models it: it
    reads the speed the host (pyserial) set on the pty (:meth:`host_baud`) and passes it with every
    byte to and from the fake, which garbles the bytes unless it talks at that speed. A driver opening
    the pty at another rate than the fake's sees noise, as on a real serial line.
    """

    PENDING_LIMIT = 1 << 16

    def __init__(self, device: FakeVn100, clock: Callable[[], float] = time.monotonic,
                 symlink_path: Optional[str] = None, period: float = 0.05, realtime: bool = True) -> None:
        self.device = device
        self.clock = clock
        self.symlink_path = symlink_path
        self.period = period
        self.realtime = realtime
        self._wake_r: Optional[int] = None
        self._wake_w: Optional[int] = None
        self._master: Optional[int] = None
        self._slave: Optional[int] = None
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self.slave_path: Optional[str] = None
        self.error: Optional[BaseException] = None

    def start(self) -> str:
        """Open the pty and start pumping; returns the path the driver should open."""
        if self._thread is not None:
            raise RuntimeError("PtyFakeVn100 already started")
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self.slave_path = os.ttyname(slave)
        path = self.slave_path
        if self.symlink_path:
            if os.path.islink(self.symlink_path):
                os.unlink(self.symlink_path)
            directory = os.path.dirname(self.symlink_path)
            if directory:
                os.makedirs(directory, exist_ok=True)
            os.symlink(self.slave_path, self.symlink_path)
            path = self.symlink_path
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="fake-vn100-pty", daemon=True)
        self._thread.start()
        return path

    @property
    def path(self) -> Optional[str]:
        return self.symlink_path or self.slave_path

    def wake(self) -> None:
        """Make the pump thread advance the device to ``clock()`` now (call after moving the clock)."""
        if self._wake_w is not None:
            try:
                os.write(self._wake_w, b"w")
            except (BlockingIOError, OSError):
                pass  # already woken (pipe full) or stopped

    def host_baud(self) -> Optional[int]:
        """The speed the host's side of the pty is set to (the rate pyserial opened it at), ``None`` if
        unknown (then bytes pass unmodelled). Read on the bridge's own slave descriptor: termios is the
        pty's, shared by every descriptor open on it."""
        fd = self._slave
        if fd is None or fcntl is None:
            return None
        try:  # struct termios2 (Linux): c_ospeed holds the speed in baud, standard or not (BOTHER)
            buf = array.array("i", [0] * 64)
            fcntl.ioctl(fd, _TCGETS2, buf)
            if buf[10] > 0:
                return int(buf[10])
        except (OSError, ValueError):
            pass
        try:
            return _TERMIOS_SPEEDS.get(termios.tcgetattr(fd)[5])
        except (termios.error, OSError, ValueError):
            return None

    def _sleep_time(self, pending: bool) -> float:
        if pending:
            return min(self.period, 0.001)  # the pty buffer was full: retry soon
        if not self.realtime:
            return self.period
        due = self.device.next_output_time()
        if due is None:
            return self.period
        return min(self.period, max(0.0, due - self.clock()))

    def _run(self) -> None:
        master, wake = self._master, self._wake_r
        assert master is not None and wake is not None
        pending = bytearray()
        try:
            while not self._stop.is_set():
                self.device.advance(self.clock())
                try:
                    pending += self.device.read(self.PENDING_LIMIT, self.host_baud())
                except OSError:
                    pending = bytearray()  # unplugged: nothing leaves the device
                if len(pending) > self.PENDING_LIMIT:
                    del pending[:len(pending) - self.PENDING_LIMIT]
                if pending:
                    try:
                        written = os.write(master, bytes(pending))
                        del pending[:written]
                    except BlockingIOError:
                        pass
                readable, _, _ = select.select([master, wake], [], [], self._sleep_time(bool(pending)))
                if wake in readable:
                    try:
                        os.read(wake, 4096)
                    except (BlockingIOError, InterruptedError):
                        pass
                if master in readable:
                    try:
                        data = os.read(master, 4096)
                    except (BlockingIOError, InterruptedError):
                        data = b""
                    if data:
                        try:
                            self.device.write(data, self.host_baud())
                        except OSError:
                            pass  # unplugged: the bytes are lost
        except BaseException as exc:  # surfaced to the owner via .error
            self.error = exc

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = self._wake_r = self._wake_w = None
        if self.symlink_path and os.path.islink(self.symlink_path):
            os.unlink(self.symlink_path)

    def __enter__(self) -> "PtyFakeVn100":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
