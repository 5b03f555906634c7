"""The simulated robot's safety sensors, no ROS: the water pressure its depth sensor feels and its two LiPo packs.

``sim_node`` writes both into the fake chips the unchanged drivers read: the pressure into the fake MS5837, the
packs' voltages through their dividers into the spare inputs of the fake ADS1115s (``config/hardware.yaml``).

* :class:`DepthModel`: the body's world position z (ENU, REP-103: up) below a mean depth,
  p = surface + rho g (mean_depth - z), the surface pressure above the water;
* :class:`SimulatedPack`: a LiPo pack of ``cells`` cells whose charge falls with the current drawn; terminal
  voltage = cells x resting cell voltage at that charge (:func:`~quadruped_drivers.battery.lipo_open_circuit_voltage`)
  - current x internal resistance; current = idle current + ``amps_per_rad_s`` x the sum of the 12 joint speeds
  (the servos' load: the more the legs move, the more they draw).

Their settings are the ``simulated_robot`` section of ``config/simulation.yaml`` (:data:`SAFETY_SENSOR_PARAMS`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Tuple

from quadruped_common.schema import Param
from quadruped_drivers.battery import lipo_open_circuit_voltage
from quadruped_drivers.hardware_config import BATTERY_PACKS

G = 9.80665

#: Per pack: (capacity Ah, start charge, internal resistance ohm, idle current A, A per rad/s of joint speed).
_PACK_DEFAULTS: Dict[str, Tuple[float, float, float, float, float]] = {
    "motors": (5.0, 0.9, 0.03, 0.5, 0.25),
    "electronics": (5.0, 0.9, 0.05, 1.5, 0.0),
}


def _pack_params(name: str) -> Tuple[Param, ...]:
    capacity, charge, resistance, idle, per_speed = _PACK_DEFAULTS[name]
    key = "simulated_robot.batteries.%s." % name
    return (
        Param(key + "capacity_ah", "Ah", "the simulated %s pack's capacity (a test makes it small to drain it in "
              "seconds)" % name, 0.0, 1000.0, low_open=True, default=capacity, source="estimate"),
        Param(key + "start_charge", "", "its state of charge at start, 0..1", 0.0, 1.0, default=charge,
              source="choice"),
        Param(key + "internal_resistance_ohm", "ohm", "its internal resistance (terminal voltage = open-circuit "
              "voltage - current x this)", 0.0, 10.0, default=resistance, source="estimate"),
        Param(key + "idle_current_a", "A", "current drawn with the legs still", 0.0, 100.0, default=idle,
              source="estimate"),
        Param(key + "amps_per_rad_s", "A/(rad/s)", "more current per rad/s of joint speed, summed over the 12 "
              "joints (the servos' load)", 0.0, 100.0, default=per_speed, source="estimate"),
    )


#: The ``simulated_robot`` section of ``config/simulation.yaml`` (part of its schema, all optional).
SAFETY_SENSOR_PARAMS: Tuple[Param, ...] = (
    Param("simulated_robot.depth_sensor.mean_depth_m", "m", "depth of the simulated body's start position (its "
          "world z moves it from there)", 0.0, 300.0, default=0.5, source="choice"),
    Param("simulated_robot.depth_sensor.temperature_c", "degC", "water temperature the fake MS5837 measures",
          -20.0, 85.0, default=20.0, source="choice"),
    Param("simulated_robot.depth_sensor.noise_counts", "", "uniform noise of the fake MS5837's raw codes, +- "
          "counts (a real chip never repeats a code pair; the driver's stuck check relies on it)", 0, 100000,
          kind="integer", default=8, source="estimate"),
) + tuple(param for name in BATTERY_PACKS for param in _pack_params(name))


@dataclass(frozen=True)
class PackSettings:
    """One simulated pack (:data:`SAFETY_SENSOR_PARAMS`)."""

    capacity_ah: float
    start_charge: float
    internal_resistance_ohm: float
    idle_current_a: float
    amps_per_rad_s: float


@dataclass(frozen=True)
class SafetySensorSettings:
    """The ``simulated_robot`` section of ``config/simulation.yaml``."""

    mean_depth_m: float = 0.5
    temperature_c: float = 20.0
    noise_counts: int = 8
    packs: Dict[str, PackSettings] = field(default_factory=lambda: {
        name: PackSettings(*values) for name, values in _PACK_DEFAULTS.items()})


def safety_sensor_settings(values: Mapping[str, Any]) -> SafetySensorSettings:
    """The settings from a schema's read values (``Schema.read`` of simulation.yaml)."""
    key = "simulated_robot.batteries.%s.%s"
    return SafetySensorSettings(
        mean_depth_m=values["simulated_robot.depth_sensor.mean_depth_m"],
        temperature_c=values["simulated_robot.depth_sensor.temperature_c"],
        noise_counts=values["simulated_robot.depth_sensor.noise_counts"],
        packs={name: PackSettings(*(values[key % (name, part)] for part in (
            "capacity_ah", "start_charge", "internal_resistance_ohm", "idle_current_a", "amps_per_rad_s")))
            for name in BATTERY_PACKS})


