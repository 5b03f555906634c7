"""The test-tank plant: the paper's model plus the effects of the tank the experiments ran in.

Equations of motion (body axes, about the centre of mass, nu = (v^B, omega) with v^B = R^T v^W):

    M nu_dot = tau_paper + tau_rope + tau_hydrostatic - C(nu) nu - f_paw(nu)                  (tank)
    dv^W/dt = R (v_dot^B + omega x v^B),  dp/dt = v^W,  dR/dt = R hat(omega)

- ``tau_paper``: the paper's paw drag, body drag and paw buoyancy of eq. (trans), (rot)
  (:meth:`FloatingBaseModel._body_wrench <quadruped_control.sim.plants.paper.FloatingBaseModel._body_wrench>`,
  the plants' shared assembly of the :mod:`quadruped_control.model.hydrodynamics` force laws; paw
  buoyancy's force 4 B_net z_hat is added here).
- M = M_RB + M_A + sum_i M_paw(r_i): rigid body diag(m I, I), the torso's ellipsoid added mass and the
  paws' point added masses rho V / 2 at the foot positions (:mod:`.added_mass`).
- C(nu) nu = Kirchhoff terms of M_RB + M_A (rigid-body gyroscopic and added-mass Coriolis/centripetal,
  Fossen eq. 6.43); f_paw = sum_i m_a (omega x v + omega x (omega x r_i) + 2 omega x c_i) with its
  moments r_i x f_i (paw added mass, :mod:`.added_mass`).
- ``tau_rope`` (:func:`rope_force`): tension-only, stiff and damped rope from the hook h^B to a fixed
  anchor a^W: with d = a - (p + R h), L = |d|, T = max(0, k (L - L_0) + c dL/dt) when L > L_0 (slack
  otherwise); force T d / L at the hook, moment h x R^T (T d / L).
- ``tau_hydrostatic`` (:func:`hydrostatic_wrench`): torso weight W (paws excluded: their net weight is
  the paper's paw buoyancy) down at the centre of mass and torso buoyancy B = W - net_weight up at the
  centre of buoyancy r_cb: force (B - W) z_hat, moment r_cb x (B R^T z_hat).

Candidate effects of the identification against Table 1, each zero (today's model) unless
``config/tank.yaml`` sets it:

- ``tau_appendage`` (:func:`appendage_damping_torque`): rotational damping of what the inertia box
  leaves out (leg links, motor housings, the enclosure's corners sweeping through the water as the body
  turns), per body axis -(c_lin + c_quad |omega|) omega: the linear (skin friction, laminar) plus
  quadratic (form drag, strip theory of appendages at radius r: 1/2 rho C_D A r^3 |omega| omega) damping
  of Fossen, "Handbook of Marine Craft Hydrodynamics and Motion Control" (2011), section 6.4.
- ``tau_torsion`` (:func:`rope_torsion_torque`): the rope and its floating block resist twisting: a
  torque about the rope's (vertical) axis -(k_t theta + c_t omega_z^W), theta the body's twist about the
  world vertical since :meth:`TankModel.attach` (the twist of the swing-twist decomposition of
  R R_0^T), omega_z^W the vertical component of the angular velocity. Acts only with the suspension on.

Each effect has a switch (:class:`TankParams`); with all four off the equations reduce to the paper's
eq. (trans), (rot) (tested). Parameters: ``config/tank.yaml``.
Integration: the model's generic RK4 on SO(3) (``_rk4`` with this class's ``_chart_derivative``, the
chart helpers of :mod:`.rigid_body`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, boolean, check_keys, load_config, number, vector
from quadruped_control.model import hydrodynamics
from quadruped_control.model.kinematics import leg_kinematics_flat
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.added_mass import ellipsoid_added_mass, point_mass_matrix, sphere_added_mass
from quadruped_control.sim.plants.paper import FloatingBaseModel
from quadruped_control.sim.plants.rigid_body import (Mat3, RigidBodyState, StepContext, as_mat3, chart_point, check_dt,
                                                     joint_array)

__all__ = ["TankModel", "TankParams", "appendage_damping_torque", "hydrostatic_wrench", "load_tank_params",
           "rope_force", "rope_torsion_torque", "rope_twist", "torso_ellipsoid"]

Vec3 = Tuple[float, float, float]


@dataclass(frozen=True)
class TankParams:
    """``config/tank.yaml``: effect switches and parameters (see the file for units and reasoning)."""

    suspension: bool = True
    hydrostatics: bool = True
    torso_added_mass: bool = True
    paw_added_mass: bool = True
    #: the paper's paw and body drag (off only for energy checks)
    drag: bool = True
    hook: Vec3 = (0.0, 0.0, 0.077)
    rope_length: float = 0.5
    rope_stiffness: float = 2000.0
    rope_damping: float = 150.0
    net_weight: float = 1.0
    center_of_buoyancy: Vec3 = (0.0, 0.0, 0.001)
    added_mass_scale: float = 1.0
    paw_added_mass_scale: float = 1.0
    #: paw drag coefficient relative to robot.yaml's C_D (the paper's CFD value)
    paw_drag_scale: float = 1.0
    #: servo speed relative to robot.yaml's no-load speed (loaded servos in water are slower)
    servo_speed_scale: float = 1.0
    #: rotational damping of appendages per body axis: linear (N m s/rad), quadratic (N m s^2/rad^2)
    appendage_damping_linear: Vec3 = (0.0, 0.0, 0.0)
    appendage_damping_quadratic: Vec3 = (0.0, 0.0, 0.0)
    #: rope torsion about the vertical: stiffness (N m/rad) and damping (N m s/rad)
    rope_torsion_stiffness: float = 0.0
    rope_torsion_damping: float = 0.0

    def __post_init__(self) -> None:
        for name in ("rope_length", "rope_stiffness"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError("tank %s must be positive and finite, got %r" % (name, value))
        for name in ("rope_damping", "added_mass_scale", "paw_added_mass_scale", "paw_drag_scale",
                     "rope_torsion_stiffness", "rope_torsion_damping"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ParameterError("tank %s must be finite and >= 0, got %r" % (name, value))
        if not (math.isfinite(self.servo_speed_scale) and 0.0 < self.servo_speed_scale <= 1.0):
            raise ParameterError("tank servo_speed_scale must be in (0, 1], got %r" % (self.servo_speed_scale,))
        if not math.isfinite(self.net_weight):
            raise ParameterError("tank net_weight must be finite, got %r" % (self.net_weight,))
        for name in ("hook", "center_of_buoyancy"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(float(v)) for v in value):
                raise ParameterError("tank %s must be 3 finite numbers (m, body frame), got %r" % (name, value))
        for name in ("appendage_damping_linear", "appendage_damping_quadratic"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(float(v)) and float(v) >= 0.0 for v in value):
                raise ParameterError("tank %s must be 3 finite numbers >= 0 (body axes), got %r" % (name, value))

    def with_values(self, **values: Any) -> "TankParams":
        """A copy with some fields replaced (identification, tests)."""
        return replace(self, **values)


def _optional_section(data: Mapping[str, Any], name: str) -> Any:
    """An optional section: absent or empty (YAML null, e.g. ``servos:`` with every key removed) means
    all its defaults; anything else is checked by the caller (a number or a list is still refused)."""
    value = data.get(name)
    return {} if value is None else value


def tank_params_from_dict(data: Mapping[str, Any]) -> TankParams:
    """Validate a parsed tank.yaml tree (strict types, no unknown keys, physically possible ranges,
    wider than the identification's plausible bounds) into :class:`TankParams`; ParameterError naming
    the key otherwise."""
    check_keys(data, "", ("effects", "suspension", "hydrostatics", "added_mass", "paw_drag", "servos",
                          "appendage_damping"),
               required=("suspension", "hydrostatics", "added_mass"))
    effects = check_keys(_optional_section(data, "effects"), "effects",
                         ("suspension", "hydrostatics", "torso_added_mass", "paw_added_mass", "drag"))
    rope = check_keys(data["suspension"], "suspension",
                      ("hook", "length", "stiffness", "damping", "torsion_stiffness", "torsion_damping"),
                      required=("hook", "length", "stiffness", "damping"))
    hydro = check_keys(data["hydrostatics"], "hydrostatics", ("net_weight", "center_of_buoyancy"),
                       required=("net_weight", "center_of_buoyancy"))
    added = check_keys(data["added_mass"], "added_mass", ("scale", "paw_scale"), required=("scale", "paw_scale"))
    paw_drag = check_keys(_optional_section(data, "paw_drag"), "paw_drag", ("scale",))
    servos = check_keys(_optional_section(data, "servos"), "servos", ("speed_scale",))
    appendage = check_keys(_optional_section(data, "appendage_damping"), "appendage_damping", ("linear", "quadratic"))

    def axes(section: Mapping[str, Any], key: str, high: float) -> Vec3:
        return tuple(vector(section.get(key, [0.0, 0.0, 0.0]), "appendage_damping." + key, 3,
                            0.0, high))  # type: ignore[return-value]

    def switch(name: str) -> bool:
        return boolean(effects.get(name, True), "effects." + name)

    return TankParams(
        suspension=switch("suspension"), hydrostatics=switch("hydrostatics"),
        torso_added_mass=switch("torso_added_mass"), paw_added_mass=switch("paw_added_mass"),
        drag=switch("drag"),
        hook=tuple(vector(rope["hook"], "suspension.hook", 3, -1.0, 1.0)),  # type: ignore[arg-type]
        rope_length=number(rope["length"], "suspension.length", 0.0, 20.0, low_open=True),
        rope_stiffness=number(rope["stiffness"], "suspension.stiffness", 0.0, 1e7, low_open=True),
        rope_damping=number(rope["damping"], "suspension.damping", 0.0, 1e6),
        net_weight=number(hydro["net_weight"], "hydrostatics.net_weight", -100.0, 100.0),
        center_of_buoyancy=tuple(vector(hydro["center_of_buoyancy"], "hydrostatics.center_of_buoyancy",
                                        3, -0.5, 0.5)),  # type: ignore[arg-type]
        added_mass_scale=number(added["scale"], "added_mass.scale", 0.0, 10.0),
        paw_added_mass_scale=number(added["paw_scale"], "added_mass.paw_scale", 0.0, 10.0),
        paw_drag_scale=number(paw_drag.get("scale", 1.0), "paw_drag.scale", 0.0, 10.0),
        servo_speed_scale=number(servos.get("speed_scale", 1.0), "servos.speed_scale", 0.0, 10.0, low_open=True),
        appendage_damping_linear=axes(appendage, "linear", 100.0),
        appendage_damping_quadratic=axes(appendage, "quadratic", 100.0),
        rope_torsion_stiffness=number(rope.get("torsion_stiffness", 0.0), "suspension.torsion_stiffness", 0.0, 1e4),
        rope_torsion_damping=number(rope.get("torsion_damping", 0.0), "suspension.torsion_damping", 0.0, 1e4))


def load_tank_params(path: Optional[str] = None, tree: Optional[Mapping[str, Any]] = None) -> TankParams:
    """:class:`TankParams` from ``config/tank.yaml`` (or ``path``/``tree``) through the strict loader
    (:mod:`quadruped_common.config`); ParameterError naming the file and the key if malformed."""
    if tree is not None:
        try:
            return tank_params_from_dict(tree)
        except ParameterError as exc:
            raise ParameterError("%s: %s" % (path or "tank parameters", exc)) from None
    return load_config(path, "tank.yaml", tank_params_from_dict)


def rope_force(hook_world: Sequence[float], hook_velocity: Sequence[float], anchor: Sequence[float],
               length: float, stiffness: float, damping: float) -> Vec3:
    """Rope force on the hook, world frame (N): T d / |d| with d = anchor - hook and
    T = max(0, k (|d| - L_0) + c d|d|/dt) while |d| > L_0, zero when slack (a rope only pulls)."""
    dx, dy, dz = anchor[0] - hook_world[0], anchor[1] - hook_world[1], anchor[2] - hook_world[2]
    distance = math.sqrt(dx * dx + dy * dy + dz * dz)
    if distance <= length:
        return (0.0, 0.0, 0.0)
    ux, uy, uz = dx / distance, dy / distance, dz / distance
    rate = -(ux * hook_velocity[0] + uy * hook_velocity[1] + uz * hook_velocity[2])  # d|d|/dt
    tension = stiffness * (distance - length) + damping * rate
    if tension <= 0.0:
        return (0.0, 0.0, 0.0)
    return (tension * ux, tension * uy, tension * uz)


def hydrostatic_wrench(R: np.ndarray, weight: float, buoyancy: float,
                       center_of_buoyancy: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
    """Torso weight W at the centre of mass and buoyancy B at r_cb: (force world (B - W) z_hat,
    moment about the centre of mass r_cb x (B R^T z_hat), body frame)."""
    up_body = np.asarray(R, dtype=float)[2, :]
    return (np.array([0.0, 0.0, buoyancy - weight]),
            hydrodynamics.torso_buoyancy_torque_matrix(buoyancy, center_of_buoyancy) @ up_body)


def appendage_damping_torque(omega: Sequence[float], linear: Sequence[float],
                             quadratic: Sequence[float]) -> Vec3:
    """tau_appendage = -(c_lin + c_quad |omega|) omega per body axis (N m): linear plus quadratic
    rotational damping of the legs, housings and corners the inertia box leaves out (module docstring)."""
    return tuple(-(c + k * abs(w)) * w for w, c, k in zip(omega, linear, quadratic))  # type: ignore[return-value]


def rope_twist(R: Sequence[float], R0: Sequence[float]) -> float:
    """Twist (rad, [-pi, pi]) of the rotation Q = R R0^T about the world vertical: the angle of the twist
    part of its swing-twist decomposition, 2 atan2(q_z, q_w) = 2 atan2(Q_10 - Q_01, 1 + tr Q).
    ``R``, ``R0``: row-major 3x3 (9 floats)."""
    q10 = R[3] * R0[0] + R[4] * R0[1] + R[5] * R0[2]
    q01 = R[0] * R0[3] + R[1] * R0[4] + R[2] * R0[5]
    trace = sum(R[3 * i] * R0[3 * i] + R[3 * i + 1] * R0[3 * i + 1] + R[3 * i + 2] * R0[3 * i + 2] for i in range(3))
    return 2.0 * math.atan2(q10 - q01, 1.0 + trace)


def rope_torsion_torque(R: Sequence[float], R0: Sequence[float], omega: Sequence[float], stiffness: float,
                        damping: float) -> Vec3:
    """Body-axes torque (N m) of a rope twisted by :func:`rope_twist` from its untwisted attitude ``R0``:
    T = -(k_t theta + c_t omega_z^W) about the world vertical, i.e. T R^T z_hat in body axes (module
    docstring). ``R``, ``R0`` row-major; ``omega`` body axes."""
    up = (R[6], R[7], R[8])  # R^T z_hat
    omega_z_world = up[0] * omega[0] + up[1] * omega[1] + up[2] * omega[2]
    torque = -(stiffness * rope_twist(R, R0) + damping * omega_z_world)
    return (torque * up[0], torque * up[1], torque * up[2])


def torso_ellipsoid(params: RobotParams, scale: float = 1.0) -> Tuple[float, float, float]:
    """Semi-axes (m) of the torso ellipsoid: the body's aspect ratios (``body.dimensions``), scaled so
    its volume is the robot's displaced volume m / rho (neutral buoyancy), times ``scale`` in volume."""
    dims = np.asarray(params.body_dimensions, dtype=float) / 2.0
    volume = scale * params.mass / params.rho
    factor = (volume / (4.0 / 3.0 * math.pi * float(np.prod(dims)))) ** (1.0 / 3.0)
    return tuple(float(v) for v in dims * factor)  # type: ignore[return-value]


def _cross(a: Sequence[float], b: Sequence[float]) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _mat6_vec(M: Sequence[float], x: Sequence[float]) -> Tuple[float, ...]:
    """M x for a row-major 6x6 M (36 floats)."""
    x0, x1, x2, x3, x4, x5 = x
    return tuple(M[i] * x0 + M[i + 1] * x1 + M[i + 2] * x2 + M[i + 3] * x3 + M[i + 4] * x4 + M[i + 5] * x5
                 for i in (0, 6, 12, 18, 24, 30))


def _inverse3(m: Sequence[float]) -> Tuple[float, ...]:
    """Inverse of a row-major 3x3 matrix by cofactors."""
    a, b, c, d, e, f, g, h, i = m
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    if not (det != 0.0 and math.isfinite(det)):
        raise ValueError("singular mass matrix block (det %r)" % (det,))
    k = 1.0 / det
    return (A * k, (c * h - b * i) * k, (b * f - c * e) * k,
            B * k, (a * i - c * g) * k, (c * d - a * f) * k,
            C * k, (b * g - a * h) * k, (a * e - b * d) * k)


def _solve_mass(solver: Tuple[Tuple[float, ...], ...], g: Sequence[float]) -> Tuple[float, ...]:
    """nu_dot = M^-1 g for M = [[A, B], [B^T, D]] with A diagonal, by the Schur complement
    S = D - B^T A^-1 B: x2 = S^-1 (g2 - B^T A^-1 g1), x1 = A^-1 (g1 - B x2). ``solver`` is
    (diag A^-1, B, S^-1) from :meth:`TankModel._mass_solver`; tested against numpy.linalg.solve."""
    (a0, a1, a2), B, Si = solver
    y0, y1, y2 = a0 * g[0], a1 * g[1], a2 * g[2]  # A^-1 g1
    h0 = g[3] - (B[0] * y0 + B[3] * y1 + B[6] * y2)  # g2 - B^T A^-1 g1
    h1 = g[4] - (B[1] * y0 + B[4] * y1 + B[7] * y2)
    h2 = g[5] - (B[2] * y0 + B[5] * y1 + B[8] * y2)
    x3 = Si[0] * h0 + Si[1] * h1 + Si[2] * h2
    x4 = Si[3] * h0 + Si[4] * h1 + Si[5] * h2
    x5 = Si[6] * h0 + Si[7] * h1 + Si[8] * h2
    return (a0 * (g[0] - (B[0] * x3 + B[1] * x4 + B[2] * x5)),
            a1 * (g[1] - (B[3] * x3 + B[4] * x4 + B[5] * x5)),
            a2 * (g[2] - (B[6] * x3 + B[7] * x4 + B[8] * x5)), x3, x4, x5)


class _TankContext(StepContext):
    """A step's inputs plus the tank's per-step constants: the mass-matrix solver and the leg sums
    (sum r_i, sum c_i, sum r_i r_i^T, sum c_i r_i^T, sum r_i . c_i) of the paw added-mass terms."""

    __slots__ = ("mass_solver", "leg_sums")


class TankModel(FloatingBaseModel):
    """The robot hanging in the test tank: :class:`FloatingBaseModel` plus the effects of
    :class:`TankParams` (module docstring). :meth:`attach` fixes the rope's anchor above the hook."""

    name = "tank"

    def __init__(self, params: RobotParams, tank: TankParams) -> None:
        super().__init__(params)
        self.tank = tank
        self.drag_constant *= tank.paw_drag_scale
        if not tank.drag:
            self.drag_constant = 0.0
            self._drag = (0.0,) * 8
        self.hook = np.array(tank.hook, dtype=float)
        self.center_of_buoyancy = np.array(tank.center_of_buoyancy, dtype=float)
        self.torso_weight = (params.mass - 4.0 * params.paw_mass) * params.gravity
        self.torso_buoyancy = self.torso_weight - tank.net_weight
        if tank.hydrostatics:
            # The torso's buoyancy moment joins the paw buoyancy torque in each step's U R^T z_hat
            # (StepContext): the plant's restoring matrix, B hat(r_cb).
            self._restoring_matrix = hydrodynamics.torso_buoyancy_torque_matrix(self.torso_buoyancy,
                                                                                 self.center_of_buoyancy)
            self._restoring = as_mat3(self._restoring_matrix)
        rigid = np.zeros((6, 6))
        rigid[:3, :3] = self.mass * np.eye(3)
        rigid[3:, 3:] = self.inertia
        added = np.zeros((6, 6))
        if tank.torso_added_mass and tank.added_mass_scale > 0.0:
            added = ellipsoid_added_mass(*torso_ellipsoid(params, tank.added_mass_scale), rho=params.rho)
        self.torso_added_mass = added
        #: M_RB + M_A: its Kirchhoff terms are the gyroscopic and added-mass Coriolis terms.
        self.body_mass_matrix = rigid + added
        # A flooded paw entrains the water of its whole sphere: rho V / 2 with the outer volume pi d^3 / 6.
        outer_volume = math.pi * params.paw_diameter ** 3 / 6.0
        self.paw_added_mass = (tank.paw_added_mass_scale * sphere_added_mass(outer_volume, params.rho)
                               if tank.paw_added_mass else 0.0)
        self.anchor = np.zeros(3)
        self._anchor: Vec3 = (0.0, 0.0, 0.0)
        self.untwisted = np.eye(3)
        self._untwisted = tuple(self.untwisted.ravel().tolist())
        self._appendage_damping = any(tank.appendage_damping_linear) or any(tank.appendage_damping_quadratic)
        self._body_m = tuple(self.body_mass_matrix.ravel().tolist())

    # ---- set-up ------------------------------------------------------------------------------

    def static_rope_tension(self) -> float:
        """Rope tension at rest, hanging: torso net weight plus the paws' net weight (N)."""
        weight = self.tank.net_weight if self.tank.hydrostatics else 0.0
        return max(0.0, weight - 4.0 * self.net_paw_buoyancy)

    def attach(self, state: RigidBodyState) -> None:
        """Place the anchor straight above the hook of ``state``, the rope stretched by its static load."""
        hook = state.position + state.rotation @ self.hook
        stretch = self.static_rope_tension() / self.tank.rope_stiffness
        self.anchor = hook + np.array([0.0, 0.0, self.tank.rope_length + stretch])
        self._anchor = tuple(self.anchor.tolist())  # type: ignore[assignment]
        # The rope hangs untwisted in this attitude (rope torsion measures the twist from it).
        self.untwisted = np.array(state.rotation, dtype=float)
        self._untwisted = tuple(self.untwisted.ravel().tolist())

    def mass_matrix(self, foot_positions: Sequence[Sequence[float]]) -> np.ndarray:
        """M = M_RB + M_A + sum_i M_paw(r_i) (6x6, body axes about the centre of mass)."""
        M = self.body_mass_matrix.copy()
        if self.paw_added_mass > 0.0:
            for r in foot_positions:
                M += point_mass_matrix(self.paw_added_mass, r[:3])
        return M

    def _mass_solver(self, sr: Sequence[float], S: Sequence[float]) -> Tuple[Tuple[float, ...], ...]:
        """(diag A^-1, B, S^-1) of :func:`_solve_mass` for M = M_RB + M_A + sum_i M_paw(r_i): the paws
        add m_a [[4 I, -hat(sr)], [hat(sr), sum_i (|r_i|^2 I - r_i r_i^T)]] (sr = sum r_i, S = sum r_i r_i^T)."""
        M = self._body_m
        ma = self.paw_added_mass
        if any(M[6 * i + j] != 0.0 for i in range(3) for j in range(6) if i != j):
            raise ValueError("the torso's translational mass block must be diagonal (mass matrix about the "
                             "centre of mass of a symmetric ellipsoid)")
        a_inv = tuple(1.0 / (M[7 * i] + 4.0 * ma) for i in range(3))
        x, y, z = sr
        B = (0.0, ma * z, -ma * y, -ma * z, 0.0, ma * x, ma * y, -ma * x, 0.0)  # -m_a hat(sr)
        trace = S[0] + S[4] + S[8]
        D = [M[18 + 6 * i + 3 + j] + ma * ((trace if i == j else 0.0) - S[3 * i + j])
             for i in range(3) for j in range(3)]
        # S = D - B^T A^-1 B
        schur = [D[3 * i + j] - sum(B[3 * k + i] * a_inv[k] * B[3 * k + j] for k in range(3))
                 for i in range(3) for j in range(3)]
        return a_inv, B, _inverse3(schur)

    # ---- equations of motion -------------------------------------------------------------------

    def generalized_forces(self, context: "_TankContext", p: Sequence[float], v: Sequence[float], R: Mat3,
                           w: Sequence[float]) -> Tuple[float, ...]:
        """Right-hand side of eq. (tank): the 6 body-axes generalised forces minus C(nu) nu and f_paw."""
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        b = (r0 * v[0] + r3 * v[1] + r6 * v[2], r1 * v[0] + r4 * v[1] + r7 * v[2], r2 * v[0] + r5 * v[1] + r8 * v[2])
        fx, fy, fz, tx, ty, tz = self._body_wrench(context, b[0], b[1], b[2], R, w[0], w[1], w[2])
        up = (r6, r7, r8)  # R^T z_hat
        tank = self.tank
        lift = context.lift  # world-up forces: paw buoyancy, then torso hydrostatics (its moment is in U)
        if tank.hydrostatics:
            lift += self.torso_buoyancy - self.torso_weight
        fx, fy, fz = fx + lift * up[0], fy + lift * up[1], fz + lift * up[2]
        if tank.suspension:
            h = tank.hook
            Rh = (r0 * h[0] + r1 * h[1] + r2 * h[2], r3 * h[0] + r4 * h[1] + r5 * h[2],
                  r6 * h[0] + r7 * h[1] + r8 * h[2])
            wxh = _cross(w, h)
            Rwxh = (r0 * wxh[0] + r1 * wxh[1] + r2 * wxh[2], r3 * wxh[0] + r4 * wxh[1] + r5 * wxh[2],
                    r6 * wxh[0] + r7 * wxh[1] + r8 * wxh[2])
            F = rope_force((p[0] + Rh[0], p[1] + Rh[1], p[2] + Rh[2]), (v[0] + Rwxh[0], v[1] + Rwxh[1], v[2] + Rwxh[2]),
                           self._anchor, tank.rope_length, tank.rope_stiffness, tank.rope_damping)
            Fb = (r0 * F[0] + r3 * F[1] + r6 * F[2], r1 * F[0] + r4 * F[1] + r7 * F[2],
                  r2 * F[0] + r5 * F[1] + r8 * F[2])
            m = _cross(h, Fb)
            fx, fy, fz, tx, ty, tz = fx + Fb[0], fy + Fb[1], fz + Fb[2], tx + m[0], ty + m[1], tz + m[2]
            if tank.rope_torsion_stiffness > 0.0 or tank.rope_torsion_damping > 0.0:
                m = rope_torsion_torque(R, self._untwisted, w, tank.rope_torsion_stiffness, tank.rope_torsion_damping)
                tx, ty, tz = tx + m[0], ty + m[1], tz + m[2]
        if self._appendage_damping:
            m = appendage_damping_torque(w, tank.appendage_damping_linear, tank.appendage_damping_quadratic)
            tx, ty, tz = tx + m[0], ty + m[1], tz + m[2]
        # Kirchhoff terms of M_RB + M_A: [omega x p; v x p + omega x h], [p; h] = M nu.
        ph = _mat6_vec(self._body_m, b + tuple(w))
        a, c1, c2 = _cross(w, ph[:3]), _cross(b, ph[:3]), _cross(w, ph[3:])
        fx, fy, fz = fx - a[0], fy - a[1], fz - a[2]
        tx, ty, tz = tx - c1[0] - c2[0], ty - c1[1] - c2[1], tz - c1[2] - c2[2]
        ma = self.paw_added_mass
        if ma > 0.0:
            # Paw added mass, summed over the legs: f_i = -m_a (omega x v + omega x (omega x r_i)
            # + 2 omega x c_i), moments r_i x f_i; with sr = sum r_i, sc = sum c_i, S = sum r_i r_i^T,
            # P = sum c_i r_i^T, rc = sum r_i . c_i:
            #   sum f_i = -m_a (4 omega x v + omega x (omega x sr) + 2 omega x sc)
            #   sum r_i x f_i = -m_a (sr x (omega x v) + (S omega) x omega + 2 (omega rc - P omega))
            sr, sc, S, P, rc = context.leg_sums
            wv = _cross(w, b)
            wwr = _cross(w, _cross(w, sr))
            wc = _cross(w, sc)
            fx -= ma * (4.0 * wv[0] + wwr[0] + 2.0 * wc[0])
            fy -= ma * (4.0 * wv[1] + wwr[1] + 2.0 * wc[1])
            fz -= ma * (4.0 * wv[2] + wwr[2] + 2.0 * wc[2])
            rwv = _cross(sr, wv)
            Sw = (S[0] * w[0] + S[1] * w[1] + S[2] * w[2], S[3] * w[0] + S[4] * w[1] + S[5] * w[2],
                  S[6] * w[0] + S[7] * w[1] + S[8] * w[2])
            Pw = (P[0] * w[0] + P[1] * w[1] + P[2] * w[2], P[3] * w[0] + P[4] * w[1] + P[5] * w[2],
                  P[6] * w[0] + P[7] * w[1] + P[8] * w[2])
            sww = _cross(Sw, w)
            tx -= ma * (rwv[0] + sww[0] + 2.0 * (w[0] * rc - Pw[0]))
            ty -= ma * (rwv[1] + sww[1] + 2.0 * (w[1] * rc - Pw[1]))
            tz -= ma * (rwv[2] + sww[2] + 2.0 * (w[2] * rc - Pw[2]))
        return fx, fy, fz, tx, ty, tz

    def _chart_derivative(self, context: "_TankContext", R0: Mat3,  # type: ignore[override]
                          y: Sequence[float]) -> Tuple[float, ...]:
        """d/dt of the chart state y = (p, v, xi, omega) under eq. (tank)."""
        R, xi_rate = chart_point(R0, y[6], y[7], y[8], y[9], y[10], y[11])
        v, w = y[3:6], y[9:12]
        nu_dot = _solve_mass(context.mass_solver, self.generalized_forces(context, y[0:3], v, R, w))
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        b = (r0 * v[0] + r3 * v[1] + r6 * v[2], r1 * v[0] + r4 * v[1] + r7 * v[2], r2 * v[0] + r5 * v[1] + r8 * v[2])
        wb = _cross(w, b)
        ax, ay, az = nu_dot[0] + wb[0], nu_dot[1] + wb[1], nu_dot[2] + wb[2]
        return (tuple(v) + (r0 * ax + r1 * ay + r2 * az, r3 * ax + r4 * ay + r5 * az, r6 * ax + r7 * ay + r8 * az)
                + xi_rate + tuple(nu_dot[3:]))

    def _step_context(self, q: Any, q_dot: Any) -> "_TankContext":
        flat = leg_kinematics_flat(q.tolist() if isinstance(q, np.ndarray) else q,
                                    q_dot.tolist() if isinstance(q_dot, np.ndarray) else q_dot, self.params)
        context = _TankContext(flat, self.net_paw_buoyancy, self._restoring)
        feet = np.array(flat).reshape(4, 6)
        r, c = feet[:, :3], feet[:, 3:]
        context.leg_sums = (tuple(r.sum(axis=0).tolist()), tuple(c.sum(axis=0).tolist()),
                            tuple((r.T @ r).ravel().tolist()), tuple((c.T @ r).ravel().tolist()),
                            float(np.sum(r * c)))
        context.mass_solver = self._mass_solver(context.leg_sums[0], context.leg_sums[2])
        return context

    def step(self, state: RigidBodyState, q: Any, q_dot: Any, dt: float) -> RigidBodyState:
        dt = check_dt(dt)
        state = state.validate()
        context = self._step_context(joint_array(q, "q"), joint_array(q_dot, "q_dot"))
        return self._rk4(state, dt, (context, context, context))

    def step_trusted(self, state: RigidBodyState, q: Any, q_dot: Any, dt: float) -> RigidBodyState:
        context = self._step_context(q, q_dot)
        return self._rk4(state, dt, (context, context, context))

    # ---- energy ------------------------------------------------------------------------------

    def kinetic_energy(self, state: RigidBodyState, q: Any = None) -> float:
        """1/2 nu^T M nu with the legs at ``q`` (nominal if None is not allowed: pass the pose)."""
        legs = self.leg_input(q, np.zeros((4, 3)))
        nu = np.concatenate((state.rotation.T @ state.velocity, state.omega))
        return 0.5 * float(nu @ self.mass_matrix(legs.foot_positions.tolist()) @ nu)

    def potential_energy(self, state: RigidBodyState, q: Any) -> float:
        """Paw buoyancy + torso weight and buoyancy + elastic rope energy, J."""
        energy = super().potential_energy(state, q)
        R, p = state.rotation, state.position
        if self.tank.hydrostatics:
            energy += self.torso_weight * p[2] - self.torso_buoyancy * (p[2] + float(R[2, :] @ self.center_of_buoyancy))
        if self.tank.suspension:
            stretch = float(np.linalg.norm(self.anchor - (p + R @ self.hook))) - self.tank.rope_length
            if stretch > 0.0:
                energy += 0.5 * self.tank.rope_stiffness * stretch * stretch
            twist = rope_twist(R.ravel().tolist(), self._untwisted)
            energy += 0.5 * self.tank.rope_torsion_stiffness * twist * twist
        return energy
