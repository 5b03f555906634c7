"""VN-100 parser throughput on a 200 Hz stream (figures, not a test).

Run: .venv/bin/python benchmarks/bench_vn100.py

Measures BinaryPacketParser.feed on one minute of a 200 Hz stream (12000 packets of 54 bytes) fed
in chunks typical of a serial read (one packet, 64 B, 4096 B), a clean and a corrupted stream (5 %
of packets with a flipped byte), plus vn_to_ros per sample, and reports packets/s, us/packet and the
CPU share a 200 Hz stream costs.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from quadruped_drivers.vn100 import protocol as vp  # noqa: E402
from quadruped_drivers.vn100.conversions import vn_to_ros  # noqa: E402

RATE_HZ = 200
SECONDS = 60
N = RATE_HZ * SECONDS


def make_stream(corrupt_fraction: float, seed: int = 1) -> bytes:
    rng = np.random.default_rng(seed)
    chunks = []
    for i in range(N):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        sample = vp.Vn100Sample(i * 5_000_000, tuple(q), tuple(rng.normal(size=3)),
                                tuple(rng.normal(size=3)))
        packet = bytearray(vp.encode_binary_packet(sample, vp.DEFAULT_GROUP1_FIELDS))
        if rng.random() < corrupt_fraction:
            packet[int(rng.integers(1, len(packet)))] ^= 0x55
        chunks.append(bytes(packet))
    return b"".join(chunks)


def bench_parser(data: bytes, chunk: int, expected_fields) -> tuple:
    best = float("inf")
    packets = 0
    for _ in range(3):
        parser = vp.BinaryPacketParser(groups_fields=expected_fields)
        start = time.perf_counter()
        for offset in range(0, len(data), chunk):
            parser.feed(data[offset:offset + chunk])
        best = min(best, time.perf_counter() - start)
        packets = parser.packets
    return best, packets


def main() -> None:
    print("VN-100 binary parser, %d packets (%d s at %d Hz), %d-byte packets"
          % (N, SECONDS, RATE_HZ, len(vp.encode_binary_packet(
              vp.Vn100Sample(0, (0, 0, 0, 1), (0, 0, 0), (0, 0, 0)),
              vp.DEFAULT_GROUP1_FIELDS))))
    print("%-42s %12s %12s %14s" % ("case", "packets/s", "us/packet", "CPU @200 Hz"))
    for label, corrupt in (("clean", 0.0), ("5% corrupted", 0.05)):
        data = make_stream(corrupt)
        for chunk in (54, 64, 4096):
            for expected in (None, vp.DEFAULT_GROUP1_FIELDS):
                seconds, packets = bench_parser(data, chunk, expected)
                per_packet = seconds / N
                print("%-42s %12.0f %12.2f %13.3f%%"
                      % ("%s, %d B reads, %s" % (label, chunk,
                                                  "expected hdr" if expected else "any hdr"),
                         N / seconds, per_packet * 1e6, per_packet * RATE_HZ * 100.0))
            assert packets <= N
    parser = vp.BinaryPacketParser()
    samples = parser.feed(make_stream(0.0)[:54 * 2000])
    start = time.perf_counter()
    for s in samples:
        vn_to_ros(s.quaternion_xyzw, s.angular_rate, s.acceleration)
    per = (time.perf_counter() - start) / len(samples)
    print("%-42s %12.0f %12.2f %13.3f%%" % ("vn_to_ros per sample", 1.0 / per, per * 1e6,
                                            per * RATE_HZ * 100.0))


if __name__ == "__main__":
    main()
