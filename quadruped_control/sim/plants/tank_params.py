"""The tank plant's parameters: ONE schema, the dataclass it declares, and the strict loader of tank.yaml.

Each parameter is declared once, as a field of :class:`TankParams` whose metadata is its :class:`TankParameter`:
its name (the field's, and the key in ``config/tank.yaml``, under its section), unit, default, closed or open
range, meaning, and the coordinates the identification fits (:class:`Fit`). From that one table:

* :func:`tank_params_from_dict` / :func:`load_tank_params` read tank.yaml (strict types, no unknown keys, the
  ranges; ParameterError naming ``section.name``);
* :meth:`TankParams.__post_init__` checks the same ranges on a set built in code (``with_values``, overrides);
* :func:`fit_coordinates` gives the identification's parameter table
  (:mod:`quadruped_control.studies.identify_parameters`);
* :func:`parameter_table` gives the table of docs/tank_model.md.

The physics of each effect: docs/tank_model.md. Every candidate effect's default is "off": the defaults are
the plant without it, bit for bit.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Dict, Mapping, Optional, Tuple

import numpy as np

from quadruped_common.config import ParameterError, check_keys, load_config
from quadruped_common.schema import Param, range_text

__all__ = ["SCHEMA", "SECTIONS", "Fit", "TankParameter", "TankParams", "fit_coordinates", "load_tank_params",
           "parameter", "parameter_table", "tank_params_from_dict", "yaml_path"]

Vec3 = Tuple[float, float, float]

#: The sections of tank.yaml, in the file's order; the keys under each are the parameters' names.
SECTIONS = ("effects", "suspension", "hydrostatics", "added_mass", "paw_drag", "servos", "appendage_damping",
            "paw_wake", "imu", "tether", "disturbance")

#: The time constants tank.yaml accepts (s): from ten 10 ms steps (a faster relaxation is a damper, not a spring)
#: to nearly three hours (one that never relaxes).
TIME_CONSTANT = (0.1, 10000.0)

_AXES = {(0,): "_x", (1,): "_y", (2,): "_z", (0, 1): "_xy"}


@dataclass(frozen=True)
class Fit:
    """One coordinate the identification fits: the bounds [low, high] of its plausible values (reasons in
    docs/identification.md), the components of a vector parameter it sets (``()``: a scalar; ``(0, 1)``: one value
    for x and y), and ``reciprocal``: it fits 1 / the parameter (0 for 0), so that "off" lies inside its bounds.
    Its name: the parameter's, with the components' axes (``_x``, ``_xy``) and ``_inverse`` for a reciprocal."""

    low: float
    high: float
    components: Tuple[int, ...] = ()
    reciprocal: bool = False


@dataclass(frozen=True)
class TankParameter:
    """One tank parameter: ``name`` (set from its field), ``section`` of tank.yaml, ``unit``, ``meaning``, its
    ``default`` and range [low, high] (``low_open`` / ``high_open``: that end excluded; per component for a vector),
    ``required`` in tank.yaml, ``check``: a further test of a value (its problem, or None), and ``fit``: the
    identification's coordinates."""

    section: str
    unit: str
    meaning: str
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    required: bool = False
    check: Optional[Callable[[Any], Optional[str]]] = None
    fit: Tuple[Fit, ...] = ()
    name: str = ""
    default: Any = None

    @property
    def path(self) -> str:
        """Its key in tank.yaml, ``section.name``."""
        return "%s.%s" % (self.section, self.name)

    def read(self, value: Any, key: str, what: str = "parameter") -> Any:
        """``value`` as this parameter's type within its range (the common :class:`~quadruped_common.schema.Param`
        reader; numpy values taken as Python ones); ParameterError naming ``key`` otherwise."""
        if isinstance(value, (np.generic, np.ndarray)):
            value = value.tolist()
        default = self.default
        kind = ("boolean" if isinstance(default, bool) else "integer" if isinstance(default, int)
                else "vector" if isinstance(default, tuple) else "number")
        spec = Param(self.path, self.unit, self.meaning, self.low, self.high, kind=kind,
                     length=len(default) if kind == "vector" else None, low_open=self.low_open,
                     high_open=self.high_open, check=self.check)
        result = spec.read(value, key, what)
        return tuple(result) if kind == "vector" else result


