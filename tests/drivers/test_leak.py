"""The leak probe: hardware.yaml ``leak``, :class:`LeakWatch` (confirmation, latch, reset, lost reads) and the
real pin's reader off a Jetson."""
import dataclasses

import pytest
import yaml

from quadruped_common.config import ParameterError, config_path
from quadruped_common.health import ERROR, OK, WARN
from quadruped_drivers.hardware_config import hardware_config_from_dict, load_hardware_config, with_leak_fitted
from quadruped_drivers.leak import GpioUnavailable, LeakWatch, open_gpio_probe

LEAK = with_leak_fitted(load_hardware_config()).leak  # 10 Hz, 3 readings to confirm, 1 s timeout


def hardware_tree():
    with open(config_path("hardware.yaml")) as stream:
        return yaml.safe_load(stream)


def test_shipped_leak_section_is_not_fitted_and_an_absent_section_reads_as_such():
    shipped = load_hardware_config().leak
    assert not shipped.fitted and shipped.active_high and shipped.confirm_readings == 3
    tree = hardware_tree()
    del tree["leak"]
    assert hardware_config_from_dict(tree).leak == dataclasses.replace(shipped, fitted=False)


@pytest.mark.parametrize("key, value, message", [
    ("pin", 41, "leak.pin"), ("rate_hz", 0.0, "leak.rate_hz"), ("timeout_s", 0.1, "at least 2 / leak.rate_hz"),
    ("confirm_readings", 0, "leak.confirm_readings"), ("active_high", "yes", "leak.active_high"),
    ("wet", True, "unknown hardware parameter 'leak.wet'"),
])
def test_bad_leak_configuration_is_refused_naming_the_key(key, value, message):
    tree = hardware_tree()
    tree["leak"][key] = value
    with pytest.raises(ParameterError, match=message):
        hardware_config_from_dict(tree)


def feed(watch, levels, t=0.0, period=0.1):
    events = []
    for level in levels:
        t += period
        events.append(watch.update(level, t))
    return t, [event for event in events if event]


def test_a_dry_probe_is_ok_and_water_is_reported_after_the_confirming_readings():
    watch = LeakWatch(LEAK, 0.0)
    assert (watch.health(0.0).level, watch.health(0.0).reason) == (WARN, "no_reading")
    t, events = feed(watch, [False] * 5)
    assert watch.health(t) .level == OK and not events
    t, events = feed(watch, [True, True], t)
    assert (watch.health(t).level, watch.health(t).reason) == (WARN, "wet") and not events
    t, events = feed(watch, [True], t)
    health = watch.health(t)
    assert (health.level, health.reason) == (ERROR, "leak") and "WATER INSIDE" in health.message
    assert len(events) == 1 and "3 times" in events[0]


def test_a_splash_shorter_than_the_confirmation_is_not_a_leak():
    watch = LeakWatch(LEAK, 0.0)
    t, events = feed(watch, [True, True, False, True, True, False] * 3)
    assert watch.health(t).level == OK and not events


def test_inverted_probe_reads_low_as_wet():
    watch = LeakWatch(dataclasses.replace(LEAK, active_high=False), 0.0)
    t, _ = feed(watch, [False] * 3)
    assert watch.health(t).reason == "leak"


def test_the_leak_is_latched_until_a_reset_while_dry():
    watch = LeakWatch(LEAK, 0.0)
    t, _ = feed(watch, [True] * 3)
    assert watch.reset() == (False, "the probe still reads wet") and watch.health(t).reason == "leak"
    t, _ = feed(watch, [False] * 20, t)
    assert watch.health(t).reason == "leak"  # dried in a draught: still reported
    done, why = watch.reset()
    assert done and "cleared" in why and watch.health(t).level == OK
    assert watch.reset() == (True, "no leak reported")


def test_failed_reads_are_a_measurement_fault_after_the_timeout():
    watch = LeakWatch(LEAK, 0.0)
    t, _ = feed(watch, [False] * 3)
    t, _ = feed(watch, [None] * 9, t)  # 0.9 s: within the 1 s timeout
    assert watch.health(t).level == OK
    t, _ = feed(watch, [None] * 2, t)
    health = watch.health(t)
    assert (health.level, health.reason) == (ERROR, "no_reading") and "pin 15" in health.message
    assert dict(watch.values())["failed reads"] == "11"
    never = LeakWatch(LEAK, 0.0)
    assert never.health(1.05).reason == "no_reading" and never.health(1.05).level == ERROR


def test_a_probe_not_fitted_is_ok_whatever_it_reads():
    watch = LeakWatch(load_hardware_config().leak, 0.0)
    assert (watch.health(100.0).level, watch.health(100.0).reason) == (OK, "not_fitted")


def test_the_real_pin_off_a_jetson_is_a_one_line_configuration_error():
    with pytest.raises(GpioUnavailable, match="Jetson.GPIO cannot run here"):
        open_gpio_probe(LEAK)
