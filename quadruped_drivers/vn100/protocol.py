"""VectorNav VN-100 serial protocol: binary output packets and ASCII commands (pure, no I/O).

References (VectorNav UM001, VN-100 User Manual):

* Sec. 3.9: ASCII messages ``$VN<body>*XX\\r\\n`` carry an 8-bit XOR checksum of every byte between
  ``$`` and ``*`` (two hex digits) or a 16-bit CRC16-CCITT of the same bytes (four hex digits).
  Example: ``$VNRRG,11*73``.
* Sec. 3.8: ``$VNERR,<code>`` reports errors; the codes are listed in hex (0x01 .. 0x0C, 0xFF).
* Sec. 4.2.3: binary output registers 75-77,
  ``$VNWRG,75,<AsyncMode>,<RateDivisor>,<OutputGroup hex>,<GroupField hex>...``; output rate is
  ImuRate (800 Hz) / RateDivisor.
* Sec. 4.3: binary packet = sync byte 0xFA, group byte, one little-endian u16 field mask per active
  group (in group order), little-endian payload without padding, CRC16-CCITT (XMODEM, initial value 0)
  of everything after the sync byte, stored big-endian, so that the CRC over group byte .. CRC is 0.
  Bit 7 of a group byte and bit 15 of a field word are extension bits (continuation bytes/words).
* Sec. 4.3.6: payload sizes per (group, field) -- :data:`FIELD_SIZES` below. Group 1 (common)
  fields: TimeStartup u64 ns (bit 0), TimeGps (1), TimeSyncIn (2), YawPitchRoll 3f deg (3),
  Quaternion 4f x,y,z,w (4), AngularRate 3f rad/s (5), Position (6), Velocity (7), Accel 3f m/s^2
  (8), Imu (9), MagPres (10), DeltaTheta (11), InsStatus/AhrsStatus (12), SyncInCnt (13),
  TimeGpsPps (14).

Frames and signs of :class:`Vn100Sample` (UM001 Sec. 4.4.4-4.4.6): the quaternion is the attitude of
the sensor body frame (x forward, y right, z down: FRD) relative to local North-East-Down, scalar
last; angular rate is in the body frame (rad/s, bias compensated); acceleration is in the body frame
and "includes gravity", i.e. it is the specific force an accelerometer senses: a level sensor at rest
reads about (0, 0, -9.81) m/s^2 (the support force points up, along -z of FRD; see also
KumarRobotics/imu_vn_100 issue #17). :mod:`quadruped_drivers.vn100.conversions` turns this into
ROS REP-103/REP-145 frames.
"""
from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

SYNC = 0xFA
ASCII_START = 0x24  # '$'
IMU_RATE_HZ = 800.0

# ---------------------------------------------------------------------------------------------
# Field tables (UM001 Sec. 4.3.6, "Binary Output Payload Length In Bytes"; VN-100 has groups 1, 2,
# 3 and 5). Index = bit offset inside the group's field word. Group 1 carries all 15 fields of the
# common group (some are "reserved" on the VN-100 but have fixed sizes shared with the VN-200/300).
# ---------------------------------------------------------------------------------------------
FIELD_SIZES: Dict[int, Tuple[int, ...]] = {
    1: (8, 8, 8, 12, 16, 12, 24, 12, 12, 24, 20, 28, 2, 4, 8),
    2: (8, 8, 8, 2, 8, 8, 8, 4, 4, 1),
    3: (2, 12, 12, 12, 4, 4, 16, 12, 12, 12, 12, 2),
    5: (2, 12, 16, 36, 12, 12, 12, 12, 12),
}

# Group 1 field bits.
TIME_STARTUP = 1 << 0
TIME_GPS = 1 << 1
TIME_SYNC_IN = 1 << 2
YAW_PITCH_ROLL = 1 << 3
QUATERNION = 1 << 4
ANGULAR_RATE = 1 << 5
POSITION = 1 << 6
VELOCITY = 1 << 7
ACCEL = 1 << 8
IMU = 1 << 9
MAG_PRES = 1 << 10
DELTA_THETA = 1 << 11
INS_STATUS = 1 << 12
SYNC_IN_CNT = 1 << 13
TIME_GPS_PPS = 1 << 14