def parameter(section: str, default: Any, unit: str, meaning: str, low: float = -math.inf, high: float = math.inf,
              **options: Any) -> Any:
    """The dataclass field of one :class:`TankParameter` (declared where the field is)."""
    spec = TankParameter(section, unit, meaning, low, high, **options)
    return dataclasses.field(default=default, metadata={"tank": spec})


def _switch(meaning: str) -> Any:
    return parameter("effects", True, "", meaning + " (switch; all off is the paper's model)")


def _block_mass(value: float) -> Optional[str]:
    return None if value == 0.0 or value >= 0.01 else "must be 0 (a fixed anchor) or >= 0.01 kg"


def _field_residual(value: Vec3) -> Optional[str]:
    norm = math.sqrt(sum(v * v for v in value))
    return None if norm <= 0.95 else "must have a norm at most 0.95 (the earth's horizontal field), got %g" % norm


@dataclass(frozen=True)
class TankParams:
    """``config/tank.yaml``: the effect switches and parameters, each declared once (module docstring). The order of
    the fitted fields is the order of the identification's parameters (its Morris design depends on it)."""

    suspension: bool = _switch("rope from the hook to the anchor")
    hydrostatics: bool = _switch("torso weight at the centre of mass, torso buoyancy at the centre of buoyancy")
    torso_added_mass: bool = _switch("the torso ellipsoid's 6x6 added mass and its Coriolis terms")
    paw_added_mass: bool = _switch("rho V / 2 per paw, through the leg Jacobian")
    drag: bool = _switch("the paper's paw and body drag (off only for energy checks)")
    center_of_buoyancy: Vec3 = parameter(
        "hydrostatics", (0.0, 0.0, 0.001), "m", "centre of buoyancy relative to the centre of mass, body axes",
        -0.5, 0.5, required=True, fit=(Fit(-0.004, 0.004, (2,)), Fit(-0.002, 0.002, (0,)), Fit(-0.002, 0.002, (1,))))
    hook: Vec3 = parameter("suspension", (0.0, 0.0, 0.077), "m", "the rope's hook, body axes", -1.0, 1.0,
                           required=True, fit=(Fit(0.05, 0.10, (2,)),))
    net_weight: float = parameter("hydrostatics", 1.0, "N", "torso weight minus torso buoyancy", -100.0, 100.0,
                                  required=True, fit=(Fit(0.2, 3.0),))
    rope_length: float = parameter("suspension", 0.5, "m", "unstretched rope from the hook to the anchor", 0.0, 20.0,
                                   low_open=True, required=True, fit=(Fit(0.2, 1.0),))
    rope_stiffness: float = parameter("suspension", 2000.0, "N/m", "the rope's stiffness (tension only)", 0.0, 1e7,
                                      low_open=True, required=True)
    rope_damping: float = parameter("suspension", 150.0, "N s/m", "the rope's damping", 0.0, 1e6, required=True)
    added_mass_scale: float = parameter("added_mass", 1.0, "", "torso added mass over the 4.9 L ellipsoid's",
                                        0.0, 10.0, required=True, fit=(Fit(0.5, 2.0),))
    paw_added_mass_scale: float = parameter("added_mass", 1.0, "", "paw added mass over rho V / 2 of a sphere",
                                            0.0, 10.0, required=True)
    servo_speed_scale: float = parameter("servos", 1.0, "", "servo speed over robot.yaml's no-load speed", 0.0, 1.0,
                                         low_open=True, fit=(Fit(0.5, 1.0),))
    servo_lag_scale: float = parameter("servos", 1.0, "", "factor on simulation.yaml's servo time constant T",
                                       0.0, 100.0, low_open=True, fit=(Fit(1.0, 8.0),))
    paw_drag_scale: float = parameter("paw_drag", 1.0, "", "paw drag coefficient over robot.yaml's C_D", 0.0, 10.0,
                                      fit=(Fit(0.6, 1.6),))
    appendage_damping_linear: Vec3 = parameter(
        "appendage_damping", (0.0, 0.0, 0.0), "N m s/rad", "linear rotational damping of appendages per body axis",
        0.0, 100.0, fit=(Fit(0.0, 0.2, (0, 1)), Fit(0.0, 0.2, (2,))))
    appendage_damping_quadratic: Vec3 = parameter(
        "appendage_damping", (0.0, 0.0, 0.0), "N m s^2/rad^2", "quadratic rotational damping per body axis",
        0.0, 100.0, fit=(Fit(0.0, 0.5, (0, 1)), Fit(0.0, 0.5, (2,))))
    rope_torsion_stiffness: float = parameter("suspension", 0.0, "N m/rad", "the rope's torsion spring (0: off)",
                                              0.0, 1e4, fit=(Fit(0.0, 0.1),))
    rope_torsion_damping: float = parameter("suspension", 0.0, "N m s/rad", "the rope's torsion damper (0: off)",
                                            0.0, 1e4, fit=(Fit(0.0, 0.2),))
    paw_wake_fraction: float = parameter("paw_wake", 0.0, "", "share kappa of a paw's velocity its wake reaches "
                                         "(0: off)", 0.0, 0.95, fit=(Fit(0.0, 0.8),))
    paw_wake_time_constant: float = parameter("paw_wake", 0.3, "s", "the paw wake's time constant tau_w", 0.02, 100.0,
                                              fit=(Fit(0.05, 1.0),))
    paw_wake_body_share: float = parameter("paw_wake", 1.0, "", "share s_b of the body's motion in the velocity "
                                           "that builds the wake", 0.0, 1.0, fit=(Fit(0.0, 1.0),))
    # no upper bound: the identification fits 1 / servo_stall_torque, and a slope near 0 is a stall torque past any
    servo_stall_torque: float = parameter("servos", 0.0, "N m", "stall torque of the servos' torque-speed line "
                                          "(0: speed independent of load)", 0.0, math.inf,
                                          fit=(Fit(0.0, 1.0, reciprocal=True),))
    body_wake_fraction: float = parameter("appendage_damping", 0.0, "", "share kappa_b of the body's rate the "
                                          "water turning with it reaches (0: off)", 0.0, 0.95, fit=(Fit(0.0, 0.8),))
    body_wake_time_constant: float = parameter("appendage_damping", 5.0, "s", "the body wake's time constant tau_b",
                                               0.05, 1000.0, fit=(Fit(0.5, 20.0),))
    # no upper bound either: the identification fits the block's mobility 1 / block_mass
    block_mass: float = parameter("suspension", 0.0, "kg", "the floating block's mass with added mass (0: a fixed "
                                  "anchor)", 0.0, math.inf, check=_block_mass, fit=(Fit(0.0, 5.0, reciprocal=True),))
    block_drag: float = parameter("suspension", 2.0, "N s^2/m^2", "the block's quadratic horizontal drag", 0.0, 1e4,
                                  fit=(Fit(0.2, 20.0),))
    block_tie_stiffness: float = parameter("suspension", 0.0, "N/m", "horizontal stiffness of the block's tie",
                                           0.0, 1000.0, fit=(Fit(0.0, 20.0),))
    paw_buoyancy_offset: float = parameter("hydrostatics", 0.0, "N", "each paw's buoyancy beyond robot.yaml's "
                                           "(the plant's only)", -1.0, 1.0, fit=(Fit(-0.05, 0.13),))
    servo_dead_band: float = parameter("servos", 0.0, "rad", "half-width of the error the servos ignore (0: none)",
                                       0.0, 0.1, fit=(Fit(0.0, 0.02),))
    hook_friction_arm: float = parameter("suspension", 0.0, "m", "mu r: the tie's Coulomb torque over the rope's "
                                         "static tension (0: off)", 0.0, 0.05, fit=(Fit(0.0, 0.004),))
    hook_friction_angle: float = parameter("suspension", 0.005, "rad", "the tie's presliding angle theta_p",
                                           0.001, 0.5)
    hook_friction_static_ratio: float = parameter("suspension", 1.0, "", "the tie's static over sliding friction",
                                                  1.0, 3.0, fit=(Fit(1.0, 2.0),))
    hook_friction_stribeck_rate: float = parameter("suspension", 0.02, "rad/s", "the rate below which the static "
                                                   "friction holds", 1e-4, 1.0, fit=(Fit(0.01, 0.3),))
    hook_friction_roll_ratio: float = parameter("suspension", 1.0, "", "the tie's friction about roll over the one "
                                                "about the other axes", 0.1, 10.0, fit=(Fit(0.25, 4.0),))
    hook_friction_wrap: float = parameter("suspension", 0.0, "1/rad", "capstan coefficient mu_w of the tether "
                                          "wound round the rope (0: off)", 0.0, 1.0, fit=(Fit(0.0, 0.5),))
    imu_field_residual: Vec3 = parameter(
        "imu", (0.0, 0.0, 0.0), "earth's horizontal field", "uncalibrated field at the IMU, body axes (0: the true "
        "heading)", -0.95, 0.95, check=_field_residual,
        fit=(Fit(-0.5, 0.5, (0,)), Fit(-0.5, 0.5, (1,)), Fit(-0.5, 0.5, (2,))))
    tether_stiffness: float = parameter("tether", 0.0, "N m/rad", "the tether's bend that never relaxes (0: off)",
                                        0.0, 2.0, fit=(Fit(0.0, 0.05),))
    tether_relaxing_stiffness: float = parameter("tether", 0.0, "N m/rad", "the tether's bend that fades (0: off)",
                                                 0.0, 2.0, fit=(Fit(0.0, 0.5),))
    tether_relaxation_time: float = parameter("tether", 10.0, "s", "the tether bend's relaxation time", *TIME_CONSTANT,
                                              fit=(Fit(1.0, 120.0),))
    rope_torsion_relaxing_stiffness: float = parameter("suspension", 0.0, "N m/rad", "the torsion's relaxing "
                                                       "branch k_r (0: off)", 0.0, 1e4, fit=(Fit(0.0, 0.1),))
    rope_torsion_relaxation_time: float = parameter("suspension", 10.0, "s", "the relaxing branch's time tau_r",
                                                    *TIME_CONSTANT, fit=(Fit(1.0, 120.0),))
    disturbance_torque_std: float = parameter("disturbance", 0.0, "N m", "the tank's disturbance torque, standard "
                                              "deviation per world axis (0: a still tank)", 0.0, 0.4)
    disturbance_correlation_time: float = parameter("disturbance", 10.0, "s", "its correlation time tau_d",
                                                    *TIME_CONSTANT)
    disturbance_seed: int = parameter("disturbance", 0, "", "the seed of its generator", 0, 2 ** 32 - 1)

    def __post_init__(self) -> None:
        for spec in SCHEMA:
            spec.read(getattr(self, spec.name), spec.name, what="tank parameter")

    @property
    def disturbed(self) -> bool:
        """Is the tank not still (a disturbance torque above 0)?"""
        return self.disturbance_torque_std > 0.0

    @property
    def heading_disturbed(self) -> bool:
        """Does the IMU report a heading other than the true one (a residual field at the IMU)?"""
        return any(float(v) != 0.0 for v in self.imu_field_residual)

    def for_trial(self, seed: int) -> "TankParams":
        """This tank for a trial of seed ``seed``: itself for seed 0 or a still tank; otherwise the same tank pushed
        by another disturbance, its seed drawn from (``disturbance_seed``, ``seed``) by numpy's SeedSequence."""
        if seed == 0 or not self.disturbed:
            return self
        state = np.random.SeedSequence([int(self.disturbance_seed), int(seed)]).generate_state(1)
        return replace(self, disturbance_seed=int(state[0]))

    def with_values(self, **values: Any) -> "TankParams":
        """A copy with some fields replaced (identification, tests)."""
        return replace(self, **values)


