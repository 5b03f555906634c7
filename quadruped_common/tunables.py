"""The live-tunable controller parameters and their bounds: ONE table for two users.

* ``cfg/AttitudeController.cfg`` (dynamic_reconfigure, rqt_reconfigure sliders) builds its parameter
  definitions from :data:`TUNABLES` at catkin build time;
* :mod:`quadruped_control.control.controller_config` validates the same values from ``config/controller.yaml``
  (gain sets, defaults) and from every live change against :func:`bounds`.

So a gain that the reconfigure GUI cannot set is also refused in a file, and vice versa. This module
imports nothing but the standard library (the .cfg generator runs it before the workspace exists).

Bounds (paper section "Attitude Controller Design"; the paper's gain sets are K_p 5..10, K_i
0.15..3, K_d 0.5..1, K_aw 0.25, tau_max 2 N m, t_rec 1.0..1.5 s, t_pow_max 0.5 s):

* gains: non-negative, upper bounds about 5-60x the paper's values (room to tune, not to type 1e300);
  K_p at least 0.1 N m (a controller without proportional action does not regulate, yet would run armed);
* tau_max: [0.1, 5] N m (0 would command no torque at all: the robot armed but disabled, which a
  configuration must not do silently; the hold is the way to stop strokes; 5 N m is beyond what four
  paws can make);
* t_rec [0.2, 5] s, t_pow_max [0.1, 2.5] s: a few control periods up to a few paper strokes.
"""
from __future__ import annotations

from collections import namedtuple
from typing import Dict, Tuple

Tunable = namedtuple("Tunable", "name group description default low high")
Tunable.__doc__ = "One live-tunable parameter: name, GUI group, description, default, closed bounds [low, high]."

TUNABLES: Tuple[Tunable, ...] = (
    Tunable("k_p", "gains", "Proportional gain K_p [N m], eq. (pid)", 5.0, 0.1, 50.0),
    Tunable("k_i", "gains", "Integral gain K_i [N m/s], eq. (pid)", 0.15, 0.0, 20.0),
    Tunable("k_d", "gains", "Derivative gain K_d [N m s], eq. (pid)", 1.0, 0.0, 20.0),
    Tunable("k_aw", "gains", "Anti-windup gain K_aw [1/(N m)], eq. (pid)", 0.25, 0.0, 10.0),
    Tunable("tau_max", "gains", "Torque magnitude limit tau_max [N m], eq. (sat)", 2.0, 0.1, 5.0),
    Tunable("t_rec", "stroke", "Recovery stroke duration t_rec [s] (>= 2 t_pow_max)", 1.5, 0.2, 5.0),
    Tunable("t_pow_max", "stroke", "Maximum power stroke duration t_pow_max [s]", 0.5, 0.1, 2.5),
)

GAIN_NAMES: Tuple[str, ...] = ("k_p", "k_i", "k_d", "k_aw")


def bounds() -> Dict[str, Tuple[float, float]]:
    """name -> (low, high) of every tunable parameter (closed interval)."""
    return {t.name: (t.low, t.high) for t in TUNABLES}
