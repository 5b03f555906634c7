"""VN-100 protocol: CRC/checksums, ASCII commands and replies, streaming binary packet parser."""
from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.protocol import BinaryPacketParser, Vn100Sample

# UM001 Sec. 4.3.7, example cases 1 (group 1 YawPitchRoll) and 2 (group 1 YPR + group 3 Temp).
MANUAL_EXAMPLE_1 = bytes.fromhex("FA0108009350" "2E42833EF13F48B504BB9288")
MANUAL_EXAMPLE_2 = bytes.fromhex("FA0508001000A41502424DDFEB3FF61A36BEBF2DA441AF1A")

FULL = vp.DEFAULT_GROUP1_FIELDS


def sample(i: int = 0) -> Vn100Sample:
    return Vn100Sample(time_startup_ns=1_000_000 + 5_000_000 * i,
                       quaternion_xyzw=(0.0, 0.0, 0.5, 0.75),
                       angular_rate=(0.125, -0.25, 0.5 + i),
                       acceleration=(0.5, -0.25, -9.75))


def stream(n: int) -> bytes:
    return b"".join(vp.encode_binary_packet(sample(i), FULL) for i in range(n))


# ------------------------------------------------------------------ checksums
def test_crc_of_manual_examples_checks_to_zero():
    assert vp.crc16(MANUAL_EXAMPLE_1[1:]) == 0
    assert vp.crc16(MANUAL_EXAMPLE_2[1:]) == 0
    assert vp.crc16(MANUAL_EXAMPLE_1[1:-2]) == 0x9288


def test_xor_checksum_matches_design_example():
    assert vp.xor_checksum(b"VNRRG,11") == 0x73
    assert vp.ascii_command("VNRRG,11") == b"$VNRRG,11*73\r\n"


# ------------------------------------------------------------------ ASCII commands
def test_command_builders_exact_bytes():
    assert vp.read_model_command() == b"$VNRRG,01*72\r\n"
    assert vp.read_serial_number_command() == b"$VNRRG,03*70\r\n"
    assert vp.read_register_command(75).startswith(b"$VNRRG,75*")
    assert vp.async_pause_command() == vp.ascii_command("VNASY,0")
    assert vp.async_resume_command() == vp.ascii_command("VNASY,1")
    assert vp.disable_ascii_output_command() == vp.ascii_command("VNWRG,06,0")
    # UM001 Sec. 4.2.4 layout: register, async mode, divisor, group byte, field word (hex).
    assert vp.configure_binary_output_command(4) == vp.ascii_command("VNWRG,75,1,4,01,0131")
    assert vp.configure_binary_output_command(16, 0x0029, async_mode=2) == \
        vp.ascii_command("VNWRG,75,2,16,01,0029")
    assert vp.configure_binary_output_command(16, groups_fields={1: 1, 3: 0x0C, 5: 0x14}) == \
        vp.ascii_command("VNWRG,75,1,16,15,0001,000C,0014")


@pytest.mark.parametrize("kwargs", [
    dict(rate_divisor=0), dict(rate_divisor=70000), dict(rate_divisor=4, register=74),
    dict(rate_divisor=4, async_mode=4), dict(rate_divisor=4, group1_fields=0),
    dict(rate_divisor=4, group1_fields=0x8000), dict(rate_divisor=4, groups_fields={4: 1}),
])
def test_configure_command_rejects_bad_arguments(kwargs):
    with pytest.raises(ValueError):
        vp.configure_binary_output_command(**kwargs)


@pytest.mark.parametrize("body", ["RRG,01", "VNRRG*01", "VN$RRG", "VNRRG,\r", "VNRRG,é"])
def test_ascii_command_rejects_bad_bodies(body):
    with pytest.raises(vp.ProtocolError):
        vp.ascii_command(body)


def test_parse_ascii_response_fields_and_register():
    reply = vp.parse_ascii_response(vp.ascii_command("VNRRG,01,VN-100T-CR"))
    assert reply.command == "VNRRG" and reply.register == 1
    assert reply.values == ("VN-100T-CR",) and not reply.is_error
    crc_line = b"$VNASY,1*%04X\r\n" % vp.crc16(b"VNASY,1")
    assert vp.parse_ascii_response(crc_line).fields == ("1",)


def test_parse_ascii_error_reply_hex_code():
    reply = vp.parse_ascii_response(vp.ascii_command("VNERR,0C"))
    assert reply.is_error and reply.error_code == 0x0C
    assert reply.error_name == "insufficient baud rate"


