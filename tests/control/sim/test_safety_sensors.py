"""The simulated robot's safety sensors: the fake MS5837 follows the body's depth through the unchanged driver,
the simulated packs discharge with time and the servos' load and reach the fake ADCs' spare inputs."""
import dataclasses

import numpy as np
import pytest
import yaml

from quadruped_common.config import ParameterError, config_path
from quadruped_common.health import ERROR, OK, WARN
from quadruped_control.sim.safety_sensors import (DepthModel, PackSettings, SafetySensorSettings, SimulatedPack,
                                                  with_overrides)
from quadruped_control.sim.simulation import load_simulation_settings, simulation_settings_from_dict
from quadruped_drivers.battery import BatteryMonitor, lipo_open_circuit_voltage
from quadruped_drivers.depth_sensor import DepthSensorRunner, make_driver, poll_period
from quadruped_drivers.hardware_config import load_hardware_config, with_batteries_fitted
from quadruped_drivers.i2c.fake_devices import build_fake_hardware

HW = with_batteries_fitted(load_hardware_config())  # the simulated robot fits both packs
SENSORS = load_simulation_settings().sensors


class Clock:
    def __init__(self):
        self.t = 10.0

    def __call__(self):
        return self.t

    def sleep(self, seconds):
        self.t += seconds


def test_settings_from_simulation_yaml():
    assert SENSORS.mean_depth_m == 0.5 and SENSORS.temperature_c == 20.0 and SENSORS.noise_counts == 8
    assert SENSORS.packs["motors"] == PackSettings(5.0, 0.9, 0.03, 0.5, 0.25)
    assert SENSORS.packs["electronics"].amps_per_rad_s == 0.0
    with open(config_path("simulation.yaml")) as stream:
        tree = yaml.safe_load(stream)
    del tree["simulated_robot"]
    assert simulation_settings_from_dict(tree).sensors == SafetySensorSettings()  # optional, same defaults
    tree["simulated_robot"] = {"batteries": {"motors": {"start_charge": 1.5}}}
    with pytest.raises(ParameterError, match="simulated_robot.batteries.motors.start_charge"):
        simulation_settings_from_dict(tree)


def test_depth_model():
    model = DepthModel(101325.0, 997.0, 0.5)
    assert model.depth(0.0) == 0.5 and model.depth(0.2) == pytest.approx(0.3) and model.depth(1.0) == 0.0
    assert model.pressure(-1.5) == pytest.approx(101325.0 + 997.0 * 9.80665 * 2.0)


def test_the_fake_on_the_simulated_bus_follows_the_depth():
    clock = Clock()
    fake = build_fake_hardware(HW, require_lock=True, clock=clock, seed=4)
    fake.depth.noise_counts = SENSORS.noise_counts
    model = DepthModel(HW.depth.surface_pa, HW.depth.fluid_density, SENSORS.mean_depth_m)
    runner = DepthSensorRunner(make_driver(fake.bus, HW.depth, clock=clock, sleep=clock.sleep), HW.depth, clock=clock)
    depths = []
    for k in range(400):  # 20 s: the body rises 10 cm and sinks again, at up to 3 cm/s
        z = 0.05 * (1.0 - np.cos(2.0 * np.pi * k / 400))
        fake.depth.set_state(model.pressure(z), SENSORS.temperature_c)
        clock.t += poll_period(HW.depth)
        step = runner.step()
        if step.publish_depth:
            depths.append((step.reading.depth_m, model.depth(z), step.reading.temperature_c))
    measured, true, temperature = np.array(depths).T
    assert len(depths) == pytest.approx(200, abs=2)  # 10 Hz
    assert np.max(np.abs(measured - true)) < 0.004 and np.min(measured) < 0.41 and np.max(measured) > 0.49
    assert np.all(np.abs(temperature - 20.0) < 0.05)
    assert np.std(np.diff(measured[:20])) > 0.0  # a few counts of noise: never the same reading twice in a row
    assert runner.health(clock.t).level == OK
    fake.set_depth_power(False)  # the fault sim_node's ~depth_sensor_fault injects
    assert not fake.depth_powered
    for _ in range(30):
        clock.t += poll_period(HW.depth)
        runner.step()
    assert runner.health(clock.t).level == ERROR
    fake.set_depth_power(True)
    for _ in range(60):
        clock.t += poll_period(HW.depth)
        runner.step()
    assert runner.health(clock.t).level == OK