#: The group-1 fields the driver asks for (0x0131, as in ``$VNWRG,75,1,4,01,0131``).
DEFAULT_GROUP1_FIELDS = TIME_STARTUP | QUATERNION | ANGULAR_RATE | ACCEL

# (group, bit) -> (sample attribute, struct format) for the fields decoded into Vn100Sample. Group 1
# has precedence when the same quantity is also selected in another group.
_DECODED: Dict[Tuple[int, int], Tuple[str, str]] = {
    (1, 0): ("time_startup_ns", "Q"),
    (1, 4): ("quaternion_xyzw", "4f"),
    (1, 5): ("angular_rate", "3f"),
    (1, 8): ("acceleration", "3f"),
    (2, 0): ("time_startup_ns", "Q"),
    (3, 9): ("acceleration", "3f"),
    (3, 10): ("angular_rate", "3f"),
    (5, 2): ("quaternion_xyzw", "4f"),
}
_SAMPLE_FIELDS = ("time_startup_ns", "quaternion_xyzw", "angular_rate", "acceleration")
_MAX_PACKET = 1 + 1 + 2 * len(FIELD_SIZES) + sum(sum(s) for s in FIELD_SIZES.values()) + 2


class ProtocolError(ValueError):
    """A malformed VN-100 message or an invalid command argument."""


def crc16(data: bytes) -> int:
    """CRC16-CCITT (XMODEM, initial value 0) as used by the VN-100 (UM001 Sec. 3.9.3, 4.3.5)."""
    return binascii.crc_hqx(data, 0)


def xor_checksum(body: bytes) -> int:
    """8-bit XOR of ``body`` (the bytes between ``$`` and ``*``), UM001 Sec. 3.9.2."""
    value = 0
    for byte in body:
        value ^= byte
    return value


@dataclass(frozen=True)
class Vn100Sample:
    """One decoded binary output packet, in the sensor's own conventions (see module docstring).

    Fields not selected in the packet are ``None``. ``quaternion_xyzw``: attitude of the FRD body
    relative to NED, scalar last. ``angular_rate``: rad/s, FRD. ``acceleration``: specific force in
    m/s^2, FRD (about (0, 0, -9.81) when level and at rest). ``time_startup_ns``: sensor clock.
    """

    time_startup_ns: Optional[int] = None
    quaternion_xyzw: Optional[Tuple[float, float, float, float]] = None
    angular_rate: Optional[Tuple[float, float, float]] = None
    acceleration: Optional[Tuple[float, float, float]] = None


GroupsFields = Mapping[int, int]


def _normalise_groups_fields(fields: Union[int, GroupsFields]) -> Dict[int, int]:
    if isinstance(fields, int):
        fields = {1: fields}
    result: Dict[int, int] = {}
    for group, mask in sorted(fields.items()):
        if group not in FIELD_SIZES:
            raise ProtocolError("binary output group %r is not supported (known: %s)"
                                % (group, sorted(FIELD_SIZES)))
        known = (1 << len(FIELD_SIZES[group])) - 1
        if not isinstance(mask, int) or mask <= 0 or mask & ~known:
            raise ProtocolError("field mask %r is empty or selects unknown fields of group %d"
                                % (mask, group))
        result[group] = mask
    if not result:
        raise ProtocolError("at least one binary output group must be selected")
    return result