@pytest.mark.parametrize("line", [
    b"$VNRRG,11*74\r\n", b"$VNRRG,11*0000\r\n", b"$VNRRG,11\r\n", b"VNRRG,11*73", b"$VNRRG,11*7",
    b"$VNRRG,11*ZZ", b"$VNERR*%02X" % vp.xor_checksum(b"VNERR"),
    b"$VNRRG,xx*%02X" % vp.xor_checksum(b"VNRRG,xx"),
])
def test_parse_ascii_rejects_bad_lines(line):
    with pytest.raises(vp.ProtocolError):
        vp.parse_ascii_response(line)


@given(st.binary(max_size=80))
def test_parse_ascii_random_bytes_only_protocol_errors(data):
    try:
        vp.parse_ascii_response(b"$VN" + data)
    except vp.ProtocolError:
        pass


def test_rate_divisor():
    assert vp.rate_divisor_for(200) == 4
    assert vp.rate_divisor_for(800.0) == 1
    assert vp.rate_divisor_for(1) == 800
    for bad in (300.0, 0.0, -200.0, float("nan"), float("inf"), 1600.0, 7.0):
        with pytest.raises(ValueError):
            vp.rate_divisor_for(bad)


def test_parse_binary_output_config_round_trip_and_errors():
    command = vp.configure_binary_output_command(16, groups_fields={1: 1, 3: 0x0C})
    reply = vp.parse_ascii_response(command)
    assert vp.parse_binary_output_config(reply.values) == (1, 16, {1: 1, 3: 0x0C})
    for values in (["1"], ["1", "4", "03", "0131"], ["a", "4", "01", "0131"]):
        with pytest.raises(vp.ProtocolError):
            vp.parse_binary_output_config(values)


# ------------------------------------------------------------------ binary packets
def test_manual_example_packets_parse():
    parser = BinaryPacketParser()
    out = parser.feed(MANUAL_EXAMPLE_1 + MANUAL_EXAMPLE_2)
    assert out == [Vn100Sample(), Vn100Sample()]  # YPR / Temp are sized but not decoded
    assert parser.packets == 2 and parser.crc_errors == 0 and parser.resync_bytes == 0


def test_encode_layout_is_little_endian_with_big_endian_crc():
    packet = vp.encode_binary_packet(sample(), FULL)
    assert packet[:4] == b"\xfa\x01\x31\x01"
    assert len(packet) == 4 + 8 + 16 + 12 + 12 + 2
    assert struct.unpack_from("<Q", packet, 4)[0] == sample().time_startup_ns
    assert struct.unpack(">H", packet[-2:])[0] == vp.crc16(packet[1:-2])
    assert vp.crc16(packet[1:]) == 0


def test_encode_rejects_missing_or_unrepresentable_values():
    with pytest.raises(ValueError):
        vp.encode_binary_packet(Vn100Sample(time_startup_ns=1), FULL)
    with pytest.raises(ValueError):
        vp.encode_binary_packet(Vn100Sample(1, (0.0, 0.0, 0.0, 1.0), (1e39, 0.0, 0.0),
                                            (0.0, 0.0, 0.0)), FULL)
    with pytest.raises(ValueError):
        vp.encode_binary_packet(sample(), {4: 1})


def test_other_groups_are_decoded_when_sized():
    fields = {2: 0x0001, 3: (1 << 9) | (1 << 10) | (1 << 4), 5: (1 << 2) | (1 << 1)}
    packet = vp.encode_binary_packet(sample(3), fields)
    parser = BinaryPacketParser()
    assert parser.feed(packet) == [sample(3)]


def test_group_one_takes_precedence_over_duplicates():
    packet = vp.encode_binary_packet(sample(1), {1: FULL, 3: 1 << 9})
    assert BinaryPacketParser().feed(packet) == [sample(1)]


floats = st.floats(allow_nan=False, width=32)


@st.composite
def samples_and_fields(draw):
    bits = draw(st.lists(st.sampled_from([vp.TIME_STARTUP, vp.QUATERNION, vp.ANGULAR_RATE,
                                          vp.ACCEL, vp.YAW_PITCH_ROLL, vp.MAG_PRES,
                                          vp.INS_STATUS]), min_size=1, unique=True))
    fields = 0
    for bit in bits:
        fields |= bit
    s = Vn100Sample(
        time_startup_ns=draw(st.integers(0, 2 ** 64 - 1)) if fields & vp.TIME_STARTUP else None,
        quaternion_xyzw=tuple(draw(st.tuples(floats, floats, floats, floats)))
        if fields & vp.QUATERNION else None,
        angular_rate=tuple(draw(st.tuples(floats, floats, floats)))
        if fields & vp.ANGULAR_RATE else None,
        acceleration=tuple(draw(st.tuples(floats, floats, floats)))
        if fields & vp.ACCEL else None)
    return s, fields


