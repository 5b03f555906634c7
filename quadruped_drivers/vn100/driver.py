"""VN-100 serial driver: baud rate search, configuration handshake, sample streaming, reconnection (no ROS).

:class:`Vn100Driver` owns one pyserial-like port (``read(n)``, ``write(b)``, ``in_waiting``,
``close()``, optional ``reset_input_buffer()``, ``timeout`` attribute; pyserial's
``serial.Serial`` and :class:`~quadruped_drivers.vn100.fake.InMemoryPort` both qualify), opened by
``port_factory(rate)`` at a baud rate (:func:`serial_port_factory` and ``InMemoryPort.factory`` make such
factories); without a configured ``baud`` the driver calls ``port_factory()`` and talks at the rate it gets.
Connecting (UM001 Sec. 3.9, 4.2.3, register 5):

1. Find the sensor. At each rate in turn, the configured ``baud`` first (``command_retries + 1`` tries),
   then :data:`SEARCH_ORDER` (115200, the factory default, then the others from fast to slow; one try
   each): open the port there, send ``$VNASY,0`` (pause asynchronous output) and ``$VNRRG,01`` (model
   number, :attr:`Vn100Driver.model`) and wait ``probe_timeout`` plus :data:`PROBE_BITS` bit times for a
   ``$VNRRG,01`` reply with a valid checksum. At a wrong rate each side receives noise, so no reply can
   form. Nothing at any rate: ``Vn100Error`` naming the port and the rates tried.
2. Found at another rate: ``$VNWRG,05,<baud>`` (the sensor answers at the old rate, then switches), open
   the port again at ``baud`` and identify the sensor there; with ``save_baud`` (only then) ``$VNWNV``
   writes the sensor's settings to its flash, so that it keeps the rate over a power cycle. One line goes
   to ``log`` ("VN-100 found at 115200 baud, switched to 921600 (not saved to flash; ...)").
3. ``$VNRRG,03`` the serial number (:attr:`Vn100Driver.serial_number`: the diagnostics' hardware ID);
4. ``$VNWRG,06,0`` turn off ASCII asynchronous output;
5. ``$VNWRG,75,1,<800/rate>,01,0131`` binary output 1 on serial port 1: TimeStartup, Quaternion,
   AngularRate, Accel (group 1); the echoed register contents are checked;
6. ``$VNASY,1`` resume.

Each reply is the next ``$VN`` line whose command and register match, found by the same streaming
parser that decodes binary packets, so packets interleaved with the replies are harmless; a
``$VNERR`` fails the step with the sensor's reason; a missing reply is retried, then fails. (While
searching, a second parser reads the noise of the wrong rates, so the link's counters do not count it.)

Serial errors never escape :meth:`Vn100Driver.read_samples`: the port is closed, ``disconnects``
counted, ``last_error`` set. The first attempt to connect again is immediate (the next call); each failed
attempt doubles the wait before the next, from ``reconnect_initial_delay`` up to ``reconnect_max_delay``
(on the injected ``clock``), so a short glitch costs about itself and an absent sensor is tried about every
``reconnect_max_delay`` s. The back-off starts again only once a connection has delivered samples: a
sensor that configures but never streams is not reconfigured in a tight loop. Optionally
(``stale_timeout``) a connection delivering no valid packet for that long is treated as lost (e.g. the
sensor reset and lost its configuration). That silence is judged on ``link_clock`` (default ``clock``):
the node passes the ROS clock, so in lock-step simulation (simulated time) the link times out after 0.1 s
of *simulated* silence, as on the robot, and not when a loaded machine takes 0.1 s of wall time for one
step; reply and reconnect deadlines stay on ``clock`` (bytes on a wire take wall time, and simulated time
stands still while the sensor is set up).
"""
from __future__ import annotations

import logging
import time
from typing import Callable, Dict, List, Optional, Sequence

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
    """The sensor did not complete the configuration handshake (not found at any baud rate, no reply,
    ``$VNERR``, mismatch)."""


#: Where the driver looks for the sensor after its configured rate: the factory default first, then the
#: other standard rates from fast to slow (the likely choices, and the cheapest to try).
SEARCH_ORDER = (vp.FACTORY_BAUD,) + tuple(sorted((b for b in vp.BAUD_RATES if b != vp.FACTORY_BAUD),
                                                 reverse=True))
