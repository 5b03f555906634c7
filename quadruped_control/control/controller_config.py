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

Every key of the file is declared once in :data:`CONTROLLER_SCHEMA` (:mod:`quadruped_common.schema`; its table
is in docs/configuration.md): the gains and the timing from the live-tuning table
:data:`quadruped_common.tunables.TUNABLES`, the ``stroke.coordinated`` keys from
:data:`~quadruped_control.control.strokes.coordinated.COORDINATED_PARAMS`. Every constructor validates its
arguments through the same declarations and raises :class:`~quadruped_common.config.ParameterError` (a
ValueError) naming the offending value, so a half-valid configuration never exists.
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional

from quadruped_common.config import ParameterError, load_config, number
from quadruped_common.robot import DEFAULT_LEG_PAIRS, LegPairs, leg_pairs
from quadruped_common.schema import Param, Schema
from quadruped_common.tunables import GAIN_NAMES, TUNABLES
from quadruped_common.tunables import bounds as tunable_bounds
from quadruped_control.control.strokes import COORDINATED_PARAMS, SCHEMES, CoordinatedParams
from quadruped_control.control.yaw_reference import YAW_REFERENCES

__all__ = [
    "CONTROLLER_SCHEMA",
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

#: Timing keys a gain set may override (the top-level values are their defaults).
_TIMING = ("t_rec", "t_pow_max", "tau_max")
#: Keys a named gain set in controller.yaml may contain (gains plus timing overrides).
GAIN_SET_KEYS = GAIN_NAMES + _TIMING

#: Bounds of the live-tunable values (gains, tau_max, t_rec, t_pow_max): one table for config files and
#: dynamic_reconfigure.
TUNABLE_BOUNDS = tunable_bounds()

#: Default bound on |z|, rad s (see ControllerConfig.integral_limit and config/controller.yaml).
DEFAULT_INTEGRAL_LIMIT = 10.0
#: Default largest accepted |omega| per axis, rad/s: the VN-100's range, 2000 deg/s (datasheet), plus 5 %.
DEFAULT_MAX_ANGULAR_RATE = 36.652

#: Slack for the cross-parameter rule t_rec >= 2 t_pow_max (values typed in decimal).
_TIMING_SLACK = 1e-9


def _tunable(name: str, value: Any) -> float:
    """A live-tunable value within the bounds of :data:`quadruped_common.tunables.TUNABLES` (the same
    bounds as the dynamic_reconfigure definition cfg/AttitudeController.cfg)."""
    low, high = TUNABLE_BOUNDS[name]
    return number(value, name, low, high)


_TUNABLES = {tunable.name: tunable for tunable in TUNABLES}
_UNIT = re.compile(r"\s*\[([^\]]*)\]")  # "[N m]" in a tunable's description


def _tunable_param(key: str, name: str, default: Any = None, note: str = "") -> Param:
    """``key`` declared from the live-tunable ``name`` of TUNABLES: its bounds, and its description's unit
    (in brackets) and meaning (the rest, plus ``note``)."""
    tunable = _TUNABLES[name]
    unit = _UNIT.search(tunable.description)
    return Param(key, unit.group(1) if unit else "", _UNIT.sub("", tunable.description, count=1) + note,
                 tunable.low, tunable.high, default=default, source="paper")


#: ``config/controller.yaml``. A gain set (``gain_sets.<set>``, named freely) gives the gains and may override
#: the timing; an override it does not give reads as the name of the top-level key it defaults to (the
#: builder takes that key's value).
CONTROLLER_SCHEMA = Schema("controller.yaml", (
    *(_tunable_param("gain_sets.<set>." + name, name) for name in GAIN_NAMES),
    *(_tunable_param("gain_sets.<set>." + name, name, default=name, note="; overrides the top-level key in this set")
      for name in _TIMING),
    *(_tunable_param(name, name, _TUNABLES[name].default, note="; default of every gain set")
      for name in ("tau_max", "t_pow_max", "t_rec")),
    Param("dt", "s", "control period: 100 Hz, the integrator step of the paper's simulation", 0.0, 1.0,
          low_open=True, default=0.01, source="paper"),
    Param("pairs", "", "the two leg pairs that alternate power and recovery strokes (a partition of legs 1-4); the "
          "first starts with a half-duration recovery", kind="list",
          default=[list(pair) for pair in DEFAULT_LEG_PAIRS], source="choice"),
    Param("normalize_force_direction", "", "false: force direction tau_hat x r_hat as in the paper; true: divided "
          "by its norm, so that every leg delivers its whole torque", kind="boolean", default=False, source="choice"),
    Param("gyroscopic_feedforward", "", "the term + omega x (I omega) of eq. (pid)", kind="boolean", default=True,
          source="paper"),
    Param("buoyancy_feedforward", "", "the term - tau_buoyancy^B of eq. (pid), from the commanded foot positions",
          kind="boolean", default=True, source="paper"),
    Param("integral_limit", "rad s", "bound on the norm of the integral state z of eq. (pid) (not in the paper)",
          0.0, 1e3, low_open=True, default=DEFAULT_INTEGRAL_LIMIT, source="choice"),
    Param("max_angular_rate", "rad/s", "largest angular rate per axis a step accepts (the VN-100's range, 2000 "
          "deg/s, plus 5 %)", 0.0, 100.0, low_open=True, default=DEFAULT_MAX_ANGULAR_RATE),
    Param("max_step_factor", "", "an irregular step integrates the elapsed time clipped to [0, max_step_factor dt]",
          1.0, 1000.0, default=5.0, source="choice"),
    Param("rotation_tolerance", "", "largest deviation of R^T R from I accepted for a measured or desired attitude",
          0.0, 0.1, low_open=True, default=1e-6, source="choice"),
    Param("stroke.scheme", "", "stroke scheme: paper (the paper's power and recovery cycle) or coordinated "
          "(docs/stroke_schemes.md)", kind="string", choices=SCHEMES, default=SCHEMES[0], source="choice"),
    *COORDINATED_PARAMS,
    Param("yaw_reference", "", "how the controller node reads a setpoint's yaw unless the message names it: "
          "relative (to the heading measured at arming), absolute (world ENU, yaw = magnetic heading: the paper's) "
          "or tilt (roll and pitch only, no torque about the vertical); node parameter ~yaw_reference",
          kind="string", choices=YAW_REFERENCES, default=YAW_REFERENCES[0], source="choice"),
), names={"set": None})

#: key -> declaration of CONTROLLER_SCHEMA (the constructors' checks)
_PARAMS: Dict[str, Param] = {param.key: param for param in CONTROLLER_SCHEMA.params}


def _read(key: str, value: Any) -> Any:
    """``value`` of ``key`` through its declaration in :data:`CONTROLLER_SCHEMA`."""
    return _PARAMS[key].read(value, key)


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
    - ``yaw_reference``: how the supervisor reads an operator's setpoint given without one: 'relative',
      'absolute' or 'tilt' (:mod:`quadruped_control.control.yaw_reference`). The controller itself and the
      offline simulator take world setpoints R_d.
    """

    gains: Gains
    tau_max: float = _PARAMS["tau_max"].default
    t_rec: float = _PARAMS["t_rec"].default
    t_pow_max: float = _PARAMS["t_pow_max"].default
    dt: float = _PARAMS["dt"].default
    pairs: LegPairs = DEFAULT_LEG_PAIRS
    normalize_force_direction: bool = _PARAMS["normalize_force_direction"].default
    gyroscopic_feedforward: bool = _PARAMS["gyroscopic_feedforward"].default
    buoyancy_feedforward: bool = _PARAMS["buoyancy_feedforward"].default
    integral_limit: float = _PARAMS["integral_limit"].default
    max_angular_rate: float = _PARAMS["max_angular_rate"].default
    max_step_factor: float = _PARAMS["max_step_factor"].default
    rotation_tolerance: float = _PARAMS["rotation_tolerance"].default
    stroke_scheme: str = _PARAMS["stroke.scheme"].default
    coordinated: CoordinatedParams = dataclasses.field(default_factory=CoordinatedParams)
    yaw_reference: str = _PARAMS["yaw_reference"].default

    def __post_init__(self) -> None:
        if not isinstance(self.gains, Gains):
            raise ParameterError("gains must be a Gains instance, got %r" % (self.gains,))
        set_ = object.__setattr__
        for name in ("tau_max", "t_rec", "t_pow_max", "dt", "max_step_factor", "rotation_tolerance"):
            set_(self, name, _read(name, getattr(self, name)))
        if self.t_rec < 2.0 * self.t_pow_max - _TIMING_SLACK:
            raise ParameterError("t_rec = %g s must be at least 2 t_pow_max = %g s (paper, section 'Power and "
                                 "Recovery Stroke Cycle')" % (self.t_rec, 2.0 * self.t_pow_max))
        if self.t_pow_max < self.dt - _TIMING_SLACK:
            raise ParameterError("t_pow_max = %g s is shorter than one control period dt = %g s"
                                 % (self.t_pow_max, self.dt))
        set_(self, "pairs", leg_pairs(self.pairs))
        for name in ("normalize_force_direction", "gyroscopic_feedforward", "buoyancy_feedforward"):
            _read(name, getattr(self, name))
        _read("stroke.scheme", self.stroke_scheme)
        _read("yaw_reference", self.yaw_reference)
        if not isinstance(self.coordinated, CoordinatedParams):
            raise ParameterError("coordinated must be a CoordinatedParams instance, got %r" % (self.coordinated,))
        for name in ("integral_limit", "max_angular_rate"):
            set_(self, name, _read(name, getattr(self, name)))

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


def _config_for_set(v: Mapping[str, Any], name: str, chosen: Mapping[str, Any]) -> ControllerConfig:
    """The ControllerConfig of gain set ``name`` from the values ``v`` of :data:`CONTROLLER_SCHEMA`; ``chosen``
    (the set as in the file) says which timing keys the set overrides."""
    prefix = "gain_sets.%s." % name

    def timing(key: str) -> float:
        return v[prefix + key] if key in chosen else v[key]

    try:
        return ControllerConfig(
            gains=Gains(**{key: v[prefix + key] for key in GAIN_NAMES}),
            tau_max=timing("tau_max"),
            t_rec=timing("t_rec"),
            t_pow_max=timing("t_pow_max"),
            dt=v["dt"],
            pairs=v["pairs"],
            normalize_force_direction=v["normalize_force_direction"],
            gyroscopic_feedforward=v["gyroscopic_feedforward"],
            buoyancy_feedforward=v["buoyancy_feedforward"],
            integral_limit=v["integral_limit"],
            max_angular_rate=v["max_angular_rate"],
            max_step_factor=v["max_step_factor"],
            rotation_tolerance=v["rotation_tolerance"],
            stroke_scheme=v["stroke.scheme"],
            coordinated=CoordinatedParams(**{p.key.rsplit(".", 1)[1]: v[p.key] for p in COORDINATED_PARAMS}),
            yaw_reference=v["yaw_reference"],
        )
    except ParameterError as exc:
        raise ParameterError("gain set '%s': %s" % (name, exc)) from None


def controller_config_from_dict(tree: Mapping[str, Any], gain_set: str = DEFAULT_GAIN_SET) -> ControllerConfig:
    """Build a :class:`ControllerConfig` from a parsed controller.yaml mapping and a gain-set name.

    Top-level keys give the defaults (``tau_max``, ``t_rec``, ``t_pow_max``, ``dt``, ``pairs``, ...);
    ``gain_sets.<name>`` gives k_p, k_i, k_d, k_aw and may override t_rec, t_pow_max and tau_max.
    Every value is read through :data:`CONTROLLER_SCHEMA`, and every gain set of the file is validated (a bad
    set is an error even when another one is chosen).
    """
    sets = tree.get("gain_sets")
    if not isinstance(sets, Mapping) or not sets:
        raise ParameterError("missing parameter 'gain_sets' (a mapping of named gain sets)")
    if gain_set not in sets:
        raise ParameterError("unknown gain set %r; available: %s" % (gain_set, ", ".join(sorted(sets))))
    v = CONTROLLER_SCHEMA.read(tree)
    configs = {name: _config_for_set(v, name, chosen) for name, chosen in sets.items()}
    return configs[gain_set]


def load_controller_config(path: Optional[str] = None, gain_set: str = DEFAULT_GAIN_SET) -> ControllerConfig:
    """Load and validate ``controller.yaml`` (default: the package's ``config/controller.yaml``).

    ``gain_set``: ``'simulation'`` (paper, section "Simulation Validation") or ``'experiment'``
    (section "Experimental Setup"), or any other set defined in the file.
    """
    return load_config(path, "controller.yaml", lambda tree: controller_config_from_dict(tree, gain_set))
