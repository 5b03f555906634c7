"""VN-100 serial driver: configuration handshake, sample streaming, reconnection (no ROS).

:class:`Vn100Driver` owns one pyserial-like port (``read(n)``, ``write(b)``, ``in_waiting``,
``close()``, optional ``reset_input_buffer()``, ``timeout`` attribute; pyserial's
``serial.Serial`` and :class:`~quadruped_drivers.vn100.fake.InMemoryPort` both qualify). The
configuration sequence (UM001 Sec. 3.9, 4.2.3) is

1. ``$VNASY,0`` pause asynchronous output (its echo is awaited but optional), flush input;
2. ``$VNRRG,01`` read the model number (:attr:`Vn100Driver.model`), ``$VNRRG,03`` the serial number
   (:attr:`Vn100Driver.serial_number`: the diagnostics' hardware ID);
3. ``$VNWRG,06,0`` turn off ASCII asynchronous output;
4. ``$VNWRG,75,1,<800/rate>,01,0131`` binary output 1 on serial port 1: TimeStartup, Quaternion,
   AngularRate, Accel (group 1); the echoed register contents are checked;
5. ``$VNASY,1`` resume.

Each reply is the next ``$VN`` line whose command and register match, found by the same streaming
parser that decodes binary packets, so packets interleaved with the replies are harmless; a
``$VNERR`` fails the step with the sensor's reason; a missing reply is retried, then fails.

Serial errors never escape :meth:`Vn100Driver.read_samples`: the port is closed, ``disconnects``
counted, ``last_error`` set, and a new connection is attempted every ``reconnect_interval`` s of
the injected ``clock``. Optionally (``stale_timeout``) a connection delivering no valid packet for
that long is treated the same way (e.g. the sensor reset and lost its configuration). That silence is
judged on ``link_clock`` (default ``clock``): the node passes the ROS clock, so in lock-step simulation
(simulated time) the link times out after 0.1 s of *simulated* silence, as on the robot, and not when
a loaded machine takes 0.1 s of wall time for one step; reply and reconnect deadlines stay on
``clock`` (bytes on a wire take wall time, and simulated time stands still while the sensor is set up).
"""
from __future__ import annotations

import time
from typing import Callable, Dict, List, Optional

from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.protocol import AsciiResponse, BinaryPacketParser, Vn100Sample

try:  # typing only
    from typing import Protocol
except ImportError:  # pragma: no cover - Python 3.7
    Protocol = object  # type: ignore


class PortLike(Protocol):  # type: ignore[misc]
    """The subset of ``serial.Serial`` the driver uses."""

    timeout: Optional[float]

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> Optional[int]: ...

    @property
    def in_waiting(self) -> int: ...

    def close(self) -> None: ...


class Vn100Error(RuntimeError):
    """The sensor did not complete the configuration handshake (no reply, ``$VNERR``, mismatch)."""


def serial_port_factory(path: str, baud: int, timeout: float = 0.01
                        ) -> Callable[[], PortLike]:
    """A factory opening ``path`` with pyserial (imported here, so the module works without it).

    8N1, read timeout ``timeout`` s, write timeout 0.5 s, exclusive access (a second driver gets an
    error instead of stealing bytes). Low-latency mode is requested where the kernel supports it
    (the udev rule sets the FTDI latency timer to 1 ms as well).
    """
    import serial  # noqa: WPS433 (lazy: pyserial is only needed on a real or pty port)

    if not path:
        raise ValueError("serial port path is empty")
    if int(baud) <= 0:
        raise ValueError("baud rate must be positive, got %r" % (baud,))

    def open_port() -> PortLike:
        port = serial.Serial(path, int(baud), timeout=timeout, write_timeout=0.5,
                             exclusive=True)
        try:
            port.set_low_latency_mode(True)
        except (AttributeError, OSError, ValueError, NotImplementedError):
            pass  # not a real UART (pty) or not Linux
        return port

    return open_port