def _schema() -> Tuple[TankParameter, ...]:
    out = []
    for f in dataclasses.fields(TankParams):
        out.append(replace(f.metadata["tank"], name=f.name, default=f.default))
    return tuple(out)


#: Every tank parameter, in the dataclass's order: the one table (module docstring).
SCHEMA: Tuple[TankParameter, ...] = _schema()
_BY_NAME: Dict[str, TankParameter] = {spec.name: spec for spec in SCHEMA}


def yaml_path(name: str) -> str:
    """The tank.yaml key (``section.name``) of parameter ``name``."""
    return _BY_NAME[name].path


def fit_coordinates() -> Tuple[Tuple[str, TankParameter, Fit], ...]:
    """The identification's coordinates in the schema's order: (name, parameter, fit)."""
    return tuple((spec.name + _AXES.get(fit.components, "") + ("_inverse" if fit.reciprocal else ""), spec, fit)
                 for spec in SCHEMA for fit in spec.fit)


def tank_params_from_dict(data: Mapping[str, Any]) -> TankParams:
    """Validate a parsed tank.yaml tree against :data:`SCHEMA` (strict types, no unknown keys, the ranges) into
    :class:`TankParams`; ParameterError naming the key (``section.name``) otherwise."""
    required = sorted({spec.section for spec in SCHEMA if spec.required})
    check_keys(data, "", SECTIONS, required=required)
    values: Dict[str, Any] = {}
    for section in SECTIONS:
        specs = [spec for spec in SCHEMA if spec.section == section]
        tree = data.get(section)
        tree = {} if tree is None and section not in required else tree  # an empty optional section: its defaults
        check_keys(tree, section, [spec.name for spec in specs], required=[s.name for s in specs if s.required])
        for spec in specs:
            if spec.name in tree:
                values[spec.name] = spec.read(tree[spec.name], spec.path)
    return TankParams(**values)


