"""Schema of ``config/vn100.yaml``: every key typed and bounded (the VN-100 driver node's settings).

:func:`vn100_settings_from_dict` validates a parsed file (plus the node's ``~param`` overrides) and
returns the settings as a plain mapping of checked values; :func:`load_vn100_settings` reads the file
through the strict loader (:mod:`quadruped_common.config`). Any problem is a ParameterError naming the
file and the key. Unknown keys are refused (a typo must not silently fall back to a default).

Bounds and their sources:

* ``baud``: the rates the VN-100 supports (UM001, Serial Baud Rate register 5);
* ``rate_hz``: 800 Hz / an integer divisor (UM001, binary output register 75);
* timeouts and intervals: positive and at most a few seconds (a NaN or infinite timeout blocks reads
  or disables stale detection);
* ``max_angular_rate``, ``max_acceleration``: the sensor's range (datasheet: +-2000 deg/s, +-16 g)
  with a margin, so at most 2x the range;
* ``quaternion_norm_tolerance``: (0, 0.1];
* covariance diagonals: three finite, non-negative variances (REP-145; a negative variance is not a
  variance) or a full row-major 3x3 matrix that is symmetric with a non-negative diagonal.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, Mapping, Optional

from quadruped_common.config import ParameterError, integer, load_config, number, string, vector
from quadruped_common.imu_plausibility import SensorLimits
from quadruped_drivers.vn100.protocol import rate_divisor_for

__all__ = ["SUPPORTED_BAUDS", "VN100_KEYS", "load_vn100_settings", "sensor_limits", "vn100_settings_from_dict"]

#: Baud rates of the VN-100's serial port (UM001, register 5).
SUPPORTED_BAUDS = (9600, 19200, 38400, 57600, 115200, 128000, 230400, 460800, 921600)


def _rate(value: Any, key: str) -> float:
    rate = number(value, key, 0.0, 800.0, low_open=True)
    try:
        rate_divisor_for(rate)
    except ValueError as exc:
        raise ParameterError("parameter '%s': %s" % (key, exc)) from None
    return rate


def _baud(value: Any, key: str) -> int:
    baud = integer(value, key, SUPPORTED_BAUDS[0], SUPPORTED_BAUDS[-1])
    if baud not in SUPPORTED_BAUDS:
        raise ParameterError("parameter '%s' = %d is not a VN-100 baud rate (%s)"
                             % (key, baud, ", ".join(str(b) for b in SUPPORTED_BAUDS)))
    return baud


def _covariance(value: Any, key: str) -> list:
    values = vector(value, key)
    if len(values) == 3:
        vector(values, key, 3, low=0.0)
        return values
    if len(values) == 9:
        for i in range(3):
            number(values[4 * i], "%s[%d]" % (key, 4 * i), low=0.0)
            for j in range(i + 1, 3):
                if not math.isclose(values[3 * i + j], values[3 * j + i], rel_tol=1e-9, abs_tol=1e-15):
                    raise ParameterError("parameter '%s' must be symmetric ([%d] != [%d])" % (key, 3 * i + j, 3 * j + i))
        return values
    raise ParameterError("parameter '%s' must be 3 variances (diagonal) or 9 values (3x3), got %d" % (key, len(values)))


def _positive(high: float) -> Callable[[Any, str], float]:
    return lambda value, key: number(value, key, 0.0, high, low_open=True)


#: key -> checker(value, key) of every key of vn100.yaml (all required).
VN100_KEYS: Dict[str, Callable[[Any, str], Any]] = {
    "port": lambda value, key: string(value, key),
    "baud": _baud,
    "rate_hz": _rate,
    "frame_id": lambda value, key: string(value, key),
    "command_timeout": _positive(10.0),
    "reconnect_interval": _positive(60.0),
    "read_timeout": _positive(1.0),
    "stale_timeout": _positive(10.0),
    "max_angular_rate": _positive(2.0 * math.radians(2000.0)),
    "max_acceleration": _positive(2.0 * 16.0 * 9.80665),
    "quaternion_norm_tolerance": _positive(0.1),
    "max_angular_acceleration": _positive(1e5),
    "angular_rate_change_margin": _positive(10.0),
    "rate_change_confirm_samples": lambda value, key: integer(value, key, 1, 100),
    "orientation_covariance_diagonal": _covariance,
    "angular_velocity_covariance_diagonal": _covariance,
    "linear_acceleration_covariance_diagonal": _covariance,
}


def vn100_settings_from_dict(tree: Mapping[str, Any], overrides: Optional[Mapping[str, Any]] = None,
                             override_names: Optional[Mapping[str, str]] = None) -> Dict[str, Any]:
    """Checked settings from a parsed vn100.yaml, with ``overrides`` (e.g. ROS ``~params``) taking precedence.

    An error in an overriding value names where it came from, not only the file's key: ``override_names``
    maps a key to its source (default ``~<key>``), e.g. ``{"rate_hz": "~rate"}`` gives "parameter '~rate
    (overrides rate_hz)'"."""
    merged = dict(tree)
    merged.update(overrides or {})
    unknown = sorted(set(merged) - set(VN100_KEYS))
    if unknown:
        raise ParameterError("unknown vn100 parameter '%s' (allowed: %s)" % (unknown[0], ", ".join(VN100_KEYS)))
    settings = {}
    for key, check in VN100_KEYS.items():
        if key not in merged:
            raise ParameterError("missing vn100 parameter '%s'" % key)
        label = key
        if overrides and key in overrides:
            label = "%s (overrides %s)" % ((override_names or {}).get(key, "~" + key), key)
        settings[key] = check(merged[key], label)
    return settings


def load_vn100_settings(path: Optional[str] = None, overrides: Optional[Mapping[str, Any]] = None,
                        override_names: Optional[Mapping[str, str]] = None) -> Dict[str, Any]:
    """Read and check ``config/vn100.yaml`` (or ``path``); ParameterError naming the file and the key (and
    the node parameter, for an overriding value)."""
    return load_config(path, "vn100.yaml", lambda tree: vn100_settings_from_dict(tree, overrides, override_names))


def sensor_limits(settings: Mapping[str, Any]) -> SensorLimits:
    """The plausibility limits of checked vn100.yaml settings: one set for the driver and the controller."""
    return SensorLimits(max_angular_rate=float(settings["max_angular_rate"]),
                        max_acceleration=float(settings["max_acceleration"]),
                        unit_tolerance=float(settings["quaternion_norm_tolerance"]),
                        max_angular_acceleration=float(settings["max_angular_acceleration"]),
                        rate_change_margin=float(settings["angular_rate_change_margin"]),
                        rate_change_confirm=int(settings["rate_change_confirm_samples"]))