class DepthModel:
    """The absolute pressure (Pa) at the sensor for the body's world z (module docstring)."""

    def __init__(self, surface_pa: float, density: float, mean_depth_m: float) -> None:
        if not (math.isfinite(density) and density > 0.0):
            raise ValueError("density must be positive, got %r" % (density,))
        self.surface_pa = float(surface_pa)
        self.density = float(density)
        self.mean_depth_m = float(mean_depth_m)

    def depth(self, z: float) -> float:
        """Depth (m) of a body at world z (0 above the water)."""
        return max(0.0, self.mean_depth_m - float(z))

    def pressure(self, z: float) -> float:
        """Absolute pressure (Pa) of a body at world z."""
        return self.surface_pa + self.density * G * self.depth(z)


class SimulatedPack:
    """A LiPo pack discharging with the current it delivers (module docstring)."""

    def __init__(self, cells: int, settings: PackSettings) -> None:
        if cells < 1:
            raise ValueError("cells must be >= 1")
        self.cells = int(cells)
        self.settings = settings
        self.charge = min(1.0, max(0.0, float(settings.start_charge)))
        self.current_a = settings.idle_current_a

    def step(self, dt: float, joint_speed_sum: float) -> None:
        """Deliver the current of ``joint_speed_sum`` (rad/s, the 12 joints' |speed| summed) for ``dt`` s."""
        speed = float(joint_speed_sum) if math.isfinite(joint_speed_sum) else 0.0
        self.current_a = self.settings.idle_current_a + self.settings.amps_per_rad_s * abs(speed)
        self.charge = max(0.0, self.charge - self.current_a * dt / (3600.0 * self.settings.capacity_ah))

    def set_charge(self, charge: float) -> None:
        """The pack at state of charge ``charge`` (0..1) from now: run flat, or another pack swapped in."""
        self.charge = min(1.0, max(0.0, float(charge)))

    @property
    def voltage(self) -> float:
        """Terminal voltage (V) now: open-circuit voltage at this charge minus the internal resistance's drop."""
        return max(0.0, self.cells * lipo_open_circuit_voltage(self.charge)
                   - self.current_a * self.settings.internal_resistance_ohm)

    def adc_volts(self, divider_ratio: float) -> float:
        """What the pack's divider puts on its ADC input (V)."""
        return self.voltage / divider_ratio


def with_overrides(settings: PackSettings, capacity_ah: Optional[float] = None,
                   start_charge: Optional[float] = None) -> PackSettings:
    """``settings`` with the capacity and start charge replaced where given (sim_node's test parameters)."""
    return PackSettings(capacity_ah if capacity_ah is not None else settings.capacity_ah,
                        start_charge if start_charge is not None else settings.start_charge,
                        settings.internal_resistance_ohm, settings.idle_current_a, settings.amps_per_rad_s)


__all__ = ["DepthModel", "PackSettings", "SAFETY_SENSOR_PARAMS", "SafetySensorSettings", "SimulatedPack",
           "safety_sensor_settings", "with_overrides"]