def load_tank_params(path: Optional[str] = None, tree: Optional[Mapping[str, Any]] = None) -> TankParams:
    """:class:`TankParams` from ``config/tank.yaml`` (or ``path``/``tree``) through the strict loader
    (:mod:`quadruped_common.config`); ParameterError naming the file and the key if malformed."""
    if tree is not None:
        try:
            return tank_params_from_dict(tree)
        except ParameterError as exc:
            raise ParameterError("%s: %s" % (path or "tank parameters", exc)) from None
    return load_config(path, "tank.yaml", tank_params_from_dict)


def _range_text(spec: TankParameter) -> str:
    return range_text(spec.low, spec.high, spec.low_open, spec.high_open)


def parameter_table() -> str:
    """Every tank parameter as a Markdown table, from :data:`SCHEMA` (docs/tank_model.md holds this table,
    and a test keeps the two equal): tank.yaml key, unit, range, default, what it means, identification bounds."""
    lines = ["| tank.yaml key | unit | range | default | meaning | identified as [bounds] |",
             "|---|---|---|---|---|---|"]
    for spec in SCHEMA:
        fits = ", ".join("`%s` [%g, %g]" % (name, fit.low, fit.high)
                         for name, owner, fit in fit_coordinates() if owner is spec)
        default = list(spec.default) if isinstance(spec.default, tuple) else spec.default
        lines.append("| `%s` | %s | %s | %s | %s | %s |" % (spec.path, spec.unit or "-", _range_text(spec),
                                                          default, spec.meaning.replace("|", "/"), fits or "-"))
    return "\n".join(lines) + "\n"