@given(samples_and_fields())
def test_encode_decode_round_trip(case):
    s, fields = case
    assert BinaryPacketParser().feed(vp.encode_binary_packet(s, fields)) == [s]


@given(st.lists(st.integers(0, 40 * 50), max_size=12))
def test_split_stream_gives_same_samples(cuts):
    data = stream(40)
    parser = BinaryPacketParser()
    out = []
    last = 0
    for cut in sorted(cuts) + [len(data)]:
        out.extend(parser.feed(data[last:cut]))
        last = max(last, cut)
    assert out == [sample(i) for i in range(40)]
    assert parser.buffered == 0 and parser.resync_bytes == 0


@settings(max_examples=300)
@given(st.binary(max_size=2000), st.sampled_from([None, FULL]))
def test_random_bytes_never_raise_and_buffer_is_bounded(data, expected):
    parser = BinaryPacketParser(groups_fields=expected)
    for start in range(0, len(data), 97):
        parser.feed(data[start:start + 97])
        assert parser.buffered <= 4096
    assert parser.packets + parser.crc_errors + parser.unsupported_packets <= data.count(0xFA)


@settings(max_examples=300)
@given(st.lists(st.tuples(st.integers(0, 10 * 50 - 1), st.integers(1, 255)), min_size=1,
                max_size=6),
       st.binary(max_size=30))
def test_mutated_stream_never_raises_and_unmutated_packets_survive(flips, junk):
    packets = [vp.encode_binary_packet(sample(i), FULL) for i in range(10)]
    data = bytearray(b"".join(packets))
    touched = set()
    for index, mask in flips:
        data[index] ^= mask
        touched.add(index // len(packets[0]))
    parser = BinaryPacketParser(groups_fields=FULL)
    out = parser.feed(junk) + parser.feed(bytes(data))
    good = [sample(i) for i in range(10) if i not in touched]
    # Every untouched packet is recovered (a false sync can never hide one: resync is bytewise).
    assert all(g in out for g in good)
    assert parser.packets == len(out)


def test_corrupted_packet_counted_and_skipped():
    packets = [vp.encode_binary_packet(sample(i), FULL) for i in range(3)]
    bad = bytearray(packets[1])
    bad[10] ^= 0x40
    parser = BinaryPacketParser()
    out = parser.feed(packets[0] + bytes(bad) + packets[2])
    assert out == [sample(0), sample(2)]
    assert parser.crc_errors == 1
    assert parser.resync_bytes == len(bad)


def test_garbage_counted_as_resync_bytes():
    parser = BinaryPacketParser()
    out = parser.feed(b"\x00\x01\x02garbage" + stream(2))
    assert out == [sample(0), sample(1)] and parser.resync_bytes == 10


def test_unsupported_group_and_unexpected_header_resync():
    unsupported = b"\xfa\x08\x01\x00" + bytes(30)  # group 4 (GPS) does not exist on a VN-100
    parser = BinaryPacketParser()
    assert parser.feed(unsupported + stream(1)) == [sample(0)]
    assert parser.unsupported_packets == 1
    strict = BinaryPacketParser(groups_fields=FULL)
    other = vp.encode_binary_packet(sample(), vp.TIME_STARTUP)
    assert strict.feed(other + stream(1)) == [sample(0)]
    assert strict.unsupported_packets == 1 and strict.packets == 1


def test_extension_bits_are_unsupported():
    parser = BinaryPacketParser()
    parser.feed(b"\xfa\x81\x01\x00\x01\x00" + stream(1))
    parser.feed(b"\xfa\x01\x01\x80" + stream(1))
    assert parser.packets == 2 and parser.unsupported_packets == 2


def test_ascii_lines_interleaved_with_packets():
    reply = vp.ascii_command("VNWRG,75,1,4,01,0131")
    data = stream(1) + reply + stream(2)[len(stream(1)):]
    parser = BinaryPacketParser()
    out = []
    for i in range(0, len(data), 7):
        out += parser.feed(data[i:i + 7])
    assert out == [sample(0), sample(1)]
    assert parser.pop_ascii_lines() == [reply]
    assert parser.pop_ascii_lines() == [] and parser.resync_bytes == 0


def test_overlong_or_binary_ascii_lines_are_discarded():
    parser = BinaryPacketParser()
    parser.feed(b"$" + b"A" * 300 + stream(1))
    parser.feed(b"$VN\x01" + stream(1))
    assert parser.pop_ascii_lines() == []
    assert parser.packets == 2


def test_parser_rejects_too_small_buffer():
    with pytest.raises(ValueError):
        BinaryPacketParser(max_buffer=16)
