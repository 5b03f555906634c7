"""``config/safety.yaml``: what the control supervisor checks before arming and how it moves the legs safely.

Read through :data:`SAFETY_SCHEMA` (one declaration per key, also docs/configuration.md). The tether
failsafe's timeout and action stay node parameters (``~heartbeat_timeout``, ``~tether_action``) because they
differ between the robot on the tank's rope and the simulated robot, which their launch files set.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Tuple

from quadruped_common.config import load_config
from quadruped_common.schema import Param, Schema
from quadruped_control.control.servo_watch import TrackingSettings

#: What a disarm does to the servos: keep them powered at their last pulse (hold), or switch every output off.
DISARM_ACTIONS = ("hold", "limp")
#: What a health source's hazard does while armed: report only, disarm (the servos hold), or disarm and go limp.
HEALTH_ACTIONS = ("warn", "disarm", "limp")
#: The health sources (``health/<name>``) with a hazard to act on; health/depth reports measurement faults only
#: (every one is reported and refuses arming, none stops the robot).
HEALTH_SOURCES = ("battery", "leak")

#: The IB53BHU's no-load speed (config/robot.yaml servo.no_load_speed_rpm, 95 rpm), rad/s: the soft start's bound
#: must stay below it (its range ends at 9.9).
_NO_LOAD_SPEED = 95.0 * math.pi / 30.0

SAFETY_SCHEMA = Schema("safety.yaml", (
    Param("soft_start.max_joint_speed", "rad/s", "largest joint speed commanded while the legs travel from where "
          "they are to the nominal pose on arming, and while they retrace to it in a hold (10 % of the servos' "
          "no-load speed)", 0.0, round(_NO_LOAD_SPEED, 1), low_open=True, default=1.0, source="choice"),
    Param("soft_start.tolerance", "rad", "legs whose every joint is this close to the nominal pose on arming start "
          "stroking at once (a step this small at full servo speed takes under 10 ms)", 0.0, 0.2,
          default=0.05, source="choice"),
    Param("arming.require_outputs", "", "arming needs pwm_node's outputs_state: outputs enabled, no e-stop, the chip "
          "answering (false only for a controller run without pwm_node)", kind="boolean", default=True,
          source="choice"),
    Param("arming.max_outputs_state_age", "s", "an outputs_state older than this is not evidence (pwm_node "
          "publishes it at 5 Hz)", 0.0, 10.0, low_open=True, default=1.0, source="choice"),
    Param("disarm_action", "", "what a disarm does to the servos: hold (powered at the last pulse) or limp (every "
          "output off; enable them again before arming)", kind="string", choices=DISARM_ACTIONS, default="hold",
          source="choice"),
    Param("tracking.time_constant", "s", "the servo model's first-order lag (the simulated servo's, "
          "simulation.yaml)", 0.0, 1.0, default=0.03, source="estimate"),
    Param("tracking.speed_scale", "", "fraction of robot.yaml's no-load speed the model's servos reach", 0.05, 1.0,
          default=1.0, source="estimate"),
    Param("tracking.latency", "s", "a reading is compared with where the model was over this span before its stamp "
          "(command to chip, reading back)", 0.0, 0.5, low_open=True, default=0.03, source="choice"),
    Param("tracking.window", "s", "span of the tracking error's RMS", 0.0, 10.0, low_open=True, default=0.5,
          source="choice"),
    Param("tracking.bound", "rad", "a joint whose error RMS is above this is reported (healthy simulated joints "
          "reach 0.015 rad on a quiet machine, 0.05 rad on a loaded one; docs/faults.md)", 0.0, 1.0, low_open=True,
          default=0.087,
          source="choice"),
    Param("tracking.warn_after", "s", "above the bound this long: WARN", 0.0, 10.0, default=0.1, source="choice"),
    Param("tracking.error_after", "s", "above the bound this long: ERROR", 0.0, 30.0, default=0.5, source="choice"),
    Param("tracking.report_hold", "s", "a joint stays WARN this long after its RMS falls under the bound", 0.0,
          60.0, default=2.0, source="choice"),
    Param("tracking.hold_on_error", "", "a joint in ERROR makes the controller hold the safe pose", kind="boolean",
          default=False, source="choice"),
    Param("health.max_age", "s", "a health source's last status older than this counts as lost (they publish at "
          "2 Hz; a driver its supervisor restarts is back within about 3 s)", 0.0, 60.0, low_open=True, default=5.0,
          source="choice"),
    Param("health.battery_action", "", "armed, a pack below its critical voltage (health/battery ERROR, reason "
          "critical): warn, disarm or limp", kind="string", choices=HEALTH_ACTIONS, default="disarm", source="choice"),
    Param("health.leak_action", "", "armed, water in the enclosure (health/leak ERROR leak, leak_node): warn, "
          "disarm or limp",
          kind="string", choices=HEALTH_ACTIONS, default="disarm", source="choice"),
))


@dataclass(frozen=True)
class SafetyConfig:
    """The supervisor's settings (:data:`SAFETY_SCHEMA`; SI units)."""

    max_joint_speed: float = SAFETY_SCHEMA["soft_start.max_joint_speed"].default
    soft_start_tolerance: float = SAFETY_SCHEMA["soft_start.tolerance"].default
    require_outputs: bool = SAFETY_SCHEMA["arming.require_outputs"].default
    max_outputs_state_age: float = SAFETY_SCHEMA["arming.max_outputs_state_age"].default
    disarm_action: str = SAFETY_SCHEMA["disarm_action"].default
    tracking: TrackingSettings = TrackingSettings()
    tracking_speed_scale: float = SAFETY_SCHEMA["tracking.speed_scale"].default
    tracking_hold: bool = SAFETY_SCHEMA["tracking.hold_on_error"].default
    health_max_age: float = SAFETY_SCHEMA["health.max_age"].default
    #: source -> action on its ERROR while armed (HEALTH_SOURCES; another source's ERROR disarms)
    health_actions: Tuple[Tuple[str, str], ...] = tuple(
        (name, SAFETY_SCHEMA["health.%s_action" % name].default) for name in HEALTH_SOURCES)

    def health_action(self, source: str) -> str:
        """The action on ``source``'s ERROR while armed."""
        return dict(self.health_actions).get(source, "disarm")


def safety_config_from_dict(tree: Mapping[str, Any]) -> SafetyConfig:
    """A parsed safety.yaml through :data:`SAFETY_SCHEMA` (ParameterError naming the key)."""
    v = SAFETY_SCHEMA.read(tree)
    return SafetyConfig(max_joint_speed=v["soft_start.max_joint_speed"],
                        soft_start_tolerance=v["soft_start.tolerance"],
                        require_outputs=v["arming.require_outputs"],
                        max_outputs_state_age=v["arming.max_outputs_state_age"],
                        disarm_action=v["disarm_action"], health_max_age=v["health.max_age"],
                        tracking=TrackingSettings(time_constant=v["tracking.time_constant"],
                                                  latency=v["tracking.latency"], window=v["tracking.window"],
                                                  bound=v["tracking.bound"], warn_after=v["tracking.warn_after"],
                                                  error_after=v["tracking.error_after"],
                                                  report_hold=v["tracking.report_hold"]),
                        tracking_speed_scale=v["tracking.speed_scale"], tracking_hold=v["tracking.hold_on_error"],
                        health_actions=tuple((name, v["health.%s_action" % name]) for name in HEALTH_SOURCES))


def load_safety_config(path: Optional[str] = None) -> SafetyConfig:
    """Load and validate safety.yaml (default: the package's config/safety.yaml)."""
    return load_config(path, "safety.yaml", safety_config_from_dict)
