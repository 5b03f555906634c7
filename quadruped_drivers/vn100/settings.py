"""Schema of ``config/vn100.yaml``: every key typed and bounded (the VN-100 driver node's settings).

:data:`VN100_SCHEMA` declares each key once (:mod:`quadruped_common.schema`; its table is in
docs/configuration.md). :func:`vn100_settings_from_dict` reads a parsed file, plus the node's ``~param``
overrides, through it and returns the settings as a plain mapping of checked values;
:func:`load_vn100_settings` reads the file through the strict loader (:mod:`quadruped_common.config`). Any
problem is a ParameterError naming the file and the key. Unknown keys are refused (a typo must not silently
fall back to a default).

Bounds and their sources:

* ``baud``: the rates the VN-100 supports (UM001, Serial Baud Rate register 5);
* ``save_baud``: false unless asked: writing the sensor's flash is a deliberate act (``$VNWNV``);
* ``rate_hz``: 800 Hz / an integer divisor (UM001, binary output register 75);
* timeouts and intervals: positive and at most a few seconds (a NaN or infinite timeout blocks reads
  or disables stale detection); the reconnection back-off starts no later than it ends
  (``reconnect_initial_delay`` <= ``reconnect_max_delay``);
* ``max_angular_rate``, ``max_acceleration``: the sensor's range (datasheet: +-2000 deg/s, +-16 g)
  with a margin, so at most 2x the range;
* ``quaternion_norm_tolerance``: (0, 0.1];
* covariance diagonals: three finite, non-negative variances (REP-145; a negative variance is not a
  variance) or a full row-major 3x3 matrix that is symmetric with a non-negative diagonal.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, Mapping, Optional

from quadruped_common.config import ParameterError, check_keys, load_config
from quadruped_common.imu_plausibility import SensorLimits
from quadruped_common.schema import Param, Schema
from quadruped_drivers.vn100.protocol import BAUD_RATES, rate_divisor_for

__all__ = ["SUPPORTED_BAUDS", "VN100_KEYS", "VN100_SCHEMA", "load_vn100_settings", "sensor_limits",
           "vn100_settings_from_dict"]

#: Baud rates of the VN-100's serial port (UM001, register 5).
SUPPORTED_BAUDS = BAUD_RATES


def _rate_problem(rate: float) -> Optional[str]:
    try:
        rate_divisor_for(rate)
    except ValueError as exc:
        return str(exc)
    return None


def _baud_problem(baud: int) -> Optional[str]:
    if baud in SUPPORTED_BAUDS:
        return None
    return "not a VN-100 baud rate (%s)" % ", ".join(str(b) for b in SUPPORTED_BAUDS)


def _covariance_problem(values: list) -> Optional[str]:
    """3 non-negative variances, or a symmetric row-major 3x3 with a non-negative diagonal."""
    if len(values) == 3:
        diagonal = [0, 1, 2]
    elif len(values) == 9:
        diagonal = [0, 4, 8]
        for i in range(3):
            for j in range(i + 1, 3):
                if not math.isclose(values[3 * i + j], values[3 * j + i], rel_tol=1e-9, abs_tol=1e-15):
                    return "must be symmetric ([%d] != [%d])" % (3 * i + j, 3 * j + i)
    else:
        return "must be 3 variances (diagonal) or 9 values (3x3), got %d" % len(values)
    negative = [i for i in diagonal if values[i] < 0.0]
    return "variance [%d] = %g is negative" % (negative[0], values[negative[0]]) if negative else None


def _positive(key: str, unit: str, meaning: str, high: float, source: str = "choice") -> Param:
    return Param(key, unit, meaning, 0.0, high, low_open=True, source=source)


def _covariance(key: str, unit: str, meaning: str) -> Param:
    return Param(key, unit, meaning + ": 3 variances (diagonal, >= 0) or a symmetric row-major 3x3",
                 kind="vector", source="estimate", check=_covariance_problem)


#: ``config/vn100.yaml``: the VN-100 driver node's settings (all required; a node ``~param`` of the same name,
#: ``~rate`` for ``rate_hz``, overrides the file's value).
VN100_SCHEMA = Schema("vn100.yaml", (
    Param("port", "", "serial device (/dev/vn100 from the udev rule; the fake sensor's pty in simulation)",
          kind="string"),
    Param("baud", "baud", "the rate the driver talks to the sensor at; a sensor answering at another standard "
          "rate is switched to it (register 5) at connect: one of " + ", ".join(str(b) for b in SUPPORTED_BAUDS),
          SUPPORTED_BAUDS[0], SUPPORTED_BAUDS[-1], kind="integer", check=_baud_problem),
    Param("save_baud", "", "after switching the sensor to `baud`, write its settings to flash ($VNWNV) so that it "
          "keeps the rate over a power cycle; false: the sensor's flash is never written", kind="boolean",
          source="choice"),
    _positive("probe_timeout", "s", "wait for the answer to the identification read ($VNRRG,01) at each baud rate "
              "tried, plus 2000 bit times of that rate; 3 tries at `baud`, 1 at each other rate", 1.0),
    Param("rate_hz", "Hz", "binary output rate: 800 Hz / an integer divisor (800, 400, 200, 160, 100, ...)", 0.0,
          800.0, low_open=True, source="choice", check=_rate_problem),
    Param("frame_id", "", "frame of the published sensor_msgs/Imu", kind="string"),
    _positive("command_timeout", "s", "wait for each ASCII reply ($VNRRG/$VNWRG); each command is tried 3 times",
              10.0),
    _positive("reconnect_initial_delay", "s", "link lost: the first reconnection attempt is immediate, the second "
              "follows after this delay, which doubles after each failed attempt", 60.0),
    _positive("reconnect_max_delay", "s", "longest wait between reconnection attempts (cap of the doubling "
              "back-off)", 60.0),
    _positive("read_timeout", "s", "pyserial read timeout (one read blocks at most this long)", 1.0),
    _positive("stale_timeout", "s", "no valid packet for this long: link lost, /imu/data stops, reconnect", 10.0),
    _positive("max_angular_rate", "rad/s", "plausibility: largest rate per axis (gyro range 2000 deg/s + 5 %)",
              2.0 * math.radians(2000.0), source=""),
    _positive("max_acceleration", "m/s^2", "plausibility: largest specific force per axis (range 16 g + 5 %)",
              2.0 * 16.0 * 9.80665, source=""),
    _positive("quaternion_norm_tolerance", "", "plausibility: largest deviation of the quaternion's norm from 1", 0.1),
    _positive("max_angular_acceleration", "rad/s^2", "plausibility: fastest change of the body's angular rate",
              1e5, source="estimate"),
    _positive("angular_rate_change_margin", "rad/s", "allowance on top of it for gyro noise and bias steps", 10.0,
              source="estimate"),
    Param("rate_change_confirm_samples", "", "consecutive agreeing samples that confirm a fast rate change", 1,
          100, kind="integer", source="choice"),
    _covariance("orientation_covariance_diagonal", "rad^2", "sensor_msgs/Imu orientation covariance"),
    _covariance("angular_velocity_covariance_diagonal", "(rad/s)^2", "sensor_msgs/Imu angular velocity covariance"),
    _covariance("linear_acceleration_covariance_diagonal", "(m/s^2)^2",
                "sensor_msgs/Imu linear acceleration covariance"),
))

#: key -> checker(value, key) of every key of vn100.yaml (all required): :meth:`Param.read` of
#: :data:`VN100_SCHEMA`.
VN100_KEYS: Dict[str, Callable[[Any, str], Any]] = {param.key: param.read for param in VN100_SCHEMA.params}


def vn100_settings_from_dict(tree: Mapping[str, Any], overrides: Optional[Mapping[str, Any]] = None,
                             override_names: Optional[Mapping[str, str]] = None) -> Dict[str, Any]:
    """Checked settings from a parsed vn100.yaml, with ``overrides`` (e.g. ROS ``~params``) taking precedence;
    every value, from the file or an override, is read through :data:`VN100_SCHEMA`.

    An error in an overriding value names where it came from, not only the file's key: ``override_names``
    maps a key to its source (default ``~<key>``), e.g. ``{"rate_hz": "~rate"}`` gives "parameter '~rate
    (overrides rate_hz)'"."""
    merged = dict(tree)
    merged.update(overrides or {})
    params = VN100_SCHEMA.params
    check_keys(merged, "", [p.key for p in params], [p.key for p in params if p.required], what="vn100 parameter")
    settings = {}
    for param in params:
        label = param.key
        if overrides and param.key in overrides:
            label = "%s (overrides %s)" % ((override_names or {}).get(param.key, "~" + param.key), param.key)
        settings[param.key] = param.read(merged[param.key], label) if param.key in merged else param.default
    if settings["reconnect_initial_delay"] > settings["reconnect_max_delay"]:
        raise ParameterError("parameter 'reconnect_initial_delay' = %g must not exceed 'reconnect_max_delay' = %g"
                             % (settings["reconnect_initial_delay"], settings["reconnect_max_delay"]))
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
