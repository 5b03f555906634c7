"""MS5837 (Bar30 / Bar02) depth sensor core: datasheet maths, driver against the register-level fake, fuzz."""

import pytest

from quadruped_drivers import ms5837_fuzz
from quadruped_drivers.i2c.fake_bus import FakeI2CBus
from quadruped_drivers.i2c.fake_ms5837 import FakeMs5837
from quadruped_drivers.ms5837 import (TYPICAL_PROM, Calibration, Model, Ms5837, PromCrcError, compensate,
                                      compensation, crc4, depth_m, raw_codes, with_crc)

# The data sheets' "Example / Typical" columns (PRESSURE AND TEMPERATURE CALCULATION).
C_30BA = (34982, 36352, 20328, 22354, 26646, 26146)
C_02BA = (46372, 43981, 29059, 27842, 31553, 28165)


class Clock:
    def __init__(self):
        self.t = 100.0
        self.sleeps = []

    def __call__(self):
        return self.t

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        self.t += seconds


def calibration(model):
    return Calibration.from_prom(TYPICAL_PROM[model])


def rig(model=Model.BA30, pressure_pa=2.0e5, temperature_c=15.0, **driver_options):
    clock = Clock()
    bus = FakeI2CBus(require_lock=True)
    fake = bus.attach(0x76, FakeMs5837(model, clock=clock, pressure_pa=pressure_pa, temperature_c=temperature_c))
    driver = Ms5837(bus, model, clock=clock, sleep=clock.sleep, **driver_options)
    return clock, bus, fake, driver


# --- CRC-4 -------------------------------------------------------------------------------------------
def test_crc4_hand_computed_and_placed_in_word0():
    # all-zero PROM: the remainder stays 0
    assert crc4([0] * 7) == 0
    words = with_crc((0x1A << 5, *C_30BA))
    assert words[0] >> 12 == crc4(words) and words[0] & 0x0FFF == 0x1A << 5
    # the CRC field itself and an 8th word do not enter the computation
    assert crc4((words[0] ^ 0xF000,) + words[1:]) == crc4(words) == crc4(words + (0xFFFF,))
    # every single-bit error in the data is detected
    for index in range(7):
        for bit in range(12 if index == 0 else 16):
            damaged = list(words)
            damaged[index] ^= 1 << bit
            assert crc4(damaged) != words[0] >> 12


def test_calibration_refuses_a_bad_crc_naming_both_values():
    words = list(TYPICAL_PROM[Model.BA30])
    good = Calibration.from_prom(words)
    assert (good.c1, good.c6, good.version) == (34982, 26146, 0x1A) and good.words == tuple(words)
    words[3] ^= 0x0100
    with pytest.raises(PromCrcError) as caught:
        Calibration.from_prom(words)
    assert caught.value.read == words[0] >> 12 and caught.value.expected == crc4(words)
    assert "computed 0x%X" % crc4(words) in str(caught.value) and "holds 0x%X" % (words[0] >> 12) in str(caught.value)


# --- compensation against the data sheets' worked examples -------------------------------------------------
def test_30ba_typical_values():
    result = compensation(4958179, 6815414, calibration(Model.BA30), Model.BA30)
    assert result.dT == -5962 and result.TEMP == 1981  # 19.81 degC
    assert result.SENS == 1145816755
    # The data sheet prints OFF = 2381326464; C2 * 2^16 + C4 * dT / 2^7 is 2381323464 (a digit slip in the
    # table: the P it prints, 39998, follows from either).
    assert result.OFF == 36352 * 2 ** 16 + (22354 * -5962 >> 7) == 2381323464
    assert result.P == 39998  # 3999.8 mbar
    pressure, temperature = compensate(4958179, 6815414, calibration(Model.BA30), Model.BA30, second_order=False)
    assert pressure == pytest.approx(399980.0) and temperature == pytest.approx(19.81)


def test_02ba_typical_values():
    result = compensation(6465444, 8077636, calibration(Model.BA02), Model.BA02)
    assert (result.dT, result.TEMP, result.OFF, result.SENS, result.P) == (68, 2000, 5764707214, 3039050829, 110002)
    # TEMP = 20.00 degC: no second-order correction for the 02BA at >= 20 degC
    assert (result.Ti, result.OFFi, result.SENSi, result.P2, result.TEMP2) == (0, 0, 0, 110002, 2000)
    assert compensate(6465444, 8077636, calibration(Model.BA02), Model.BA02) == (pytest.approx(110002.0), 20.0)


