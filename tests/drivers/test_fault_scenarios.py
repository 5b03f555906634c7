"""The fault campaigns at a size that fits CI (benchmarks/fuzz_campaign.py runs the full size)."""
import pytest

from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.fault_scenarios import FAULTS, faulty_cycles
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.vn100 import fuzz

MUST_BE_ZERO_VN100 = ("crashes", "hangs", "nan_outputs", "implausible_published", "bad_offsets")
MUST_BE_ZERO_I2C = ("crashes", "hangs", "nan_outputs", "wrongly_fresh", "pulses_outside_limits")


@pytest.mark.parametrize("seed", [1, 2])
def test_mutated_vn100_streams(seed):
    stats = fuzz.run(4000, seed=seed)
    assert {key: stats[key] for key in MUST_BE_ZERO_VN100} == dict.fromkeys(MUST_BE_ZERO_VN100, 0)
    assert all(stats["mutation " + kind] > 0 for kind in fuzz.MUTATIONS)
    # the checks were exercised: CRC-valid implausible packets reached the gate and were dropped
    assert stats["dropped angular rate range"] > 0 and stats["dropped quaternion norm"] > 0
    assert stats["published"] > stats["mutation clean"] // 2


@pytest.mark.parametrize("seed", [1, 2])
def test_faulty_i2c_cycles(seed):
    stats = faulty_cycles(1500, load_hardware_config(), load_servo_calibration(), seed=seed)
    assert {key: stats[key] for key in MUST_BE_ZERO_I2C} == dict.fromkeys(MUST_BE_ZERO_I2C, 0), stats
    assert all(stats["fault " + fault] > 0 for fault in FAULTS)
    assert stats["chip_resets_found"] > 0 and stats["mux_mismatches"] > 0 and stats["adc_config_losses"] > 0
    assert stats["fresh_joint_samples"] > 6 * stats["cycles"]  # most joints stay fresh through it all
