"""I2C bus budget of one 100 Hz control cycle (paper: the main node runs at 100 Hz).

One cycle = 12 servo feedback reads through the TCA9548A (incl. mux switching, each switch read back,
and one ADC's config register read back in turn) + one 12-channel PCA9685 update; the PCA9685's
MODE1/MODE2 check (every 0.1 s) is counted per cycle as its share. Bits on the wire are counted from the fake bus's transaction log (START, address +
ACK, 9 bits per data byte, repeated START, STOP; clock stretching and the Linux driver's gaps between
transactions are not included), converted to bus time at 100 kHz and 400 kHz and compared with the
target of 30 % of the 10 ms cycle at 400 kHz. Also measures the Python time per cycle against the fakes.

    .venv/bin/python benchmarks/bench_bus_budget.py
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_drivers.calibration import load_servo_calibration  # noqa: E402
from quadruped_drivers.hardware_config import load_hardware_config  # noqa: E402
from quadruped_drivers.i2c.fake_bus import bits_on_wire  # noqa: E402
from quadruped_drivers.i2c.fake_devices import build_fake_hardware  # noqa: E402
from quadruped_drivers.pwm_output import ServoPwmOutput  # noqa: E402
from quadruped_drivers.servo_feedback import ServoFeedbackArray  # noqa: E402

CYCLE_S = 0.01
TARGET_FRACTION = 0.30


def main() -> None:
    hw = load_hardware_config()
    cal = load_servo_calibration()
    fake = build_fake_hardware(hw)
    fake.set_joint_voltages(np.full(12, 1.7))
    feedback = ServoFeedbackArray(fake.bus, hw, cal)
    pwm = ServoPwmOutput(fake.bus, hw)
    pwm.start()
    feedback.start()
    pulses = cal.angles_to_pulses(np.radians([-140.0, -40.0, 90.0] * 4))
    feedback.read()
    pwm.command(pulses)

    fake.bus.clear_log()
    feedback.read()
    read_log = list(fake.bus.log)
    fake.bus.clear_log()
    pwm.command(pulses + 10.0)
    pwm_log = list(fake.bus.log)
    fake.bus.clear_log()
    pwm._check_mode()  # the periodic chip check, every mode_check_interval
    check_log = list(fake.bus.log)
    cycles_per_check = pwm.mode_check_interval / CYCLE_S
    read_bits, pwm_bits = bits_on_wire(read_log), bits_on_wire(pwm_log)
    check_bits = bits_on_wire(check_log) / cycles_per_check
    mux_writes = sum(1 for t in read_log if t.address == hw.mux_address and t.kind == "write")
    mux_reads = sum(1 for t in read_log if t.address == hw.mux_address and t.kind == "read")
    config_checks = sum(1 for t in read_log if t.kind == "write_read" and t.written == b"\x01")
    hardening = sum(bits_on_wire([t]) for t in read_log if t.address == hw.mux_address and t.kind == "read")
    plain_read = 1 + 9 + 2 * 9 + 1  # a 2-byte conversion read without the pointer byte
    hardening += sum(bits_on_wire([t]) - (plain_read if t.written == b"\x00" else 0)
                     for t in read_log if t.kind == "write_read") + check_bits
    total = read_bits + pwm_bits + check_bits
    print("one 100 Hz cycle on the wire (steady state)")
    print("  feedback: %2d transactions (%d mux switches + %d read-backs, %d ADC config check), %4d bits"
          % (len(read_log), mux_writes, mux_reads, config_checks, read_bits))
    print("  PWM:      %2d transaction  (%d data bytes),   %4d bits" % (len(pwm_log), len(pwm_log[0].written), pwm_bits))
    print("  PCA9685 MODE1/MODE2 check: %d transaction of %d bits every %.0f cycles = %.1f bits per cycle"
          % (len(check_log), bits_on_wire(check_log), cycles_per_check, check_bits))
    print("  total:    %4.0f bits (of which fault detection: %.0f bits = %.3f ms at 400 kHz)"
          % (total, hardening, hardening / 400e3 * 1e3))
    for clock_hz in (100e3, 400e3):
        bus_time = total / clock_hz
        print("  at %3.0f kHz: %.3f ms = %5.1f %% of the 10 ms cycle" % (clock_hz / 1e3, bus_time * 1e3,
                                                                       100 * bus_time / CYCLE_S))
    at_400 = total / 400e3 / CYCLE_S
    print("  target: <= %.0f %% at 400 kHz -> %s (margin %.1f points)"
          % (100 * TARGET_FRACTION, "MET" if at_400 <= TARGET_FRACTION else "MISSED", 100 * (TARGET_FRACTION - at_400)))
    with_deselect = total + 20  # one more 1-byte mux write per cycle when mux.deselect_after_read is true
    print("  with mux.deselect_after_read: %d bits = %.1f %% at 400 kHz" % (with_deselect, 100 * with_deselect / 400e3 / CYCLE_S))

    fake.bus.log_enabled = False
    cycles = 2000
    start = time.perf_counter()
    for _ in range(cycles):
        feedback.read()
        pwm.command(pulses)
        pwm.update()
    elapsed = (time.perf_counter() - start) / cycles
    print("Python time per cycle against the fakes (feedback.read + pwm.command + pwm.update): %.1f us "
          "(%.1f %% of 10 ms), %d cycles" % (elapsed * 1e6, 100 * elapsed / CYCLE_S, cycles))


if __name__ == "__main__":
    main()