class Vn100Driver:
    """VN-100 driver over a port from ``port_factory``; see the module docstring.

    ``rate_hz`` must divide 800 Hz (``ValueError`` otherwise). ``command_timeout``: seconds to wait
    for each reply, ``command_retries``: extra attempts per command. Counters: ``disconnects``,
    ``connect_failures``, ``bad_ascii_lines``; the parser's own counters are in :attr:`parser`.
    """

    def __init__(self, port_factory: Callable[[], PortLike], rate_hz: float = 200.0,
                 clock: Callable[[], float] = time.monotonic, reconnect_interval: float = 1.0,
                 read_size: int = 4096, command_timeout: float = 0.5, command_retries: int = 2,
                 stale_timeout: Optional[float] = None, async_mode: int = 1,
                 group1_fields: int = vp.DEFAULT_GROUP1_FIELDS,
                 link_clock: Optional[Callable[[], float]] = None) -> None:
        self.rate_divisor = vp.rate_divisor_for(rate_hz)
        self.rate_hz = vp.IMU_RATE_HZ / self.rate_divisor
        if reconnect_interval < 0 or command_timeout <= 0 or read_size < 1 or command_retries < 0:
            raise ValueError("reconnect_interval >= 0, command_timeout > 0, read_size >= 1 and "
                             "command_retries >= 0 are required")
        if stale_timeout is not None and stale_timeout <= 0:
            raise ValueError("stale_timeout must be positive or None")
        self._configure_command = vp.configure_binary_output_command(
            self.rate_divisor, group1_fields, register=75, async_mode=async_mode)
        self._expected_config = (async_mode, self.rate_divisor, {1: group1_fields})
        self._port_factory = port_factory
        self._clock = clock
        self._link_clock = link_clock if link_clock is not None else clock
        self.reconnect_interval = float(reconnect_interval)
        self.read_size = int(read_size)
        self.command_timeout = float(command_timeout)
        self.command_retries = int(command_retries)
        self.stale_timeout = stale_timeout
        self.parser = BinaryPacketParser(groups_fields={1: group1_fields})
        self._port: Optional[PortLike] = None
        self._pending: List[Vn100Sample] = []
        self._next_attempt: float = float("-inf")
        self.model: Optional[str] = None
        self.serial_number: Optional[str] = None
        self.last_error = ""
        self.disconnects = 0
        self.connects = 0
        self.connect_failures = 0
        self.bad_ascii_lines = 0
        self.sensor_errors: List[AsciiResponse] = []
        self.last_sample_time: Optional[float] = None

    # ------------------------------------------------------------------ state
    @property
    def connected(self) -> bool:
        return self._port is not None

    def counters(self) -> Dict[str, int]:
        """Driver and parser counters, for diagnostics."""
        result = dict(self.parser.counters())
        result.update(disconnects=self.disconnects, connects=self.connects,
                      connect_failures=self.connect_failures,
                      bad_ascii_lines=self.bad_ascii_lines)
        return result

    def close(self) -> None:
        """Close the port (binary output keeps streaming on the sensor; harmless)."""
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001 - closing a dead port must not raise
                pass

    # ------------------------------------------------------------------ connection
    def connect(self) -> None:
        """Open the port and run the configuration handshake; ``Vn100Error``/``OSError`` on
        failure (the port is closed again and ``last_error`` set)."""
        self.close()
        self.parser.reset()
        self._pending = []
        try:
            self._port = self._port_factory()
            self._configure()
        except Exception as exc:
            self.close()
            self.connect_failures += 1
            self.last_error = "connect failed: %s" % (exc,)
            self._next_attempt = self._clock() + self.reconnect_interval
            raise
        self.connects += 1
        self.last_error = ""
        self.last_sample_time = self._link_time()

    def _configure(self) -> None:
        port = self._port
        assert port is not None
        self._command(vp.async_pause_command(), "VNASY", None, required=False)
        reset = getattr(port, "reset_input_buffer", None)
        if callable(reset):
            reset()
        self.parser.reset()
        reply = self._command(vp.read_model_command(), "VNRRG", vp.MODEL_REGISTER)
        self.model = ",".join(reply.values)
        reply = self._command(vp.read_serial_number_command(), "VNRRG", vp.SERIAL_NUMBER_REGISTER)
        self.serial_number = ",".join(reply.values)
        self._command(vp.disable_ascii_output_command(), "VNWRG",
                      vp.ASYNC_OUTPUT_TYPE_REGISTER)
        reply = self._command(self._configure_command, "VNWRG", 75)
        try:
            echoed = vp.parse_binary_output_config(reply.values)
        except vp.ProtocolError as exc:
            raise Vn100Error("unexpected binary output register echo: %s" % exc)
        if echoed != self._expected_config:
            raise Vn100Error("binary output register reads back %r, expected %r"
                             % (echoed, self._expected_config))
        self._pending = []
        self._command(vp.async_resume_command(), "VNASY", None, required=False,
                      keep_samples=True)

    def _command(self, command: bytes, name: str, register: Optional[int], required: bool = True,
                 keep_samples: bool = False) -> AsciiResponse:
        """Send ``command`` and wait for the reply line; retried ``command_retries`` times."""
        port = self._port
        assert port is not None
        label = command.decode("ascii").strip()
        attempts = self.command_retries + 1 if required else 1
        for _ in range(attempts):
            self.parser.pop_ascii_lines()
            port.write(command)
            reply = self._await_reply(name, register, keep_samples)
            if reply is not None:
                if reply.is_error:
                    self.sensor_errors.append(reply)
                    raise Vn100Error("sensor rejected %s: %s (0x%02X)"
                                     % (label, reply.error_name, reply.error_code or 0))
                return reply
        if required:
            raise Vn100Error("no reply to %s within %.3g s (%d attempts)"
                             % (label, self.command_timeout, attempts))
        return AsciiResponse(command=name, fields=())

    def _await_reply(self, name: str, register: Optional[int],
                     keep_samples: bool) -> Optional[AsciiResponse]:
        port = self._port
        assert port is not None
        deadline = self._clock() + self.command_timeout
        # Backstop against a clock that never advances (a pyserial read blocks <= port.timeout).
        for _ in range(100000):
            waiting = port.in_waiting
            data = port.read(min(max(waiting, 1), self.read_size))
            if data:
                samples = self.parser.feed(data)
                if keep_samples:
                    self._pending.extend(samples)
                for line in self.parser.pop_ascii_lines():
                    try:
                        response = vp.parse_ascii_response(line)
                    except vp.ProtocolError:
                        self.bad_ascii_lines += 1
                        continue
                    if response.is_error:
                        return response
                    if response.command == name and (register is None
                                                     or response.register == register):
                        return response
            if self._clock() >= deadline:
                return None
        return None

    # ------------------------------------------------------------------ streaming
    def _disconnect(self, reason: str) -> None:
        self.close()
        self.disconnects += 1
        self.last_error = reason
        self._next_attempt = self._clock() + self.reconnect_interval

    def read_samples(self) -> List[Vn100Sample]:
        """Samples received since the last call (never raises on serial or sensor errors).

        While disconnected, returns ``[]`` and tries :meth:`connect` once the reconnect interval
        has passed (immediately the first time).
        """
        if self._port is None:
            now = self._clock()
            if now < self._next_attempt:
                return []
            try:
                self.connect()
            except (OSError, Vn100Error, ValueError) as exc:
                self.last_error = "connect failed: %s" % (exc,)
                return []
        port = self._port
        assert port is not None
        samples, self._pending = self._pending, []
        try:
            for _ in range(8):  # drain bursts, bounded so one call cannot spin forever
                waiting = port.in_waiting
                data = port.read(min(max(waiting, 1), self.read_size))
                if not data:
                    break
                samples.extend(self.parser.feed(data))
                for line in self.parser.pop_ascii_lines():
                    self._note_line(line)
                if port.in_waiting <= 0:
                    break
        except (OSError, ValueError) as exc:  # pyserial: SerialException is an OSError
            self._disconnect("serial error: %s" % (exc,))
            return samples
        now = self._link_time()
        if samples or self.last_sample_time is None:
            self.last_sample_time = now
        elif (self.stale_timeout is not None and now is not None
              and now - self.last_sample_time > self.stale_timeout):
            self._disconnect("no valid packet for %.3g s" % (now - self.last_sample_time))
        return samples

    def _link_time(self) -> Optional[float]:
        """``link_clock`` now, or None while it has no time yet: ROS time reads 0 under /use_sim_time
        until the first /clock. Silence is counted from the first reading that has a time; counting
        it from 0 made a link set up before the simulation's first /clock look silent for t_0 s the
        moment that clock arrived, and the driver dropped a link that had just been configured (in
        lock-step, while the simulation had started sending: its first samples were lost)."""
        now = self._link_clock()
        return now if now > 0 else None

    def _note_line(self, line: bytes) -> None:
        """Lines while streaming are unexpected; a ``$VNERR`` is kept for diagnostics."""
        try:
            response = vp.parse_ascii_response(line)
        except vp.ProtocolError:
            self.bad_ascii_lines += 1
            return
        if response.is_error:
            self.sensor_errors.append(response)
            del self.sensor_errors[:-16]
            self.last_error = "sensor error: %s" % response.error_name
