"""The depth sensor's configuration (hardware.yaml ``depth``), the pure run loop of ms5837_node (start, retry,
restart, zeroing, what is published) and health/depth, against the register-level fake MS5837."""
import dataclasses

import numpy as np
import pytest
import yaml

from quadruped_common.config import ParameterError, config_path
from quadruped_common.health import ERROR, OK, WARN, Health, HealthGate
from quadruped_drivers.depth_sensor import (G, UNMEASURED_VARIANCE, DepthSensorRunner, SurfaceReference,
                                            depth_variance, make_driver, poll_period, pose_covariance, publishable)
from quadruped_drivers.hardware_config import hardware_config_from_dict, load_hardware_config
from quadruped_drivers.i2c.bus_lock import ROLES
from quadruped_drivers.i2c.fake_bus import FakeI2CBus
from quadruped_drivers.i2c.fake_ms5837 import FakeMs5837
from quadruped_drivers.ms5837 import Model

DEPTH = load_hardware_config().depth
SURFACE = 101325.0


def hardware_tree():
    with open(config_path("hardware.yaml")) as stream:
        return yaml.safe_load(stream)


class Clock:
    def __init__(self):
        self.t = 50.0

    def __call__(self):
        return self.t

    def sleep(self, seconds):
        self.t += seconds


def pressure_at(depth_m, density=997.0):
    return SURFACE + density * G * depth_m


def rig(depth=DEPTH, attach=True, depth_m=0.5):
    clock = Clock()
    bus = FakeI2CBus(require_lock=True)
    fake = FakeMs5837(depth.ms5837_model, clock=clock, pressure_pa=pressure_at(depth_m), temperature_c=20.0,
                      noise_counts=8)
    if attach:
        bus.attach(depth.address, fake)
    driver = make_driver(bus, depth, clock=clock, sleep=clock.sleep)
    return clock, bus, fake, DepthSensorRunner(driver, depth, clock=clock)


def run(clock, runner, seconds):
    """Call the runner as the node's timer does for ``seconds``; the steps."""
    steps = []
    for _ in range(int(round(seconds / poll_period(runner.depth)))):
        clock.t += poll_period(runner.depth)
        steps.append(runner.step())
    return steps


# --- configuration ---------------------------------------------------------------------------------
def test_shipped_depth_section():
    assert DEPTH.fitted and DEPTH.model == "bar30" and DEPTH.ms5837_model is Model.BA30 and DEPTH.address == 0x76
    assert DEPTH.mux_channel == -1 and DEPTH.rate_hz == 10.0 and DEPTH.osr == 4096
    assert DEPTH.fluid_density == 997.0 and DEPTH.surface_pa == SURFACE and not DEPTH.zero_at_start
    assert "depth" in ROLES


@pytest.mark.parametrize("key, value, message", [
    ("mux_channel", 3, "behind the TCA9548A is not supported"),
    ("mux_channel", 8, "depth.mux_channel"),
    ("osr", 8192, "the bar30 has no conversion command above OSR 4096"),
    ("osr", 1000, "not an MS5837 oversampling ratio"),
    ("rate_hz", 50.0, "two conversions at OSR 4096 take 18.1 ms"),
    ("rate_hz", 0.0, "depth.rate_hz"),
    ("timeout_s", 0.1, "at least 2 / depth.rate_hz"),
    ("address", 0x71, "clashes with the mux"),
    ("address", 0x70, "clashes"),
    ("model", "bar100", "depth.model"),
    ("fluid_density_kg_m3", 1.2, "depth.fluid_density_kg_m3"),
    ("fitted", "yes", "depth.fitted"),
    ("unknown_key", 1, "unknown hardware parameter 'depth.unknown_key'"),
])
def test_bad_depth_configuration_is_refused_naming_the_key(key, value, message):
    tree = hardware_tree()
    tree["depth"][key] = value
    with pytest.raises(ParameterError, match=message):
        hardware_config_from_dict(tree)


def test_depth_section_defaults_and_required_fitted():
    tree = hardware_tree()
    tree["depth"] = {"fitted": True}
    depth = hardware_config_from_dict(tree).depth
    assert depth == dataclasses.replace(DEPTH, zero_at_start=False)  # every other key's default is the shipped value
    tree["depth"] = {"fitted": False, "model": "bar02", "osr": 8192, "rate_hz": 5.0}
    assert hardware_config_from_dict(tree).depth.ms5837_model is Model.BA02
    del tree["depth"]
    with pytest.raises(ParameterError, match="missing hardware parameter 'depth.fitted'"):
        hardware_config_from_dict(tree)


# --- pure helpers ----------------------------------------------------------------------------------
def test_message_helpers():
    assert poll_period(DEPTH) == pytest.approx(0.05)
    variance = depth_variance(DEPTH)
    assert variance == pytest.approx((30.0 / (997.0 * G)) ** 2)  # 3 mm standard deviation
    covariance = pose_covariance(DEPTH)
    assert len(covariance) == 36 and covariance[14] == variance
    assert [covariance[7 * i] for i in (0, 1, 3, 4, 5)] == [UNMEASURED_VARIANCE] * 5
    assert sum(value != 0.0 for value in covariance) == 6


def test_health_gate_publishes_on_period_and_change():
    gate = HealthGate(0.5)
    ok = runner_health(OK)
    assert gate.due(0.0, ok) and not gate.due(0.2, ok) and gate.due(0.5, ok)
    assert gate.due(0.6, runner_health(ERROR)) and not gate.due(0.7, runner_health(ERROR))
    assert gate.due(0.65, runner_health(ERROR)) is False and gate.due(0.1, runner_health(ERROR))  # clock went back
    # a 20 Hz caller with a few ms of jitter: 2 Hz on average, not every 11th tick
    gate, rng = HealthGate(0.5), np.random.default_rng(1)
    ticks = 0.05 * np.arange(1, 2001) + rng.uniform(-0.004, 0.004, 2000)
    assert sum(gate.due(t, ok) for t in ticks) == pytest.approx(200, abs=1)