def test_pack_discharges_with_time_and_load():
    settings = PackSettings(capacity_ah=1.0, start_charge=0.5, internal_resistance_ohm=0.03, idle_current_a=0.5,
                            amps_per_rad_s=0.25)
    idle, busy = SimulatedPack(2, settings), SimulatedPack(2, settings)
    assert idle.voltage == pytest.approx(2 * lipo_open_circuit_voltage(0.5) - 0.5 * 0.03)
    for _ in range(3600):
        idle.step(1.0, 0.0)
        busy.step(1.0, 12.0)  # 0.5 + 3 A
    assert idle.charge == pytest.approx(0.5 - 0.5 / 1.0, abs=1e-9) and busy.charge == 0.0
    assert busy.current_a == pytest.approx(3.5) and busy.voltage < idle.voltage
    assert busy.adc_volts(3.0) == pytest.approx(busy.voltage / 3.0)
    assert with_overrides(settings, capacity_ah=0.01) == dataclasses.replace(settings, capacity_ah=0.01)
    busy.set_charge(1.5)  # a fresh pack swapped in (sim_node ~battery_flat false): clamped to full
    assert busy.charge == 1.0 and busy.voltage > idle.voltage
    busy.set_charge(0.0)  # run flat (~battery_flat true): below any critical cell voltage at rest
    assert busy.voltage / 2 < 3.4


def test_a_small_pack_reaches_critical_in_seconds_through_the_fake_adc():
    """The rostest's drain, without ROS: sim_node's packs on the fake ADCs, the driver and health/battery."""
    from quadruped_drivers.calibration import load_servo_calibration
    from quadruped_drivers.servo_feedback import ServoFeedbackArray, SpareInput

    clock = Clock()
    fake = build_fake_hardware(HW)
    packs = {p.name: (p, SimulatedPack(p.cells, with_overrides(SENSORS.packs[p.name], 0.02, 0.12)))
             for p in HW.batteries.fitted}
    spares = [SpareInput(p.name, p.mux_channel, p.adc_address, p.adc_input) for p in HW.batteries.fitted]
    feedback = ServoFeedbackArray(fake.bus, HW, load_servo_calibration(), clock=clock, spare_inputs=spares,
                                  spare_period=1.0 / HW.batteries.rate_hz)
    fake.set_joint_voltages(np.full(12, 1.65))
    feedback.start()
    monitor = BatteryMonitor(HW.batteries, HW.adc_full_scale_v)
    levels = []
    for _ in range(3000):
        clock.t += 0.01
        for pack, simulated in packs.values():
            simulated.step(0.01, 15.0)  # the legs stroking
            fake.set_spare_voltage(pack.mux_channel, pack.adc_address, pack.adc_input,
                                   simulated.adc_volts(pack.divider_ratio))
        feedback.read()
        for sample in feedback.take_spare_samples():
            monitor.update(sample.name, sample.stamp, sample.volts)
        level = monitor.health(clock.t).level
        if not levels or levels[-1][1] != level:
            levels.append((clock.t - 10.0, level))
    # no reading yet, both read within 0.3 s, then down to critical in about 2.6 s, no flicker on the way
    assert [level for _, level in levels] == [ERROR, OK, WARN, ERROR]
    assert levels[1][0] < 0.3 and levels[-1][0] < 5.0 and monitor.health(clock.t).reason.startswith("motors:critical")