class _Layout:
    """Decoding recipe for one header (group byte + field words)."""

    __slots__ = ("header", "length", "struct", "names")

    def __init__(self, groups_fields: Dict[int, int]) -> None:
        group_byte = 0
        words = b""
        fmt = "<"
        names: List[Optional[str]] = []
        payload = 0
        for group, mask in sorted(groups_fields.items()):
            group_byte |= 1 << (group - 1)
            words += struct.pack("<H", mask)
            for bit, size in enumerate(FIELD_SIZES[group]):
                if not mask & (1 << bit):
                    continue
                payload += size
                decoded = _DECODED.get((group, bit))
                if decoded is not None and decoded[0] not in names:
                    fmt += decoded[1]
                    names.append(decoded[0])
                else:
                    fmt += "%dx" % size
        self.header = bytes((SYNC, group_byte)) + words
        self.length = len(self.header) + payload + 2
        self.struct = struct.Struct(fmt)
        self.names = tuple(n for n in names if n is not None)

    def decode(self, packet: bytes) -> Vn100Sample:
        values = self.struct.unpack_from(packet, len(self.header))
        kwargs = {}
        index = 0
        for name in self.names:
            if name == "time_startup_ns":
                kwargs[name] = values[index]
                index += 1
            else:
                width = 4 if name == "quaternion_xyzw" else 3
                kwargs[name] = tuple(values[index:index + width])
                index += width
        return Vn100Sample(**kwargs)


def encode_binary_packet(sample: Vn100Sample, fields: Union[int, GroupsFields]) -> bytes:
    """Build a binary output packet carrying ``sample`` (used by the fake device and the tests).

    ``fields``: a group-1 field mask, or a mapping ``{group: field mask}``. Fields the sample can
    carry must be present in it (``ValueError`` otherwise); fields it cannot carry (YawPitchRoll,
    MagPres, ...) are zero-filled.
    """
    layout = _Layout(_normalise_groups_fields(fields))
    values: List[Union[int, float]] = []
    for name in layout.names:
        value = getattr(sample, name)
        if value is None:
            raise ProtocolError("field %s is selected but the sample has no value for it" % name)
        if name == "time_startup_ns":
            if not 0 <= int(value) < 1 << 64:
                raise ProtocolError("time_startup_ns %r does not fit a u64" % (value,))
            values.append(int(value))
        else:
            values.extend(float(v) for v in value)
    try:  # pad bytes ('x') of the payload struct pack as zeros
        body = layout.header + layout.struct.pack(*values)
    except (struct.error, OverflowError) as exc:
        raise ProtocolError("sample value does not fit the packet: %s" % exc)
    return body + struct.pack(">H", crc16(body[1:]))