#: Added to ``probe_timeout`` per probe, in bit times of the rate tried: 200 bytes of 10 bits (the probe,
#: its reply and a line of asynchronous output queued before the pause): 0.21 s at 9600, 2 ms at 921600.
PROBE_BITS = 2000


def serial_port_factory(path: str, baud: int, timeout: float = 0.01
                        ) -> Callable[..., PortLike]:
    """A factory opening ``path`` with pyserial (imported here, so the module works without it):
    ``factory()`` at ``baud``, ``factory(rate)`` at ``rate`` (the driver's baud rate search);
    ``factory.path`` is ``path``.

    8N1, read timeout ``timeout`` s, write timeout 0.5 s, exclusive access (a second driver gets an
    error instead of stealing bytes). Low-latency mode is requested where the kernel supports it
    (the udev rule sets the FTDI latency timer to 1 ms as well).
    """
    import serial  # noqa: WPS433 (lazy: pyserial is only needed on a real or pty port)

    if not path:
        raise ValueError("serial port path is empty")
    if int(baud) <= 0:
        raise ValueError("baud rate must be positive, got %r" % (baud,))
    default_baud = int(baud)

    def open_port(rate: Optional[int] = None) -> PortLike:
        port = serial.Serial(path, default_baud if rate is None else int(rate), timeout=timeout,
                             write_timeout=0.5, exclusive=True)
        try:
            port.set_low_latency_mode(True)
        except (AttributeError, OSError, ValueError, NotImplementedError):
            pass  # not a real UART (pty) or not Linux
        return port

    open_port.path = path  # type: ignore[attr-defined]
    return open_port