def _at(model, temperature_c):
    cal = calibration(model)
    d1, d2 = raw_codes(1.5e5, temperature_c, cal, model)
    return compensation(d1, d2, cal, model)


def test_second_order_branches_30ba():
    high = _at(Model.BA30, 30.0)  # >= 20 degC: Ti = 2 dT^2 / 2^37, OFFi = (TEMP-2000)^2 / 2^4, SENSi = 0
    assert high.TEMP >= 2000 and high.Ti == 2 * high.dT ** 2 >> 37 and high.OFFi == (high.TEMP - 2000) ** 2 >> 4
    assert high.SENSi == 0
    low = _at(Model.BA30, 5.0)  # < 20 degC
    d = low.TEMP - 2000
    assert low.Ti == 3 * low.dT ** 2 >> 33 and low.OFFi == 3 * d * d >> 1 and low.SENSi == 5 * d * d >> 3
    very = _at(Model.BA30, -25.0)  # first-order TEMP < -15 degC: the very-low terms are added
    d, v = very.TEMP - 2000, very.TEMP + 1500
    assert very.TEMP < -1500
    assert very.OFFi == (3 * d * d >> 1) + 7 * v * v and very.SENSi == (5 * d * d >> 3) + 4 * v * v
    assert very.P2 != very.P and very.TEMP2 == very.TEMP - very.Ti


def test_second_order_branches_02ba():
    low = _at(Model.BA02, 5.0)
    d = low.TEMP - 2000
    assert low.Ti == 11 * low.dT ** 2 >> 35 and low.OFFi == 31 * d * d >> 3 and low.SENSi == 63 * d * d >> 5
    very = _at(Model.BA02, -18.0)  # no very-low branch for the 02BA
    d = very.TEMP - 2000
    assert very.OFFi == 31 * d * d >> 3 and very.SENSi == 63 * d * d >> 5
    high = _at(Model.BA02, 30.0)
    assert (high.Ti, high.OFFi, high.SENSi) == (0, 0, 0)


@pytest.mark.parametrize("model, pressure", [(Model.BA30, 2.6e6), (Model.BA30, 1.0e5), (Model.BA02, 1.1e5)])
@pytest.mark.parametrize("temperature", [-18.0, 4.0, 25.0])
def test_raw_codes_invert_compensate(model, pressure, temperature):
    cal = calibration(model)
    d1, d2 = raw_codes(pressure, temperature, cal, model)
    got_p, got_t = compensate(d1, d2, cal, model)
    step = 10.0 if model is Model.BA30 else 1.0
    assert abs(got_p - pressure) <= step and abs(got_t - temperature) <= 0.01


def test_depth_from_pressure():
    assert depth_m(101325.0 + 1025.0 * 9.80665 * 10.0, 101325.0, 1025.0) == pytest.approx(10.0)
    assert depth_m(101325.0, 101325.0, 997.0) == 0.0
    with pytest.raises(ValueError):
        depth_m(2e5, 101325.0, 0.0)


# --- the driver against the fake ---------------------------------------------------------------------
def test_start_and_read_respect_the_conversion_wait():
    clock, bus, fake, driver = rig(pressure_pa=2.0e5, temperature_c=15.0)
    cal = driver.start()
    assert cal.words == tuple(TYPICAL_PROM[Model.BA30]) and fake.resets == 1
    reading = driver.read()
    assert reading.fresh and reading.reason == ""
    assert reading.pressure_pa == pytest.approx(2.0e5, abs=20.0) and reading.temperature_c == pytest.approx(15.0, abs=0.02)
    assert reading.depth_m == pytest.approx((2.0e5 - 101325.0) / (997.0 * 9.80665), abs=0.005)
    assert fake.early_reads == 0 and all(s >= driver.conversion_time - 1e-9 for s in clock.sleeps[1:])
    assert fake.commands[:8] == [0x1E, 0xA0, 0xA2, 0xA4, 0xA6, 0xA8, 0xAA, 0xAC]
    assert fake.commands[8:] == [0x48, 0x00, 0x58, 0x00, 0x48]  # OSR 4096; the next D1 already started