class BinaryPacketParser:
    """Streaming parser of a VN-100 serial byte stream (binary packets plus ASCII reply lines).

    ``feed(data)`` returns the samples of every complete, CRC-valid binary packet in the stream so
    far; partial packets are kept until the rest arrives. After a bad CRC only the sync byte is
    dropped and the search for the next 0xFA restarts inside the rejected bytes, so a false sync
    never hides a real packet. ``$...\\n`` lines (command replies interleaved with binary output)
    are collected in :meth:`pop_ascii_lines` instead of being discarded.

    ``groups_fields``: optional expected configuration ``{group: field mask}`` (or a group-1 mask).
    When given, headers that differ from it are treated like unsupported ones; this keeps a
    corrupted byte that looks like a sync byte from claiming a long packet and delaying real ones.

    Counters: ``packets`` (good packets), ``crc_errors``, ``unsupported_packets`` (sync bytes
    followed by a header this parser cannot size or that is not the expected one), ``resync_bytes``
    (bytes discarded: garbage, bad packets' sync bytes, overlong or non-ASCII lines),
    ``ascii_lines``, ``overflow_bytes`` (bytes dropped because the buffer bound was hit). The parser
    never raises on any input.
    """

    MAX_ASCII_LINE = 256

    def __init__(self, groups_fields: Optional[Union[int, GroupsFields]] = None,
                 max_buffer: int = 4096, max_ascii_lines: int = 64) -> None:
        self._expected: Optional[bytes] = None
        if groups_fields is not None:
            self._expected = _Layout(_normalise_groups_fields(groups_fields)).header
        if max_buffer < _MAX_PACKET:
            raise ValueError("max_buffer must hold the longest packet (%d bytes)" % _MAX_PACKET)
        self._max_buffer = max_buffer
        self._max_ascii_lines = max_ascii_lines
        self._buffer = bytearray()
        self._layouts: Dict[bytes, Optional[_Layout]] = {}
        self._lines: List[bytes] = []
        self.packets = 0
        self.crc_errors = 0
        self.unsupported_packets = 0
        self.resync_bytes = 0
        self.ascii_lines = 0
        self.overflow_bytes = 0

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a packet or line."""
        return len(self._buffer)

    def counters(self) -> Dict[str, int]:
        """All counters, for diagnostics."""
        return {"packets": self.packets, "crc_errors": self.crc_errors,
                "unsupported_packets": self.unsupported_packets,
                "resync_bytes": self.resync_bytes, "ascii_lines": self.ascii_lines,
                "overflow_bytes": self.overflow_bytes}

    def reset(self) -> None:
        """Forget buffered bytes and lines (after a reconnect); counters are kept."""
        self._buffer = bytearray()
        self._lines = []

    def pop_ascii_lines(self) -> List[bytes]:
        """ASCII lines (``$...`` up to and including ``\\n``) seen since the last call."""
        lines, self._lines = self._lines, []
        return lines

    def _layout_for(self, buf: bytearray, start: int) -> Tuple[int, Optional[_Layout]]:
        """(status, layout): status 0 = need more bytes, 1 = layout found, -1 = unsupported."""
        end = len(buf)
        if start + 2 > end:
            return 0, None
        group_byte = buf[start + 1]
        if group_byte == 0 or group_byte & 0x80:
            return -1, None
        groups = [g for g in range(1, 8) if group_byte & (1 << (g - 1))]
        header_end = start + 2 + 2 * len(groups)
        if header_end > end:
            return 0, None
        header = bytes(buf[start:header_end])
        if self._expected is not None and header != self._expected:
            return -1, None
        layout = self._layouts.get(header, _MISSING)
        if layout is _MISSING:
            layout = None
            try:
                masks = struct.unpack_from("<%dH" % len(groups), header, 2)
                layout = _Layout(_normalise_groups_fields(dict(zip(groups, masks))))
            except (ProtocolError, struct.error):
                layout = None
            if len(self._layouts) < 256:
                self._layouts[header] = layout
        if layout is None:
            return -1, None
        return 1, layout

    def feed(self, data: bytes) -> List[Vn100Sample]:
        """Add received bytes; return the samples of the packets completed by them."""
        samples: List[Vn100Sample] = []
        buf = self._buffer
        buf += data
        pos = 0
        end = len(buf)
        while pos < end:
            byte = buf[pos]
            if byte == SYNC:
                status, layout = self._layout_for(buf, pos)
                if status == 0:
                    break
                if status < 0:
                    self.unsupported_packets += 1
                    self.resync_bytes += 1
                    pos += 1
                    continue
                assert layout is not None
                stop = pos + layout.length
                if stop > end:
                    break
                if binascii.crc_hqx(bytes(buf[pos + 1:stop]), 0) != 0:
                    self.crc_errors += 1
                    self.resync_bytes += 1
                    pos += 1
                    continue
                samples.append(layout.decode(bytes(buf[pos:stop])))
                self.packets += 1
                pos = stop
            elif byte == ASCII_START:
                consumed = self._take_line(buf, pos, end)
                if consumed == 0:
                    break
                pos += consumed
            else:
                nxt = _next_start(buf, pos + 1, end)
                self.resync_bytes += nxt - pos
                pos = nxt
        del buf[:pos]
        if len(buf) > self._max_buffer:  # cannot happen with the default bounds; kept as a guard
            excess = len(buf) - self._max_buffer
            self.overflow_bytes += excess
            del buf[:excess]
        return samples

    def _take_line(self, buf: bytearray, pos: int, end: int) -> int:
        """Consume an ASCII line starting at ``pos``; 0 = incomplete (wait for more bytes)."""
        limit = min(end, pos + self.MAX_ASCII_LINE)
        index = pos + 1
        while index < limit:
            byte = buf[index]
            if byte == 0x0A:
                line = bytes(buf[pos:index + 1])
                self.ascii_lines += 1
                if len(self._lines) >= self._max_ascii_lines:
                    self._lines.pop(0)
                self._lines.append(line)
                return index + 1 - pos
            if byte == ASCII_START or not (0x20 <= byte < 0x7F or byte == 0x0D):
                # Not a line after all (binary garbage or a new start): drop up to that byte.
                self.resync_bytes += index - pos
                return index - pos
            index += 1
        if limit - pos >= self.MAX_ASCII_LINE:
            self.resync_bytes += limit - pos
            return limit - pos
        return 0


_MISSING = object()


def _next_start(buf: bytearray, start: int, end: int) -> int:
    """Index of the next 0xFA or '$' at or after ``start`` (``end`` if none)."""
    a = buf.find(b"\xfa", start, end)
    b = buf.find(b"$", start, end)
    if a < 0:
        return b if b >= 0 else end
    if b < 0:
        return a
    return a if a < b else b


# ---------------------------------------------------------------------------------------------
# ASCII commands and replies (UM001 Sec. 3.9, 4.2.3)
# ---------------------------------------------------------------------------------------------
ERROR_NAMES: Dict[int, str] = {
    0x01: "hard fault", 0x02: "serial buffer overflow", 0x03: "invalid checksum",
    0x04: "invalid command", 0x05: "not enough parameters", 0x06: "too many parameters",
    0x07: "invalid parameter", 0x08: "invalid register", 0x09: "unauthorized access",
    0x0A: "watchdog reset", 0x0B: "output buffer overflow", 0x0C: "insufficient baud rate",
    0xFF: "error buffer overflow",
}


@dataclass(frozen=True)
class AsciiResponse:
    """A parsed ``$VN...`` line: ``command`` e.g. ``"VNRRG"``, ``fields`` after it.

    ``register`` is the register number of a VNRRG/VNWRG reply (else ``None``); ``error_code`` is
    set for ``$VNERR`` (hex code, UM001 Sec. 3.8).
    """

    command: str
    fields: Tuple[str, ...]
    register: Optional[int] = None
    error_code: Optional[int] = None

    @property
    def is_error(self) -> bool:
        return self.error_code is not None

    @property
    def error_name(self) -> str:
        if self.error_code is None:
            return ""
        return ERROR_NAMES.get(self.error_code, "unknown error 0x%02X" % self.error_code)

    @property
    def values(self) -> Tuple[str, ...]:
        """Fields after the register number (for VNRRG/VNWRG), else all fields."""
        return self.fields[1:] if self.register is not None else self.fields


def _check_body(body: str) -> bytes:
    try:
        raw = body.encode("ascii")
    except UnicodeEncodeError:
        raise ProtocolError("command body must be ASCII: %r" % body)
    if not raw.startswith(b"VN") or any(c in raw for c in b"$*\r\n") \
            or any(not 0x20 <= c < 0x7F for c in raw):
        raise ProtocolError("command body must start with 'VN' and contain no '$', '*' or control "
                            "characters: %r" % body)
    return raw


def ascii_command(body: str) -> bytes:
    """``"VNRRG,11"`` -> ``b"$VNRRG,11*73\\r\\n"`` (8-bit XOR checksum, UM001 Sec. 3.9.2)."""
    raw = _check_body(body)
    return b"$" + raw + b"*%02X\r\n" % xor_checksum(raw)


def parse_ascii_response(line: bytes) -> AsciiResponse:
    """Parse and verify one ``$VN...*XX`` (XOR) or ``$VN...*XXXX`` (CRC16) line.

    Trailing ``\\r\\n`` is optional. Raises :class:`ProtocolError` on bad framing or checksum.
    """
    text = bytes(line).rstrip(b"\r\n")
    if not text.startswith(b"$VN"):
        raise ProtocolError("not a VectorNav ASCII message: %r" % (line,))
    star = text.rfind(b"*")
    if star < 0:
        raise ProtocolError("missing checksum: %r" % (line,))
    body, check = text[1:star], text[star + 1:]
    if any(not 0x20 <= c < 0x7F for c in body) or b"$" in body or b"*" in body:
        raise ProtocolError("invalid characters in message: %r" % (line,))
    try:
        value = int(check.decode("ascii"), 16)
    except (ValueError, UnicodeDecodeError):
        raise ProtocolError("malformed checksum %r in %r" % (check, line))
    if len(check) == 2:
        if value != xor_checksum(body):
            raise ProtocolError("checksum mismatch (got %02X, computed %02X) in %r"
                                % (value, xor_checksum(body), line))
    elif len(check) == 4:
        if value != crc16(body):
            raise ProtocolError("CRC mismatch (got %04X, computed %04X) in %r"
                                % (value, crc16(body), line))
    else:
        raise ProtocolError("checksum must have 2 or 4 hex digits: %r" % (line,))
    parts = body.decode("ascii").split(",")
    command, fields = parts[0], tuple(parts[1:])
    register: Optional[int] = None
    error: Optional[int] = None
    if command == "VNERR":
        if len(fields) != 1:
            raise ProtocolError("VNERR needs exactly one error code: %r" % (line,))
        try:
            error = int(fields[0], 16)
        except ValueError:
            raise ProtocolError("malformed error code in %r" % (line,))
    elif command in ("VNRRG", "VNWRG"):
        if not fields:
            raise ProtocolError("%s reply without a register number: %r" % (command, line))
        try:
            register = int(fields[0], 10)
        except ValueError:
            raise ProtocolError("malformed register number in %r" % (line,))
    return AsciiResponse(command=command, fields=fields, register=register, error_code=error)


def _check_register(register: int) -> int:
    if not isinstance(register, int) or not 0 <= register <= 255:
        raise ProtocolError("register must be an integer 0..255, got %r" % (register,))
    return register


def read_register_command(register: int) -> bytes:
    """``$VNRRG,<reg>`` (two digits, as in ``$VNRRG,01``)."""
    return ascii_command("VNRRG,%02d" % _check_register(register))


def write_register_command(register: int, values: Sequence[str]) -> bytes:
    """``$VNWRG,<reg>,<v1>,<v2>...`` with the values already formatted as strings."""
    body = "VNWRG,%02d" % _check_register(register)
    for value in values:
        body += "," + str(value)
    return ascii_command(body)


MODEL_REGISTER = 1
SERIAL_NUMBER_REGISTER = 3
BAUD_RATE_REGISTER = 5
ASYNC_OUTPUT_TYPE_REGISTER = 6
BINARY_OUTPUT_REGISTERS = (75, 76, 77)

#: Baud rates of the VN-100's serial port (UM001, Serial Baud Rate register 5).
BAUD_RATES = (9600, 19200, 38400, 57600, 115200, 128000, 230400, 460800, 921600)
#: The rate a factory-fresh VN-100 talks at (UM001, register 5 default).
FACTORY_BAUD = 115200


def read_model_command() -> bytes:
    """``$VNRRG,01``: model number register (e.g. ``VN-100T-CR``)."""
    return read_register_command(MODEL_REGISTER)


def read_serial_number_command() -> bytes:
    """``$VNRRG,03``: serial number register (a 32-bit number, e.g. ``0100012345``)."""
    return read_register_command(SERIAL_NUMBER_REGISTER)


def write_baud_rate_command(baud: int) -> bytes:
    """``$VNWRG,05,<baud>``: switch the port the command arrives on to ``baud`` (UM001, register 5). The
    sensor answers at the old rate, then changes; the new rate is lost at power-off unless written to flash
    (:func:`write_settings_command`)."""
    if baud not in BAUD_RATES:
        raise ProtocolError("not a VN-100 baud rate: %r (%s)" % (baud, ", ".join(str(b) for b in BAUD_RATES)))
    return write_register_command(BAUD_RATE_REGISTER, [str(int(baud))])


def write_settings_command() -> bytes:
    """``$VNWNV``: write the current register settings to the sensor's flash (they survive a power cycle)."""
    return ascii_command("VNWNV")