class Vn100Driver:
    """VN-100 driver over a port from ``port_factory``; see the module docstring.

    ``rate_hz`` must divide 800 Hz (``ValueError`` otherwise). ``command_timeout``: seconds to wait
    for each reply, ``command_retries``: extra attempts per command (and per probe at ``baud``).
    ``baud``: the rate to talk at (``None``: the port's own, no search); ``search_bauds``: the rates tried
    after it (default :data:`SEARCH_ORDER`); ``save_baud``: write the flash after switching the sensor's
    rate; ``probe_timeout``: wait per probe (plus :data:`PROBE_BITS` bit times). ``port_name`` (default
    ``port_factory.path``) names the port in errors; ``log`` receives the line saying that the sensor's
    rate was switched. Counters: ``disconnects``, ``connects``, ``connect_failures``, ``baud_switches``,
    ``bad_ascii_lines``; the parser's own counters are in :attr:`parser`.
    """

    def __init__(self, port_factory: Callable[..., PortLike], rate_hz: float = 200.0,
                 clock: Callable[[], float] = time.monotonic, reconnect_initial_delay: float = 0.02,
                 reconnect_max_delay: float = 1.0, read_size: int = 4096, command_timeout: float = 0.5,
                 command_retries: int = 2, stale_timeout: Optional[float] = None, async_mode: int = 1,
                 group1_fields: int = vp.DEFAULT_GROUP1_FIELDS,
                 link_clock: Optional[Callable[[], float]] = None, baud: Optional[int] = None,
                 save_baud: bool = False, probe_timeout: float = 0.05,
                 search_bauds: Optional[Sequence[int]] = None, port_name: Optional[str] = None,
                 log: Optional[Callable[[str], None]] = None) -> None:
        self.rate_divisor = vp.rate_divisor_for(rate_hz)
        self.rate_hz = vp.IMU_RATE_HZ / self.rate_divisor
        if not (0 <= reconnect_initial_delay <= reconnect_max_delay) or command_timeout <= 0 \
                or read_size < 1 or command_retries < 0 or not probe_timeout > 0:
            raise ValueError("0 <= reconnect_initial_delay <= reconnect_max_delay, command_timeout > 0, "
                             "probe_timeout > 0, read_size >= 1 and command_retries >= 0 are required")
        if stale_timeout is not None and stale_timeout <= 0:
            raise ValueError("stale_timeout must be positive or None")
        search = tuple(SEARCH_ORDER if search_bauds is None else search_bauds)
        for rate in ((baud,) if baud is not None else ()) + search:
            if rate not in vp.BAUD_RATES:
                raise ValueError("%r is not a VN-100 baud rate (%s)"
                                 % (rate, ", ".join(str(b) for b in vp.BAUD_RATES)))
        self._configure_command = vp.configure_binary_output_command(
            self.rate_divisor, group1_fields, register=75, async_mode=async_mode)
        self._expected_config = (async_mode, self.rate_divisor, {1: group1_fields})
        self._port_factory = port_factory
        self._clock = clock
        self._link_clock = link_clock if link_clock is not None else clock
        self.reconnect_initial_delay = float(reconnect_initial_delay)
        self.reconnect_max_delay = float(reconnect_max_delay)
        self.read_size = int(read_size)
        self.command_timeout = float(command_timeout)
        self.command_retries = int(command_retries)
        self.stale_timeout = stale_timeout
        self.baud = None if baud is None else int(baud)
        self.search_bauds = search
        self.save_baud = bool(save_baud)
        self.probe_timeout = float(probe_timeout)
        self.port_name = port_name or getattr(port_factory, "path", None) or "the serial port"
        self._log = log if log is not None else logging.getLogger(__name__).warning
        self.parser = BinaryPacketParser(groups_fields={1: group1_fields})
        self._probe_parser = BinaryPacketParser(groups_fields={1: group1_fields})
        self._port: Optional[PortLike] = None
        self._pending: List[Vn100Sample] = []
        self._next_attempt: float = float("-inf")
        self._delay = self.reconnect_initial_delay  # wait after the next failed attempt
        self._streamed = False  # the current connection has delivered samples
        self.model: Optional[str] = None
        self.serial_number: Optional[str] = None
        self.port_baud: Optional[int] = None  # the rate the open port is set to
        self.found_baud: Optional[int] = None  # the rate the sensor answered at on the last connect
        self.last_baud_change = ""
        self.last_error = ""
        self.disconnects = 0
        self.connects = 0
        self.connect_failures = 0
        self.baud_switches = 0
        self.bad_ascii_lines = 0
        self.sensor_errors: List[AsciiResponse] = []
        self.last_sample_time: Optional[float] = None

    # ------------------------------------------------------------------ state
    @property
    def connected(self) -> bool:
        return self._port is not None

    @property
    def next_attempt(self) -> float:
        """``clock`` time of the next connection attempt of :meth:`read_samples` while disconnected."""
        return self._next_attempt

    def counters(self) -> Dict[str, int]:
        """Driver and parser counters, for diagnostics."""
        result = dict(self.parser.counters())
        result.update(disconnects=self.disconnects, connects=self.connects,
                      connect_failures=self.connect_failures, baud_switches=self.baud_switches,
                      bad_ascii_lines=self.bad_ascii_lines)
        return result

    def close(self) -> None:
        """Close the port (binary output keeps streaming on the sensor; harmless)."""
        port, self._port = self._port, None
        self.port_baud = None
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001 - closing a dead port must not raise
                pass

    # ------------------------------------------------------------------ connection
    def connect(self) -> None:
        """Find the sensor, open the port at its rate and run the configuration handshake;
        ``Vn100Error``/``OSError`` on failure (the port is closed again, ``last_error`` set and the next
        attempt of :meth:`read_samples` scheduled after the back-off delay)."""
        self.close()
        self.parser.reset()
        self._pending = []
        try:
            self._find_sensor()
            self._configure()
        except Exception as exc:
            self.close()
            self.connect_failures += 1
            self.last_error = "connect failed: %s" % (exc,)
            self._schedule_retry()
            raise
        self.connects += 1
        self._streamed = False
        self.last_error = ""
        self.last_sample_time = self._link_time()

    def _schedule_retry(self) -> None:
        """Next attempt after the current delay, which doubles (up to ``reconnect_max_delay``)."""
        self._next_attempt = self._clock() + self._delay
        self._delay = min(2.0 * self._delay, self.reconnect_max_delay)

    def _open(self, rate: Optional[int]) -> None:
        self._port = self._port_factory() if rate is None else self._port_factory(rate)
        self.port_baud = rate

    def _find_sensor(self) -> None:
        """Step 1 and 2 of the module docstring: the port open at ``baud`` with the sensor answering."""
        if self.baud is None:
            self._open(None)
            attempts = self.command_retries + 1
            if not self._probe(attempts, None):
                raise Vn100Error("no reply to $VNRRG,01 within %.3g s (%d attempts)"
                                 % (self.probe_timeout, attempts))
            return
        tried: List[str] = []
        found: Optional[int] = None
        for rate in (self.baud,) + tuple(r for r in self.search_bauds if r != self.baud):
            try:
                self._open(rate)
            except (OSError, ValueError) as exc:
                if rate == self.baud:
                    raise  # no port at all (unplugged) or a rate the adapter refuses: no search
                tried.append("%d (cannot open: %s)" % (rate, exc))
                continue
            tried.append(str(rate))
            if self._probe(self.command_retries + 1 if rate == self.baud else 1, rate):
                found = rate
                break
            self.close()
        if found is None:
            raise Vn100Error("no VN-100 answered on %s at %s baud (no valid reply to $VNRRG,01)"
                             % (self.port_name, ", ".join(tried)))
        self.found_baud = found
        if found != self.baud:
            self._switch_baud(found)

    def _switch_baud(self, found: int) -> None:
        """The sensor answered at ``found``: switch it (register 5) and the port to ``baud``."""
        assert self.baud is not None
        self._command(vp.write_baud_rate_command(self.baud), "VNWRG", vp.BAUD_RATE_REGISTER)
        self.close()  # the reply came at the old rate; the sensor talks at the new one from now on
        self._open(self.baud)
        if not self._probe(self.command_retries + 1, self.baud):
            raise Vn100Error("VN-100 found at %d baud on %s and switched to %d (register 5), but it does "
                             "not answer at %d" % (found, self.port_name, self.baud, self.baud))
        if self.save_baud:
            self._command(vp.write_settings_command(), "VNWNV", None)
            note = "saved to flash"
        else:
            note = "not saved to flash; set save_baud: true to keep it"
        self.baud_switches += 1
        self.last_baud_change = "VN-100 found at %d baud, switched to %d (%s)" % (found, self.baud, note)
        self._log(self.last_baud_change)

    def _probe(self, attempts: int, rate: Optional[int]) -> bool:
        """Is the sensor there at the open port's rate? ``$VNASY,0`` + ``$VNRRG,01``, ``attempts`` times,
        each awaited ``probe_timeout`` (+ :data:`PROBE_BITS` bit times at ``rate``); sets :attr:`model`."""
        port = self._port
        assert port is not None
        reset = getattr(port, "reset_input_buffer", None)
        if callable(reset):
            reset()
        self._probe_parser.reset()
        timeout = self.probe_timeout + (PROBE_BITS / float(rate) if rate else 0.0)
        probe = vp.async_pause_command() + vp.read_model_command()
        for _ in range(attempts):
            self._probe_parser.pop_ascii_lines()
            port.write(probe)
            reply = self._await_reply("VNRRG", vp.MODEL_REGISTER, False, timeout=timeout,
                                      parser=self._probe_parser, probing=True)
            if reply is not None:
                self.model = ",".join(reply.values)
                return True
        return False

    def _configure(self) -> None:
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

    def _await_reply(self, name: str, register: Optional[int], keep_samples: bool,
                     timeout: Optional[float] = None, parser: Optional[BinaryPacketParser] = None,
                     probing: bool = False) -> Optional[AsciiResponse]:
        """The reply line to ``name``/``register`` within ``timeout`` (default ``command_timeout``), a
        ``$VNERR`` (not while ``probing``: then an error line may be the answer to the noise of another
        rate, and it is skipped), or None."""
        port = self._port
        assert port is not None
        parser = self.parser if parser is None else parser
        deadline = self._clock() + (self.command_timeout if timeout is None else timeout)
        # Backstop against a clock that never advances (a pyserial read blocks <= port.timeout).
        for _ in range(100000):
            waiting = port.in_waiting
            data = port.read(min(max(waiting, 1), self.read_size))
            if data:
                samples = parser.feed(data)
                if keep_samples:
                    self._pending.extend(samples)
                for line in parser.pop_ascii_lines():
                    try:
                        response = vp.parse_ascii_response(line)
                    except vp.ProtocolError:
                        if not probing:
                            self.bad_ascii_lines += 1
                        continue
                    if response.is_error:
                        if probing:
                            continue
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
        if self._streamed:  # a working link lost: try again at once, the back-off from its start
            self._delay = self.reconnect_initial_delay
            self._next_attempt = self._clock()
        else:  # lost before it delivered a sample: keep backing off
            self._schedule_retry()

    def read_samples(self) -> List[Vn100Sample]:
        """Samples received since the last call (never raises on serial or sensor errors).

        While disconnected, returns ``[]`` and tries :meth:`connect` when the back-off allows: at once
        after a working link was lost (and at start), then after doubling delays.
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
        if samples and not self._streamed:
            self._streamed = True
            self._delay = self.reconnect_initial_delay
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