def runner_health(level):
    return Health(level, "" if level == OK else "x", "m")


def test_surface_reference():
    assert SurfaceReference(SURFACE).surface_pa == SURFACE
    zeroing = SurfaceReference(SURFACE, zero_at_start=True, readings=3)
    assert not zeroing.ready and zeroing.add(100000.0) is None and zeroing.add(100010.0) is None
    assert "taken" in zeroing.add(100020.0) and zeroing.surface_pa == 100010.0 and zeroing.zeroed
    refused = SurfaceReference(SURFACE, zero_at_start=True, max_offset_pa=3000.0, readings=1)
    assert "refused" in refused.add(pressure_at(1.0)) and refused.surface_pa == SURFACE and not refused.zeroed
    assert SurfaceReference(SURFACE, zero_at_start=True, known=99000.0).surface_pa == 99000.0


# --- the run loop against the fake -------------------------------------------------------------------
def test_readings_at_the_configured_rate_with_depth_and_ok_health():
    clock, bus, fake, runner = rig(depth_m=0.5)
    steps = run(clock, runner, 5.0)
    published = [step for step in steps if step.publish_pressure]
    assert len(published) == pytest.approx(5.0 * DEPTH.rate_hz, abs=2)
    assert all(step.publish_depth and step.reading.fresh for step in published)
    depths = [step.reading.depth_m for step in published]
    assert all(abs(depth - 0.5) < 0.005 for depth in depths)  # noise of a few counts: a few mm
    assert all(abs(step.reading.temperature_c - 20.0) < 0.05 for step in published)
    assert any(step.event and "started" in step.event for step in steps)
    health = runner.health(clock.t)
    assert health.level == OK and "depth 0.50 m" in health.message and dict(health.values)["fresh"] == str(len(published))


def test_no_sensor_at_start_is_retried_then_found():
    clock, bus, fake, runner = rig(attach=False)
    steps = run(clock, runner, 2.5)
    problems = [step.problem for step in steps if step.problem]
    assert len(problems) == 3 and "does not answer at 0x76" in problems[0]  # retried once a second
    assert runner.health(clock.t).level == ERROR and runner.health(clock.t).reason == "no_answer"
    bus.attach(0x76, fake)
    steps = run(clock, runner, 2.0)
    assert any(step.publish_pressure for step in steps) and runner.health(clock.t).level == OK


def test_lost_sensor_goes_error_within_the_timeout_and_recovers():
    clock, bus, fake, runner = rig()
    run(clock, runner, 2.0)
    assert runner.health(clock.t).level == OK
    bus.detach(0x76)
    lost = clock.t
    error_at = None
    for _ in range(100):
        clock.t += poll_period(DEPTH)
        step = runner.step()
        assert not step.publish_pressure  # nothing from a sensor that does not answer
        health = runner.health(clock.t)
        if health.level == WARN:
            assert health.reason == "dropped"
        if health.level == ERROR and error_at is None:
            error_at = clock.t
    assert error_at is not None and DEPTH.timeout_s < error_at - lost <= DEPTH.timeout_s + 2 * poll_period(DEPTH)
    assert runner.health(clock.t).reason == "stale" and runner.counts["restarts"] >= 1
    bus.attach(0x76, fake)  # found again by the retries (the last dropped reading is seconds old)
    steps = run(clock, runner, 2.0)
    assert any(step.publish_pressure for step in steps) and runner.health(clock.t).level == OK


def test_bad_prom_is_error_and_never_published():
    clock, bus, fake, runner = rig()
    fake.corrupt_prom(2, 0x0010)
    steps = run(clock, runner, 1.5)
    assert not any(step.publish_pressure for step in steps) and "PROM refused" in steps[0].problem
    health = runner.health(clock.t)
    assert health.level == ERROR and health.reason == "prom_crc" and "CRC" in health.message


def test_garbage_is_dropped_and_warned_never_published():
    clock, bus, fake, runner = rig()
    run(clock, runner, 1.0)
    fake.inject_codes([0xFFFFFF])
    steps = run(clock, runner, 0.3)
    rejected = [step for step in steps if step.reading is not None and not step.publish_pressure]
    assert rejected and rejected[0].reading.reason == "implausible_pressure"
    assert all(publishable(step.reading, runner.driver) for step in steps if step.publish_pressure)
    health = runner.health(clock.t)
    assert health.level == WARN and "implausible_pressure" in health.message


def test_zero_at_start_takes_the_surface_and_publishes_depth_after():
    depth = dataclasses.replace(DEPTH, zero_at_start=True)
    clock, bus, fake, runner = rig(depth=depth, depth_m=0.1)  # 0.1 m: within zero_max_offset_pa
    steps = run(clock, runner, 2.0)
    published = [step for step in steps if step.publish_pressure]
    assert not any(step.publish_depth for step in published[:9]) and all(step.publish_depth for step in published[10:])
    assert any(step.event and "surface pressure" in step.event for step in steps)
    assert abs(published[-1].reading.depth_m) < 0.005 and runner.surface.zeroed


def test_not_fitted_is_ok_and_does_nothing():
    depth = dataclasses.replace(DEPTH, fitted=False)
    runner = DepthSensorRunner(None, depth, clock=Clock())
    assert runner.step().reading is None
    health = runner.health(0.0)
    assert health.level == OK and health.reason == "not_fitted"
