"""Fuzzing the VN-100 input path: mutated byte streams through the parser and the sample gate (no ROS).

:func:`run` builds ``packets`` binary output packets from plausible random samples, mutates most of
them and feeds the stream in random chunks (as serial reads deliver it) through the code the node runs
on every read: :class:`~quadruped_drivers.vn100.protocol.BinaryPacketParser` then
:class:`~quadruped_drivers.vn100.sample_gate.SampleGate`. Mutations:

* ``bitflip`` (1-3 bits), ``overwrite`` (1-4 bytes), ``truncate``, ``insert`` (garbage bytes),
  ``ascii`` (a ``$VN`` line or a broken one inside the stream): mostly caught by framing and the CRC;
* ``collide``: a packet whose fields are replaced by random bit patterns (any float32, NaN, inf, any
  u64 time stamp) and whose CRC is recomputed, i.e. the 1-in-65,536 corrupted packet that passes the
  CRC; ``extreme``: the same with chosen values (3.4e38 and 1e3 rad/s, 1e19 ns, NaN, a non-unit
  quaternion, 20 g);
* ``clean``: unchanged.

It counts what must never happen: exceptions out of the path (``crashes``), a chunk that takes longer
than ``hang_s`` (``hangs``), non-finite published values (``nan_outputs``), published samples outside
the gate's limits (``implausible_published``), dating offsets outside ``[0, max_backdate]``.
"""
from __future__ import annotations

import math
import random
import struct
import time
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.conversions import SensorLimits
from quadruped_drivers.vn100.sample_gate import DROP_REASONS, SampleGate

MUTATIONS = ("clean", "bitflip", "overwrite", "truncate", "insert", "ascii", "collide", "extreme")
_EXTREMES = (3.4e38, -3.4e38, 1e3, 1e6, float("nan"), float("inf"), 200.0)


def _plausible_sample(rng: random.Random, time_ns: int) -> vp.Vn100Sample:
    q = np.array([rng.gauss(0, 1) for _ in range(4)])
    q /= np.linalg.norm(q)
    rate = tuple(rng.uniform(-5.0, 5.0) for _ in range(3))
    accel = tuple(rng.uniform(-20.0, 20.0) for _ in range(3))
    return vp.Vn100Sample(time_ns, tuple(float(v) for v in q), rate, accel)


def _with_crc(body: bytes) -> bytes:
    return body + struct.pack(">H", vp.crc16(body[1:]))


def _collide(rng: random.Random, packet: bytes, header: int) -> bytes:
    """Random bit patterns in the payload, CRC recomputed (a corruption the CRC cannot see)."""
    payload = bytearray(packet[header:-2])
    for index in range(len(payload)):
        if rng.random() < 0.3:
            payload[index] = rng.randrange(256)
    return _with_crc(packet[:header] + bytes(payload))


def _extreme(rng: random.Random, sample: vp.Vn100Sample, fields: int) -> bytes:
    time_ns = sample.time_startup_ns or 0
    quaternion = list(sample.quaternion_xyzw or (0.0, 0.0, 0.0, 1.0))
    rate = list(sample.angular_rate or (0.0, 0.0, 0.0))
    accel = list(sample.acceleration or (0.0, 0.0, 0.0))
    choice = rng.randrange(5)
    if choice == 0:
        time_ns = rng.choice([10 ** 19, (1 << 64) - 1, 0])
    elif choice == 1:
        rate[rng.randrange(3)] = rng.choice(_EXTREMES)
    elif choice == 2:
        accel[rng.randrange(3)] = rng.choice(_EXTREMES)
    elif choice == 3:
        quaternion = [v * rng.choice([1.01, 0.5, 2.0, 0.0]) for v in quaternion]
    else:
        quaternion[rng.randrange(4)] = rng.choice([float("nan"), float("inf")])
    body = struct.pack("<BBH", vp.SYNC, 1, fields) + struct.pack("<Q4f3f3f", time_ns, *quaternion, *rate, *accel)
    return _with_crc(body)