def test_poll_is_non_blocking_and_never_reads_early():
    clock, bus, fake, driver = rig()
    driver.start()
    readings = []
    for _ in range(40):  # 100 Hz loop: a reading every second cycle at OSR 4096
        clock.t += 0.005
        reading = driver.poll()
        if reading is not None:
            readings.append(reading)
    assert len(readings) >= 5 and all(reading.fresh for reading in readings)
    assert fake.early_reads == 0 and clock.sleeps == [pytest.approx(0.01)]  # only start()'s reset wait


def test_bad_prom_refused_with_a_clear_error():
    clock, bus, fake, driver = rig()
    fake.corrupt_prom(2, 0x0004)
    with pytest.raises(PromCrcError, match="CRC mismatch"):
        driver.start()
    assert driver.counters()["crc_failures"] == 1 and driver.calibration is None
    with pytest.raises(RuntimeError):
        driver.poll()


def test_nack_is_counted_and_not_fresh():
    clock, bus, fake, driver = rig()
    driver.start()
    assert driver.read().fresh
    bus.inject_fault(0x76, "nack")
    reading = driver.read()
    assert not reading.fresh and reading.reason == "bus_error" and driver.counters()["bus_error"] == 1
    assert driver.read().fresh  # recovers on the next read


def test_unfinished_and_garbage_conversions_are_not_fresh():
    clock, bus, fake, driver = rig()
    driver.start()
    driver.read()
    fake.conversion_scale = 2.0  # slower than the data sheet's maximum: the ADC reads 0
    reading = driver.read()
    assert not reading.fresh and reading.reason == "adc_not_ready"
    fake.conversion_scale = 1.0
    fake.inject_codes([0xFFFFFF, 1])
    reading = driver.read()
    assert not reading.fresh and reading.reason.startswith("implausible")


def test_stuck_adc_is_not_fresh():
    clock, bus, fake, driver = rig()
    driver.start()
    driver.read()
    fake.noise_counts = 0
    reasons = [driver.read().reason for _ in range(4)]
    assert reasons[:2] == ["", ""] and reasons[2:] == ["stuck_adc", "stuck_adc"]


def test_depth_jump_not_fresh_until_confirmed():
    clock, bus, fake, driver = rig(pressure_pa=2.0e5, max_depth_rate=1.0, rate_margin_m=0.05, rate_confirm_readings=3)
    driver.start()
    assert driver.read().fresh
    fake.set_state(2.0e5 + 997.0 * 9.80665 * 5.0, 15.0)  # 5 m in ~20 ms: beyond 1 m/s
    reasons = [driver.read().reason for _ in range(3)]
    assert reasons == ["rate", "rate", ""]
    counts = driver.counters()
    assert counts["rate"] == 2 and counts["jumps_accepted"] == 1
    # a single spike and back is never fresh
    fake.inject_codes([raw_codes(2.0e5 + 997.0 * 9.80665 * 9.0, 15.0, calibration(Model.BA30), Model.BA30)[0]])
    assert driver.read().reason == "rate" and driver.read().fresh


def test_02ba_plausible_range():
    clock, bus, fake, driver = rig(Model.BA02, pressure_pa=1.01e5)
    driver.start()
    assert driver.read().fresh
    fake.set_state(2.5e5, 15.0)  # 15 m: beyond the Bar02's range (ADC saturates or implausible)
    assert not driver.read().fresh


# --- fuzz campaign -----------------------------------------------------------------------------------
@pytest.mark.parametrize("model", [Model.BA30, Model.BA02])
def test_fuzz_campaign_small(model):
    stats = ms5837_fuzz.run(3000, seed=3, model=model)
    assert {key: stats[key] for key in ms5837_fuzz.MUST_BE_ZERO} == dict.fromkeys(ms5837_fuzz.MUST_BE_ZERO, 0), stats
    assert all(stats["fault " + fault] > 0 for fault in ms5837_fuzz.FAULTS)
    assert stats["crc_refusals"] == stats["fault prom"] and stats["fresh"] > 100
    assert stats["driver implausible_pressure"] > 0 and stats["driver rate"] > 0 and stats["driver bus_error"] > 0
    # what ms5837_node would publish: every reading fresh, finite and plausible
    assert stats["published"] == stats["fresh"] > 100 and stats["implausible_published"] == 0
