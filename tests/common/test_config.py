"""The one strict configuration loader (quadruped_common.config) and the schemas built on it."""
import math

import pytest

from quadruped_common.config import MAX_DEPTH, ParameterError, config_path, load_yaml, parse_yaml
from quadruped_common.tunables import TUNABLES, bounds
from quadruped_control.control.controller_config import Gains, load_controller_config
from quadruped_control.sim.config_files import LOADERS
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.vn100.settings import load_vn100_settings, vn100_settings_from_dict

@pytest.mark.parametrize("name", sorted(LOADERS))
def test_every_shipped_file_loads(name):
    assert LOADERS[name](config_path(name)) is not None


def _write(tmp_path, text, name="bad.yaml"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return str(path)


@pytest.mark.parametrize("text, match", [
    ("body:\n  mass: 4.9\n  mass: 49.0\n", r"duplicate key 'body\.mass' \(line 3; first at line 2\)"),
    ("a: 1\na: 2\n", "duplicate key 'a'"),
    ("legs:\n  1: [0, 0, 0]\n  '2': [0, 0, 0]\n", r"'legs' \(line 2\): key '1' is not a string"),
    ("true: 1\n", "key 'true' is not a string"),
    ("? [1, 2]\n: 3\n", "not a string"),
    ("base: &b {x: 1}\nother: *b\n", r"aliases \(\*b\) are not allowed"),
    ("a: &a [*a]\n", "aliases"),
    ("x: " + "[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5) + "\n", "nested more than"),
    ("n: " + "9" * 400 + "\n", r"'n' \(line 1\): integer 99999999999999999999\.\.\. is too large"),
    ("t: 2001-12-14\n", "unsupported YAML type"),
    ("b: !!binary aGVsbG8=\n", "unsupported YAML type"),
    ("a: [unclosed\n", "not valid YAML"),
    ("- 1\n- 2\n", "mapping at the top level"),
    ("", "mapping at the top level"),
    ("a: 1\n---\nb: 2\n", "not valid YAML"),
])
def test_malformed_yaml_is_refused_naming_file_and_key(tmp_path, text, match):
    path = _write(tmp_path, text)
    with pytest.raises(ParameterError, match=match) as info:
        load_yaml(path)
    assert str(info.value).startswith(path + ": ")


def test_bad_encoding_size_and_missing_file(tmp_path):
    path = _write(tmp_path, b"a: 1\nb: \xff\xfe\n")
    with pytest.raises(ParameterError, match=r"bad\.yaml: not UTF-8 text \(byte 0xff at offset 8\)"):
        load_yaml(path)
    big = _write(tmp_path, "a: 1\n" + "#" * (1 << 20) + "\n", "big.yaml")
    with pytest.raises(ParameterError, match="big.yaml: larger than"):
        load_yaml(big)
    with pytest.raises(ParameterError, match="cannot read"):
        load_yaml(str(tmp_path / "missing.yaml"))
    assert parse_yaml("\ufeffa: 1") == {"a": 1}


def test_plain_values_parse_as_yaml_1_1_scalars():
    tree = parse_yaml("a: 1\nb: 2.5\nc: true\nd: null\ne: text\nf: [1, 2]\ng: {h: .inf}\n'1': quoted\n")
    assert tree == {"a": 1, "b": 2.5, "c": True, "d": None, "e": "text", "f": [1, 2], "g": {"h": math.inf},
                    "1": "quoted"}


def _vn100_tree():
    return load_yaml(config_path("vn100.yaml"))


@pytest.mark.parametrize("key, value, match", [
    ("baud", True, "'baud' must be an integer"),
    ("baud", 100000, "not a VN-100 baud rate"),
    ("rate_hz", 300.0, "rate_hz"),
    ("rate_hz", "200", "'rate_hz' must be a number"),
    ("read_timeout", math.nan, "'read_timeout' must be finite"),
    ("stale_timeout", math.inf, "'stale_timeout' must be finite"),
    ("command_timeout", 0.0, r"'command_timeout' = 0 is outside \(0"),
    ("port", 7, "'port' must be a non-empty string"),
    ("max_angular_rate", -1.0, "max_angular_rate"),
    ("orientation_covariance_diagonal", [1e-4, -1e-4, 1e-4], r"'orientation_covariance_diagonal' = .*: variance \[1\] "
                                                              "= -0.0001 is negative"),
    ("angular_velocity_covariance_diagonal", [math.nan, 0.0, 0.0], r"angular_velocity_covariance_diagonal\[0\]"),
    ("linear_acceleration_covariance_diagonal", [1, 2, 3, 4], "3 variances"),
    ("typo_key", 1, "unknown vn100 parameter 'typo_key'"),
])
def test_vn100_schema_bounds_every_key(key, value, match):
    tree = _vn100_tree()
    tree[key] = value
    with pytest.raises(ParameterError, match=match):
        vn100_settings_from_dict(tree)


def test_vn100_overrides_are_checked_too():
    assert vn100_settings_from_dict(_vn100_tree(), {"rate_hz": 100})["rate_hz"] == 100.0
    with pytest.raises(ParameterError, match="rate_hz"):
        vn100_settings_from_dict(_vn100_tree(), {"rate_hz": 123.0})
    # a rate the sensor cannot divide to, from the node's ~rate: the error names the parameter and the file
    with pytest.raises(ParameterError, match=r"vn100\.yaml: parameter '~rate \(overrides rate_hz\)'.*800 Hz") as info:
        load_vn100_settings(None, {"rate_hz": 300.0}, {"rate_hz": "~rate"})
    assert "Vn100Error" not in str(info.value) and "protocol" not in str(info.value)
    tree = _vn100_tree()
    del tree["frame_id"]
    with pytest.raises(ParameterError, match="missing vn100 parameter 'frame_id'"):
        vn100_settings_from_dict(tree)


def test_gain_bounds_are_the_reconfigure_bounds():
    limits = bounds()
    for name in ("k_p", "k_i", "k_d", "k_aw"):
        low, high = limits[name]
        values = dict(k_p=1.0, k_i=1.0, k_d=1.0, k_aw=1.0)
        for ok in (low, high):
            Gains(**dict(values, **{name: ok}))
        for bad in (low - 1e-9, high * (1 + 1e-9), math.nan, math.inf, 1e300):
            with pytest.raises(ParameterError, match=name):
                Gains(**dict(values, **{name: bad}))


def test_generated_reconfigure_definition_uses_the_same_table():
    cfg = pytest.importorskip("underwater_quadruped.cfg.AttitudeControllerConfig")
    generated = {p["name"]: (p["default"], p["min"], p["max"])
                 for group in cfg.config_description["groups"] for p in group["parameters"] if p["type"] == "double"}
    assert generated == {t.name: (t.default, t.low, t.high) for t in TUNABLES}


def test_bad_gain_set_is_refused_even_when_another_is_chosen(tmp_path):
    text = open(config_path("controller.yaml")).read().replace("k_p: 10.0", "k_p: 1.0e+300", 1)
    path = _write(tmp_path, text, "controller.yaml")
    with pytest.raises(ParameterError, match=r"controller\.yaml: .*'gain_sets\.experiment\.k_p' = 1e\+300 is outside"):
        load_controller_config(path, "simulation")


def test_calibration_rejects_negative_rms_and_unknown_keys(tmp_path):
    base = open(config_path("servo_calibration.yaml")).read()
    path = _write(tmp_path, base.replace("feedback_fitted: false", "feedback_fitted: false\n    feedback_rms_deg: -1.0", 1),
                  "cal.yaml")
    with pytest.raises(ParameterError, match=r"cal\.yaml: .*'joints\.leg1_motor1\.feedback_rms_deg' = -1"):
        load_servo_calibration(path)
    path = _write(tmp_path, base.replace("direction: 1", "direction: 1\n    directoin: -1", 1), "cal2.yaml")
    with pytest.raises(ParameterError, match=r"unknown calibration parameter 'joints\.leg1_motor1\.directoin'"):
        load_servo_calibration(path)
