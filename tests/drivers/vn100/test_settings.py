"""config/vn100.yaml's baud rate search and reconnection settings (the rest: tests/common/test_config.py)."""
from __future__ import annotations

import pytest

from quadruped_common.config import ParameterError, config_path, load_yaml
from quadruped_drivers.vn100 import protocol as vp
from quadruped_drivers.vn100.settings import SUPPORTED_BAUDS, VN100_SCHEMA, vn100_settings_from_dict


def tree():
    return load_yaml(config_path("vn100.yaml"))


def test_shipped_values():
    settings = vn100_settings_from_dict(tree())
    assert settings["save_baud"] is False  # the sensor's flash is written only on request
    assert settings["baud"] == 921600 and SUPPORTED_BAUDS == vp.BAUD_RATES
    assert 0 < settings["reconnect_initial_delay"] < settings["stale_timeout"] < settings["reconnect_max_delay"]
    assert 0 < settings["probe_timeout"] < settings["command_timeout"]


@pytest.mark.parametrize("key, value, match", [
    ("save_baud", "yes", "'save_baud' must be"),
    ("probe_timeout", 0.0, r"'probe_timeout' = 0 is outside \(0"),
    ("probe_timeout", 2.0, "'probe_timeout'"),
    ("reconnect_initial_delay", -0.1, "'reconnect_initial_delay'"),
    ("reconnect_max_delay", float("inf"), "'reconnect_max_delay' must be finite"),
    ("reconnect_interval", 1.0, "unknown vn100 parameter 'reconnect_interval'"),  # renamed: the cap
])
def test_bounds(key, value, match):
    values = tree()
    values[key] = value
    with pytest.raises(ParameterError, match=match):
        vn100_settings_from_dict(values)


def test_the_back_off_starts_no_later_than_its_cap():
    values = tree()
    values["reconnect_initial_delay"], values["reconnect_max_delay"] = 2.0, 1.0
    with pytest.raises(ParameterError, match="'reconnect_initial_delay' = 2 must not exceed 'reconnect_max_delay' = 1"):
        vn100_settings_from_dict(values)


def test_each_new_setting_says_what_it_does():
    for key in ("save_baud", "probe_timeout", "reconnect_initial_delay", "reconnect_max_delay"):
        param = VN100_SCHEMA[key]
        assert param.meaning and param.source == "choice"
    assert "flash" in VN100_SCHEMA["save_baud"].meaning and "cap" in VN100_SCHEMA["reconnect_max_delay"].meaning
