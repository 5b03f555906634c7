"""Typed, validated configuration of the attitude controller (``config/controller.yaml``).

Paper section "Attitude Controller Design":

- gains K_p, K_i, K_d, K_aw of the control law, eq. (pid);
- the torque limit tau_max of eq. (sat) (2 N m in the paper);
- the stroke-cycle timing: maximum power-stroke duration t_pow^max (0.5 s) and recovery duration
  t_rec >= 2 t_pow^max (section "Power and Recovery Stroke Cycle");
- the control period dt (100 Hz, the integrator step of section "Simulation Validation");
- the two leg pairs that alternate between power and recovery strokes.

The paper gives two gain sets, both stored in ``config/controller.yaml``:

- ``simulation`` (section "Simulation Validation"): K_p = 5, K_i = 0.15, K_d = 1, K_aw = 0.25, t_rec = 1.5 s;
- ``experiment`` (section "Experimental Setup"): K_p = 10, K_i = 3, K_d = 0.5, K_aw = 0.25, t_rec = 1.5 s.

Leg pairs: the paper calls its diagonal pairs "(1,2)" and "(3,4)", but with its mirroring matrices
M_i (eq. M_legs) legs 1 and 2 sit at the same (rear) end of the body on opposite sides, so (1,2) is not
diagonal. The intent (diagonal pairs) is kept: the default pairs are (1,3) and (2,4), and the pairs are
a configuration value. The FIRST pair plays the role of the paper's "(1,2)": it starts with a
half-duration recovery.

Every constructor validates its arguments and raises :class:`~quadruped_common.config.ParameterError`
(a ValueError) naming the offending value, so a half-valid configuration never exists.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional

from quadruped_common.config import ParameterError, load_config, number
from quadruped_common.robot import DEFAULT_LEG_PAIRS, LegPairs, leg_pairs
from quadruped_common.tunables import bounds as tunable_bounds
from quadruped_control.control.strokes import SCHEMES, CoordinatedParams

__all__ = [
    "ControllerConfig",
    "DEFAULT_GAIN_SET",
    "Gains",
    "GAIN_SET_KEYS",
    "apply_tunables",
    "ParameterError",
    "controller_config_from_dict",
    "load_controller_config",
]

#: Gain set used when none is named (the paper's simulation gains).
DEFAULT_GAIN_SET = "simulation"

#: Keys a named gain set in controller.yaml may contain (gains plus timing overrides).
GAIN_SET_KEYS = ("k_p", "k_i", "k_d", "k_aw", "t_rec", "t_pow_max", "tau_max")

#: Bounds of the live-tunable values (gains, tau_max, t_rec, t_pow_max): one table for config files and
#: dynamic_reconfigure.
TUNABLE_BOUNDS = tunable_bounds()

#: Default bound on |z|, rad s (see ControllerConfig.integral_limit and config/controller.yaml).
DEFAULT_INTEGRAL_LIMIT = 10.0
#: Default largest accepted |omega| per axis, rad/s: the VN-100's range, 2000 deg/s (datasheet), plus 5 %.
DEFAULT_MAX_ANGULAR_RATE = 36.652

#: Slack for the cross-parameter rule t_rec >= 2 t_pow_max (values typed in decimal).
_TIMING_SLACK = 1e-9


def _finite(name: str, value: Any, low: float = 0.0, low_open: bool = False,
            high: float = math.inf) -> float:
    """``value`` as a float, with a ParameterError unless it is a finite number in range."""
    return number(value, name, low, high, low_open=low_open)


def _tunable(name: str, value: Any, tunable: Optional[str] = None) -> float:
    """A live-tunable value within the bounds of :data:`quadruped_common.tunables.TUNABLES` (the same
    bounds as the dynamic_reconfigure definition cfg/AttitudeController.cfg); ``name`` is used in errors,
    ``tunable`` (default ``name``) picks the bounds."""
    low, high = TUNABLE_BOUNDS[tunable or name]
    return number(value, name, low, high)


@dataclass(frozen=True)
class Gains:
    """Scalar gains of the control law eq. (pid): K_p (N m), K_i (N m / s), K_d (N m s), K_aw (1/(N m)).

    All must be finite and within the bounds of the live-tuning definition
    (:data:`quadruped_common.tunables.TUNABLES`, also cfg/AttitudeController.cfg): non-negative (a
    negative gain destabilises the loop) and below an upper bound (a gain of 1e300 overflows).
    """

    k_p: float
    k_i: float
    k_d: float
    k_aw: float

    def __post_init__(self) -> None:
        for name in ("k_p", "k_i", "k_d", "k_aw"):
            object.__setattr__(self, name, _tunable(name, getattr(self, name)))

    def replace(self, **changes: float) -> "Gains":
        """A copy with some gains changed (validated)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class ControllerConfig:
    """All parameters of the attitude controller (paper section "Attitude Controller Design").

    - ``gains``: K_p, K_i, K_d, K_aw of eq. (pid).
    - ``tau_max``: torque magnitude limit of eq. (sat), N m (paper: 2 N m).
    - ``t_rec``: recovery-stroke duration, s (paper: 1.5 s; 1.0 s in some experiments).
    - ``t_pow_max``: maximum power-stroke duration t_pow^max, s (paper: 0.5 s). The paper requires
      t_rec >= 2 t_pow^max; this is enforced.
    - ``dt``: nominal control period, s (100 Hz). Used for the first step and to clip irregular steps.
    - ``pairs``: the two leg pairs; the first starts with a half-duration recovery (the paper's "(1,2)").
    - ``normalize_force_direction``: False keeps f_i = tau_hat x r_hat as written in the paper (its norm
      is sin of the angle between tau_i and r_i, which scales that leg's torque by sin^2); True divides
      by that norm so every leg delivers |tau_i| (see :mod:`quadruped_control.control.allocation`).
    - ``gyroscopic_feedforward``, ``buoyancy_feedforward``: include the feedforward terms
      omega x I omega and -tau_buoyancy of eq. (pid) (paper: both on).
    - ``integral_limit``: bound on the norm of the integral state z of eq. (pid), rad s (not in the
      paper, which relies on K_aw only). Always on: it bounds z whatever the gains and inputs.
    - ``max_angular_rate``: largest |omega| per axis a step accepts, rad/s (a backstop behind the
      supervisor's sensor-range check; it bounds omega x I omega).
    - ``max_step_factor``: irregular steps are integrated with the elapsed time clipped to
      [0, max_step_factor * dt] (a stalled loop must not inject a huge integral increment).
    - ``rotation_tolerance``: largest |R^T R - I| accepted for measured and desired attitudes.
    - ``stroke_scheme``: 'paper' (the paper's stroke cycle) or 'coordinated'; ``coordinated``: the
      parameters of the latter (:mod:`quadruped_control.control.strokes`).
    """

    gains: Gains
    tau_max: float = 2.0
    t_rec: float = 1.5
    t_pow_max: float = 0.5
    dt: float = 0.01
    pairs: LegPairs = DEFAULT_LEG_PAIRS
    normalize_force_direction: bool = False
    gyroscopic_feedforward: bool = True
    buoyancy_feedforward: bool = True
    integral_limit: float = DEFAULT_INTEGRAL_LIMIT
    max_angular_rate: float = DEFAULT_MAX_ANGULAR_RATE
    max_step_factor: float = 5.0
    rotation_tolerance: float = 1e-6
    stroke_scheme: str = "paper"
    coordinated: CoordinatedParams = dataclasses.field(default_factory=CoordinatedParams)

    def __post_init__(self) -> None:
        if not isinstance(self.gains, Gains):
            raise ParameterError("gains must be a Gains instance, got %r" % (self.gains,))
        set_ = object.__setattr__
        set_(self, "tau_max", _tunable("tau_max", self.tau_max))
        set_(self, "t_rec", _tunable("t_rec", self.t_rec))
        set_(self, "t_pow_max", _tunable("t_pow_max", self.t_pow_max))
        set_(self, "dt", _finite("dt", self.dt, low_open=True, high=1.0))
        set_(self, "max_step_factor", _finite("max_step_factor", self.max_step_factor, low=1.0, high=1000.0))
        set_(self, "rotation_tolerance", _finite("rotation_tolerance", self.rotation_tolerance,
                                                 low_open=True, high=0.1))
        if self.t_rec < 2.0 * self.t_pow_max - _TIMING_SLACK:
            raise ParameterError("t_rec = %g s must be at least 2 t_pow_max = %g s (paper, section 'Power and "
                                 "Recovery Stroke Cycle')" % (self.t_rec, 2.0 * self.t_pow_max))
        if self.t_pow_max < self.dt - _TIMING_SLACK:
            raise ParameterError("t_pow_max = %g s is shorter than one control period dt = %g s"
                                 % (self.t_pow_max, self.dt))
        set_(self, "pairs", leg_pairs(self.pairs))
        for name in ("normalize_force_direction", "gyroscopic_feedforward", "buoyancy_feedforward"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError("%s must be true or false, got %r" % (name, getattr(self, name)))
        if self.stroke_scheme not in SCHEMES:
            raise ParameterError("stroke.scheme must be one of %s, got %r" % (", ".join(SCHEMES), self.stroke_scheme))
        if not isinstance(self.coordinated, CoordinatedParams):
            raise ParameterError("coordinated must be a CoordinatedParams instance, got %r" % (self.coordinated,))
        set_(self, "integral_limit", _finite("integral_limit", self.integral_limit, low_open=True, high=1e3))
        set_(self, "max_angular_rate", _finite("max_angular_rate", self.max_angular_rate, low_open=True, high=100.0))

    @property
    def max_step(self) -> float:
        """Largest elapsed time integrated in one step, s."""
        return self.max_step_factor * self.dt

    def replace(self, **changes: Any) -> "ControllerConfig":
        """A validated copy with some fields changed (live reconfigure)."""
        return dataclasses.replace(self, **changes)

    def with_gains(self, gains: Optional[Gains] = None, **changes: float) -> "ControllerConfig":
        """A validated copy with new gains: a whole :class:`Gains` and/or single ones (``k_p=...``)."""
        new_gains = self.gains if gains is None else gains
        if changes:
            new_gains = new_gains.replace(**changes)
        return dataclasses.replace(self, gains=new_gains)


def apply_tunables(config: ControllerConfig, values: Mapping[str, Any]) -> ControllerConfig:
    """``config`` with the live-tunable values (k_p, k_i, k_d, k_aw, tau_max, t_rec, t_pow_max; any
    subset) replaced, validated as a whole: a ParameterError for NaN, out-of-range values (the
    reconfigure bounds) or t_rec < 2 t_pow_max, and then nothing is changed."""
    unknown = sorted(set(values) - set(TUNABLE_BOUNDS))
    if unknown:
        raise ParameterError("not live-tunable: %s" % ", ".join(unknown))
    gains = {k: v for k, v in values.items() if k in ("k_p", "k_i", "k_d", "k_aw")}
    timing = {k: v for k, v in values.items() if k not in gains}
    return config.with_gains(config.gains.replace(**gains)).replace(**timing)


def _bool(tree: Mapping[str, Any], key: str, default: bool) -> bool:
    value = tree.get(key, default)
    if not isinstance(value, bool):
        raise ParameterError("parameter '%s' must be true or false, got %r" % (key, value))
    return value


def _config_for_set(tree: Mapping[str, Any], name: str, chosen: Any) -> ControllerConfig:
    """The ControllerConfig of gain set ``name`` (its values named by their full key path in errors)."""
    prefix = "gain_sets.%s" % name
    if not isinstance(chosen, Mapping):
        raise ParameterError("parameter '%s' must be a mapping of gains" % prefix)
    for key in chosen:
        if key not in GAIN_SET_KEYS:
            raise ParameterError("unknown parameter '%s.%s' (allowed: %s)" % (prefix, key, ", ".join(GAIN_SET_KEYS)))
    for key in ("k_p", "k_i", "k_d", "k_aw"):
        if key not in chosen:
            raise ParameterError("missing parameter '%s.%s'" % (prefix, key))
    for key in GAIN_SET_KEYS:  # every value of the set against the live-tuning bounds, by its own name
        if key in chosen:
            _tunable("%s.%s" % (prefix, key), chosen[key], key)

    stroke = tree.get("stroke", {}) or {}
    if not isinstance(stroke, Mapping) or sorted(set(stroke) - {"scheme", "coordinated"}):
        raise ParameterError("parameter 'stroke' must be a mapping with keys scheme, coordinated, got %r" % (stroke,))
    coordinated_tree = stroke.get("coordinated", {}) or {}
    if not isinstance(coordinated_tree, Mapping):
        raise ParameterError("parameter 'stroke.coordinated' must be a mapping, got %r" % (coordinated_tree,))
    known = {f.name for f in dataclasses.fields(CoordinatedParams)}
    if sorted(set(coordinated_tree) - known):
        raise ParameterError("unknown parameters stroke.coordinated.%s (allowed: %s)"
                             % (sorted(set(coordinated_tree) - known), ", ".join(sorted(known))))

    def timing(key: str, default: float) -> Any:
        return chosen.get(key, tree.get(key, default))

    try:
        return ControllerConfig(
            gains=Gains(k_p=chosen["k_p"], k_i=chosen["k_i"], k_d=chosen["k_d"], k_aw=chosen["k_aw"]),
            tau_max=timing("tau_max", 2.0),
            t_rec=timing("t_rec", 1.5),
            t_pow_max=timing("t_pow_max", 0.5),
            dt=tree.get("dt", 0.01),
            pairs=tree.get("pairs", DEFAULT_LEG_PAIRS),
            normalize_force_direction=_bool(tree, "normalize_force_direction", False),
            gyroscopic_feedforward=_bool(tree, "gyroscopic_feedforward", True),
            buoyancy_feedforward=_bool(tree, "buoyancy_feedforward", True),
            integral_limit=tree.get("integral_limit", DEFAULT_INTEGRAL_LIMIT),
            max_angular_rate=tree.get("max_angular_rate", DEFAULT_MAX_ANGULAR_RATE),
            max_step_factor=tree.get("max_step_factor", 5.0),
            rotation_tolerance=tree.get("rotation_tolerance", 1e-6),
            stroke_scheme=stroke.get("scheme", "paper"),
            coordinated=CoordinatedParams(**coordinated_tree),
        )
    except ParameterError as exc:
        raise ParameterError("gain set '%s': %s" % (name, exc)) from None


def controller_config_from_dict(tree: Mapping[str, Any], gain_set: str = DEFAULT_GAIN_SET) -> ControllerConfig:
    """Build a :class:`ControllerConfig` from a parsed controller.yaml mapping and a gain-set name.

    Top-level keys give the defaults (``tau_max``, ``t_rec``, ``t_pow_max``, ``dt``, ``pairs``, ...);
    ``gain_sets.<name>`` gives k_p, k_i, k_d, k_aw and may override t_rec, t_pow_max and tau_max.
    Every gain set of the file is validated (a bad set is an error even when another one is chosen).
    """
    known_top = {"gain_sets", "tau_max", "t_rec", "t_pow_max", "dt", "pairs", "normalize_force_direction",
                 "gyroscopic_feedforward", "buoyancy_feedforward", "integral_limit", "max_angular_rate",
                 "max_step_factor", "rotation_tolerance", "stroke"}
    for key in tree:
        if key not in known_top:
            raise ParameterError("unknown controller parameter '%s'" % key)
    sets = tree.get("gain_sets")
    if not isinstance(sets, Mapping) or not sets:
        raise ParameterError("missing parameter 'gain_sets' (a mapping of named gain sets)")
    if gain_set not in sets:
        raise ParameterError("unknown gain set %r; available: %s" % (gain_set, ", ".join(sorted(sets))))
    for key in ("tau_max", "t_rec", "t_pow_max"):  # top-level defaults, even where every set overrides them
        if key in tree:
            _tunable(key, tree[key])
    configs = {name: _config_for_set(tree, name, chosen) for name, chosen in sets.items()}
    return configs[gain_set]


def load_controller_config(path: Optional[str] = None, gain_set: str = DEFAULT_GAIN_SET) -> ControllerConfig:
    """Load and validate ``controller.yaml`` (default: the package's ``config/controller.yaml``).

    ``gain_set``: ``'simulation'`` (paper, section "Simulation Validation") or ``'experiment'``
    (section "Experimental Setup"), or any other set defined in the file.
    """
    return load_config(path, "controller.yaml", lambda tree: controller_config_from_dict(tree, gain_set))