def disable_ascii_output_command() -> bytes:
    """``$VNWRG,06,0``: Async Data Output Type = off, so only binary packets stream."""
    return write_register_command(ASYNC_OUTPUT_TYPE_REGISTER, ["0"])


def async_pause_command() -> bytes:
    """``$VNASY,0``: pause asynchronous output (for a quiet configuration phase)."""
    return ascii_command("VNASY,0")


def async_resume_command() -> bytes:
    """``$VNASY,1``: resume asynchronous output."""
    return ascii_command("VNASY,1")


def rate_divisor_for(rate_hz: float) -> int:
    """Rate divisor for ``rate_hz`` = 800 Hz / divisor; ``ValueError`` unless it divides exactly."""
    if not isinstance(rate_hz, (int, float)) or not math.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError("rate_hz must be a positive finite number, got %r" % (rate_hz,))
    divisor = int(round(IMU_RATE_HZ / rate_hz))
    if divisor < 1 or abs(IMU_RATE_HZ / divisor - rate_hz) > 1e-9 * IMU_RATE_HZ:
        raise ValueError("rate_hz %r is not 800 Hz divided by an integer (e.g. 800, 400, 200, "
                         "100, 50)" % (rate_hz,))
    return divisor


def configure_binary_output_command(rate_divisor: int,
                                    group1_fields: int = DEFAULT_GROUP1_FIELDS,
                                    register: int = 75, async_mode: int = 1,
                                    groups_fields: Optional[GroupsFields] = None) -> bytes:
    """``$VNWRG,75,<AsyncMode>,<RateDivisor>,<groups hex>,<fields hex>...`` (UM001 Sec. 4.2.3).

    Default: group 1 TimeStartup|Quaternion|AngularRate|Accel (0x0131) on serial port 1.
    ``groups_fields`` (``{group: mask}``) replaces ``group1_fields`` for multi-group messages.
    """
    if register not in BINARY_OUTPUT_REGISTERS:
        raise ProtocolError("binary output registers are 75, 76, 77; got %r" % (register,))
    if not isinstance(rate_divisor, int) or not 1 <= rate_divisor <= 0xFFFF:
        raise ProtocolError("rate divisor must be an integer 1..65535, got %r" % (rate_divisor,))
    if async_mode not in (0, 1, 2, 3):
        raise ProtocolError("async mode must be 0..3, got %r" % (async_mode,))
    selection = _normalise_groups_fields(groups_fields if groups_fields is not None
                                         else group1_fields)
    group_byte = 0
    for group in selection:
        group_byte |= 1 << (group - 1)
    values = [str(async_mode), str(rate_divisor), "%02X" % group_byte]
    values += ["%04X" % selection[g] for g in sorted(selection)]
    return write_register_command(register, values)


def parse_binary_output_config(values: Sequence[str]) -> Tuple[int, int, Dict[int, int]]:
    """Inverse of :func:`configure_binary_output_command` for the register values of a VNWRG/VNRRG
    75-77 reply: ``(async_mode, rate_divisor, {group: mask})``; ``ProtocolError`` if malformed."""
    try:
        async_mode = int(values[0], 10)
        divisor = int(values[1], 10)
        group_byte = int(values[2], 16)
        groups = [g for g in range(1, 8) if group_byte & (1 << (g - 1))]
        masks = [int(v, 16) for v in values[3:]]
    except (IndexError, ValueError):
        raise ProtocolError("malformed binary output register values: %r" % (list(values),))
    if len(masks) != len(groups) or group_byte & 0x80:
        raise ProtocolError("group byte and field words disagree: %r" % (list(values),))
    return async_mode, divisor, dict(zip(groups, masks))