def mutate(rng: random.Random, sample: vp.Vn100Sample,
           fields: int = vp.DEFAULT_GROUP1_FIELDS) -> Tuple[str, bytes]:
    """(mutation kind, bytes) for one packet carrying ``sample``."""
    packet = vp.encode_binary_packet(sample, fields)
    kind = rng.choice(MUTATIONS)
    data = bytearray(packet)
    if kind == "bitflip":
        for _ in range(rng.randint(1, 3)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif kind == "overwrite":
        for _ in range(rng.randint(1, 4)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    elif kind == "truncate":
        del data[rng.randrange(1, len(data)):]
    elif kind == "insert":
        at = rng.randrange(len(data))
        data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 20)))
    elif kind == "ascii":
        line = rng.choice([b"$VNERR,0A*7E\r\n", b"$VNRRG,01,VN-100T-CR*5C\r\n", b"$VN\xfa\xfa garbage",
                           b"$" + bytes(rng.randrange(256) for _ in range(40))])
        at = rng.randrange(len(data))
        data[at:at] = line
    elif kind == "collide":
        data = bytearray(_collide(rng, packet, 4))
    elif kind == "extreme":
        data = bytearray(_extreme(rng, sample, fields))
    return kind, bytes(data)


def run(packets: int, seed: int = 0, limits: SensorLimits = SensorLimits(), max_backdate: float = 0.1,
        hang_s: float = 1.0, clock: Callable[[], float] = time.perf_counter,
        progress: Optional[Callable[[int], None]] = None) -> Dict[str, int]:
    """Fuzz the VN-100 path with ``packets`` packets; returns the counters (module docstring)."""
    rng = random.Random(seed)
    parser = vp.BinaryPacketParser(groups_fields={1: vp.DEFAULT_GROUP1_FIELDS})
    gate = SampleGate(limits, max_backdate=max_backdate)
    stats: Dict[str, int] = {"packets": 0, "crashes": 0, "hangs": 0, "nan_outputs": 0,
                             "implausible_published": 0, "bad_offsets": 0, "published": 0, "decoded": 0}
    for kind in MUTATIONS:
        stats["mutation " + kind] = 0
    pending = bytearray()
    time_ns = 1_000_000_000
    for index in range(packets):
        time_ns += 5_000_000
        kind, data = mutate(rng, _plausible_sample(rng, time_ns))
        stats["mutation " + kind] += 1
        stats["packets"] += 1
        pending += data
        if rng.random() < 0.5 and index + 1 < packets:
            continue  # let a read carry several packets, split anywhere
        while pending:
            size = rng.randint(1, 300)
            chunk, pending = bytes(pending[:size]), pending[size:]
            _feed(parser, gate, chunk, stats, limits, max_backdate, hang_s, clock)
        if progress is not None:
            progress(index + 1)
    stats.update({("dropped " if reason in DROP_REASONS else "") + reason: count
                  for reason, count in gate.counts.items()})
    stats.update({"parser " + name: count for name, count in parser.counters().items()})
    return stats


def _feed(parser: vp.BinaryPacketParser, gate: SampleGate, chunk: bytes, stats: Dict[str, int],
          limits: SensorLimits, max_backdate: float, hang_s: float, clock: Callable[[], float]) -> None:
    started = clock()
    try:
        samples = parser.feed(chunk)
        stats["decoded"] += len(samples)
        out = gate.process(samples)
    except Exception:  # noqa: BLE001 - the campaign counts what would have killed the reader
        stats["crashes"] += 1
        return
    if clock() - started > hang_s:
        stats["hangs"] += 1
    for reading, offset in out:
        stats["published"] += 1
        values: List[float] = list(reading.orientation_xyzw) + list(reading.angular_velocity) + list(
            reading.linear_acceleration)
        if not all(math.isfinite(v) for v in values) or not math.isfinite(offset):
            stats["nan_outputs"] += 1
            continue
        if (np.any(np.abs(reading.angular_velocity) > limits.max_angular_rate)
                or np.any(np.abs(reading.linear_acceleration) > limits.max_acceleration)
                or abs(float(np.linalg.norm(reading.orientation_xyzw)) - 1.0) > 1e-6):
            stats["implausible_published"] += 1
        if not 0.0 <= offset <= max_backdate:
            stats["bad_offsets"] += 1


__all__ = ["MUTATIONS", "mutate", "run"]
