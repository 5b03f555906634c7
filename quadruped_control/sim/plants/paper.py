"""Floating-base dynamics of the underwater quadruped and its Runge-Kutta integrator.

Model (paper section "Body Dynamics"): the torso is a rigid body driven by the paw drag of the four
legs (eq. (force_leg), (torque_leg)), the net paw buoyancy (eq. (buoy_torque)) and the inertia-box body
drag (eq. (drag_total)):

    m dv_B^W/dt = sum_i F_i^W + F_buoyancy^W + R f_drag^B                               eq. (trans)
    I domega_B^B/dt + omega x I omega = sum_i tau_i^B + tau_buoyancy^B + tau_drag^B      eq. (rot)
    dp^W/dt = v_B^W,   dR_B^W/dt = R hat(omega_B^B)

Leg dynamics are neglected: the commanded joint angles q (4 x 3, legs 1..4, (theta1, theta2, theta3))
are the input, and their velocities q_dot come from finite differences of the commands
(:func:`joint_velocity`). Over a step the joints are held; :func:`held_joint_input` holds the midpoint
of consecutive commands, which makes the hold second-order accurate (a choice: the paper does not say
which angle is held). The foot velocity is the floating-base Jacobian times u, eq. (ee_vel),
(fb_jac): v_e,i^W = v_B^W - R [r_e,i^B]_x omega + R J_P,i^B q_dot_i = v_B^W + R (omega x r + J q_dot).

As in the paper, torso gravity and buoyancy forces are not modelled (the robot hangs from a rope that
balances them) and the centre of buoyancy is at the centre of mass. Beyond the paper, an optional
centre-of-buoyancy offset adds the restoring torque r_cb^B x (R^T [0, 0, B]) of a torso buoyancy B
acting at r_cb^B (force still balanced by the rope): ``FloatingBaseModel(params, restoring_offset=...)``.

Integration (paper section "Simulation Validation": RK4, dt = 0.01 s): classic fourth-order
Runge-Kutta in the Munthe-Kaas form on SO(3). Within a step R = R_0 exp(hat(xi)) and the rotation
vector xi obeys d xi/dt = J_r(xi)^-1 omega, so every stage uses an exact rotation, the scheme keeps
fourth order, and the new R is a rotation to machine precision.
Because q and q_dot are held constant over a step (zero-order hold of the command), the foot positions
r_e,i^B and the joint-induced foot velocities J_P,i^B q_dot_i are computed once per step; the stages
only re-evaluate what depends on v, R and omega, on plain floats (faster than numpy for 3-vectors).
:meth:`FloatingBaseModel.step` and :meth:`~FloatingBaseModel.step_trusted` run that held-input RK4
on unpacked floats (``_rk4_held``, ``_stage9``: legs unrolled, no position in the stages since no
force depends on it); the generic ``_rk4`` over the readable :meth:`~FloatingBaseModel._chart_derivative`
(built from ``_accelerations`` and ``_chart_rate``) is the reference they are tested against.
:meth:`FloatingBaseModel.step_continuous` samples a smooth joint trajectory at the stage times instead
(reference solutions). A non-finite result raises :class:`DynamicsError` and leaves the input state as is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.robot import LEGS
from quadruped_common.so3 import hat
from quadruped_control.model import hydrodynamics
from quadruped_control.model.kinematics import leg_kinematics, leg_kinematics_flat
from quadruped_control.model.params import RobotParams

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: A joint trajectory for :meth:`FloatingBaseModel.step_continuous`: t -> (q, q_dot), each 4 x 3.
JointTrajectory = Callable[[float], Tuple[ArrayLike, ArrayLike]]

NUM_LEGS = len(LEGS)

__all__ = [
    "DynamicsError",
    "FloatingBaseModel",
    "JointTrajectory",
    "LegInput",
    "RigidBodyState",
    "StateDerivative",
    "Wrench",
    "held_joint_input",
    "joint_velocity",
]


class DynamicsError(RuntimeError):
    """The integration produced a non-finite state (diverged); the input state is left untouched."""


# --------------------------------------------------------------------------------------------------
# State
# --------------------------------------------------------------------------------------------------

def _vector3(value: ArrayLike, name: str) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape != (3,):
        raise ValueError("%s must have 3 elements, got shape %s" % (name, arr.shape))
    if not math.isfinite(float(arr.sum())):  # NaN or inf anywhere makes the sum non-finite
        raise ValueError("%s has non-finite elements: %s" % (name, arr))
    return arr


@dataclass
class RigidBodyState:
    """State of the floating base.

    ``position`` p^W (m) and ``velocity`` v_B^W (m/s) of the centre of mass in the world frame,
    ``rotation`` R_B^W (body -> world), ``omega`` omega_B^B (rad/s) in the body frame (as in eq. (ee_vel)).
    """

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))

    #: Largest |R^T R - I| accepted by :meth:`validate`.
    ROTATION_TOL = 1e-6

    def copy(self) -> "RigidBodyState":
        """Deep copy (independent arrays)."""
        return RigidBodyState(self.position.copy(), self.velocity.copy(), self.rotation.copy(), self.omega.copy())

    def validate(self) -> "RigidBodyState":
        """Check shapes, finiteness and R in SO(3); returns a copy with float arrays, ValueError otherwise."""
        rotation = np.array(self.rotation, dtype=float)
        if rotation.shape != (3, 3) or not math.isfinite(float(rotation.sum())):
            raise ValueError("rotation must be a finite 3x3 matrix, got %r" % (self.rotation,))
        error = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
        # For an orthogonal matrix det = +-1 = R_0 . (R_1 x R_2) (rows); -1 is a reflection.
        (a, b, c), (d, e, f), (g, h, i) = rotation.tolist()
        det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
        if error > self.ROTATION_TOL or det <= 0.0:
            raise ValueError("rotation is not in SO(3) (|R^T R - I| = %.3g, det = %.6g)" % (error, det))
        return RigidBodyState(_vector3(self.position, "position"), _vector3(self.velocity, "velocity"),
                              rotation, _vector3(self.omega, "omega"))

    def to_vector(self) -> np.ndarray:
        """Flat (18,) vector [p, v, R row-major, omega] (for logging and comparisons)."""
        return np.concatenate((self.position, self.velocity, self.rotation.reshape(9), self.omega))

    @classmethod
    def from_vector(cls, vector: ArrayLike) -> "RigidBodyState":
        """Inverse of :meth:`to_vector`; validates the result."""
        vec = np.asarray(vector, dtype=float)
        if vec.shape != (18,):
            raise ValueError("state vector must have 18 elements, got shape %s" % (vec.shape,))
        return cls(vec[0:3].copy(), vec[3:6].copy(), vec[6:15].reshape(3, 3).copy(), vec[15:18].copy()).validate()


@dataclass
class StateDerivative:
    """Time derivative of a :class:`RigidBodyState`: (p_dot, v_dot, R_dot = R hat(omega), omega_dot)."""

    position_dot: np.ndarray
    velocity_dot: np.ndarray
    rotation_dot: np.ndarray
    omega_dot: np.ndarray


# --------------------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------------------

def _joint_array(value: ArrayLike, name: str) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape == (3 * NUM_LEGS,):
        arr = arr.reshape(NUM_LEGS, 3)
    if arr.shape != (NUM_LEGS, 3):
        raise ValueError("%s must have shape (4, 3) or (12,) (legs 1..4 x (theta1, theta2, theta3)), got %s"
                         % (name, arr.shape))
    if not np.all(np.isfinite(arr)):
        raise ValueError("%s has non-finite elements: %s" % (name, arr.tolist()))
    return arr


def joint_velocity(q_previous: ArrayLike, q_current: ArrayLike, dt: float) -> np.ndarray:
    """Commanded joint velocity by backward finite difference, (q_k - q_(k-1)) / dt, shape (4, 3).

    The paper obtains q_dot "through finite differences" of the commanded angles (section "Body
    Dynamics"). Raises ValueError for a non-positive dt or malformed/non-finite angles.
    """
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError("dt must be a positive finite number, got %r" % (dt,))
    return (_joint_array(q_current, "q_current") - _joint_array(q_previous, "q_previous")) / dt


def held_joint_input(q_previous: ArrayLike, q_current: ArrayLike, dt: float) -> Tuple[np.ndarray, np.ndarray]:
    """Joint input (q_hold, q_dot) to hold over the step that moves the joints from q_(k-1) to q_k.

    The joints are taken to travel linearly between consecutive commands, so the held angles are the
    midpoint (q_(k-1) + q_k) / 2 and q_dot the finite difference (q_k - q_(k-1)) / dt. Holding the
    midpoint makes the zero-order hold second-order accurate in dt (holding either end is first
    order); the paper only says the velocities come from finite differences. Both arrays are (4, 3).
    """
    q_dot = joint_velocity(q_previous, q_current, dt)
    q_hold = 0.5 * (_joint_array(q_previous, "q_previous") + _joint_array(q_current, "q_current"))
    return q_hold, q_dot


@dataclass(frozen=True)
class LegInput:
    """Per-leg kinematic quantities that are constant while q, q_dot are held (one integration step).

    ``foot_positions``: r_e,i^B, shape (4, 3); ``joint_foot_velocities``: J_P,i^B(q_i) q_dot_i, the
    foot velocity relative to the body in body axes, shape (4, 3). Rows are legs 1..4.
    """

    foot_positions: np.ndarray
    joint_foot_velocities: np.ndarray

    @classmethod
    def from_joints(cls, q: ArrayLike, q_dot: ArrayLike, params: RobotParams) -> "LegInput":
        """Evaluate eq. (ee_body) and eq. (J_leg) for all legs. Raises ValueError (UnreachableError for
        a configuration the five-bar cannot assemble) for bad input."""
        q_arr = _joint_array(q, "q")
        q_dot_arr = _joint_array(q_dot, "q_dot")
        rows = leg_kinematics(q_arr.tolist(), q_dot_arr.tolist(), params)
        data = np.array(rows)
        return cls(data[:, 0:3].copy(), data[:, 3:6].copy())


# --------------------------------------------------------------------------------------------------
# Wrench breakdown
# --------------------------------------------------------------------------------------------------

@dataclass
class Wrench:
    """All external forces and torques on the torso at one instant (rows of the (4, 3) arrays: legs 1..4).

    Forces marked ``_world`` are in the world frame, torques (about the centre of mass) in the body frame.
    """

    foot_velocities_world: np.ndarray   # v_e,i^W, eq. (fb_jac)
    leg_forces_world: np.ndarray        # F_i^W, eq. (force_leg)
    leg_torques_body: np.ndarray        # tau_i^B, eq. (torque_leg)
    buoyancy_force_world: np.ndarray    # F_buoyancy^W, eq. (buoy_torque)
    buoyancy_torque_body: np.ndarray    # tau_buoyancy^B, eq. (buoy_torque)
    drag_force_body: np.ndarray         # f_D + f_V, eq. (quad), (visc)
    drag_force_world: np.ndarray        # f_drag^W = R (f_D + f_V), eq. (drag_total)
    drag_torque_body: np.ndarray        # tau_drag^B = g_D + g_V, eq. (drag_total)
    restoring_torque_body: np.ndarray   # r_cb x R^T [0, 0, B] (zero unless configured; not in the paper)

    @property
    def total_force_world(self) -> np.ndarray:
        """Right-hand side of eq. (trans)."""
        return self.leg_forces_world.sum(axis=0) + self.buoyancy_force_world + self.drag_force_world

    @property
    def total_torque_body(self) -> np.ndarray:
        """Right-hand side of eq. (rot) (plus the optional restoring torque)."""
        return (self.leg_torques_body.sum(axis=0) + self.buoyancy_torque_body + self.drag_torque_body
                + self.restoring_torque_body)


# --------------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------------

#: Below this rotation-vector norm the series forms of the SO(3) chart coefficients are used.
_SMALL_ANGLE = 1e-4

# The Runge-Kutta stages work on plain Python floats: for 3-vectors and 3x3 matrices, CPython float
# arithmetic is several times faster than numpy's per-call overhead. Matrices are row-major 9-tuples.
Mat3 = Tuple[float, float, float, float, float, float, float, float, float]


def _exp_rotation(x: float, y: float, z: float) -> Mat3:
    """exp(hat(xi)) by Rodrigues' formula (the maths of so3.exp_so3, on floats and without input checks)."""
    t2 = x * x + y * y + z * z
    if t2 < _SMALL_ANGLE * _SMALL_ANGLE:
        a = 1.0 - t2 / 6.0     # sin(t) / t
        b = 0.5 - t2 / 24.0    # (1 - cos(t)) / t^2
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    return (1.0 - b * (y * y + z * z), bxy - a * z, bxz + a * y,
            bxy + a * z, 1.0 - b * (x * x + z * z), byz - a * x,
            bxz - a * y, byz + a * x, 1.0 - b * (x * x + y * y))


def _matmul(A: Mat3, B: Mat3) -> Mat3:
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


def _as_mat3(M: np.ndarray) -> Mat3:
    return tuple(np.asarray(M, dtype=float).reshape(9).tolist())  # type: ignore[return-value]


def _chart_rate(x: float, y: float, z: float, wx: float, wy: float, wz: float) -> Tuple[float, float, float]:
    """d xi / dt = J_r(xi)^-1 omega for R = R_0 exp(hat(xi)) with R^T dR/dt = hat(omega).

    J_r^-1(xi) = I + 1/2 hat(xi) + c(t) hat(xi)^2, c(t) = 1/t^2 - (1 + cos t) / (2 t sin t), t = |xi|.
    """
    t2 = x * x + y * y + z * z
    if t2 < _SMALL_ANGLE * _SMALL_ANGLE:
        c = 1.0 / 12.0 + t2 / 720.0
    else:
        t = math.sqrt(t2)
        c = 1.0 / t2 - (1.0 + math.cos(t)) / (2.0 * t * math.sin(t))
    ax, ay, az = y * wz - z * wy, z * wx - x * wz, x * wy - y * wx        # xi x omega
    bx, by, bz = y * az - z * ay, z * ax - x * az, x * ay - y * ax        # xi x (xi x omega)
    return wx + 0.5 * ax + c * bx, wy + 0.5 * ay + c * by, wz + 0.5 * az + c * bz


class _StepContext:
    """The inputs of one step as floats: per leg (r_e,i^B, J_P,i^B q_dot_i), and the matrix U with
    U R^T z_hat = paw buoyancy torque (sum_i r_i) x (R^T B_net z_hat) + the optional restoring torque."""

    __slots__ = ("feet", "up_torque", "flat")

    def __init__(self, rows: Sequence[Sequence[float]], net_paw_buoyancy: float, restoring: Mat3) -> None:
        feet = self.feet = [tuple(row) for row in rows]
        sx = sy = sz = 0  # int 0 as sum() starts: 0 + x == x exactly
        flat: Tuple[float, ...] = ()
        for foot in feet:
            sx += foot[0]
            sy += foot[1]
            sz += foot[2]
            flat += foot
        sx *= net_paw_buoyancy
        sy *= net_paw_buoyancy
        sz *= net_paw_buoyancy
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = restoring
        # net * hat(sum_i r_i) + restoring matrix
        self.up_torque = (r0, r1 - sz, r2 + sy, r3 + sz, r4, r5 - sx, r6 - sy, r7 + sx, r8)
        # Everything :meth:`FloatingBaseModel._stage9` reads: the 4 x 6 leg rows, then U.
        self.flat = flat + self.up_torque

    @classmethod
    def from_flat(cls, flat: Tuple[float, ...], net_paw_buoyancy: float, restoring: Mat3) -> "_StepContext":
        """Context from the flat 24-tuple of :func:`~quadruped_control.model.kinematics.leg_kinematics_flat` (same values as ``cls(rows, ...)``)."""
        self = cls.__new__(cls)
        self.feet = [flat[0:6], flat[6:12], flat[12:18], flat[18:24]]
        # sum() order: ((0 + r_1) + r_2) + r_3) + r_4, and 0 + x == x
        sx = (flat[0] + flat[6] + flat[12] + flat[18]) * net_paw_buoyancy
        sy = (flat[1] + flat[7] + flat[13] + flat[19]) * net_paw_buoyancy
        sz = (flat[2] + flat[8] + flat[14] + flat[20]) * net_paw_buoyancy
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = restoring
        self.up_torque = (r0, r1 - sz, r2 + sy, r3 + sz, r4, r5 - sx, r6 - sy, r7 + sx, r8)
        self.flat = flat + self.up_torque
        return self

    @classmethod
    def from_legs(cls, legs: LegInput, net_paw_buoyancy: float, restoring: Mat3) -> "_StepContext":
        return cls(np.hstack((legs.foot_positions, legs.joint_foot_velocities)).tolist(), net_paw_buoyancy,
                   restoring)


class FloatingBaseModel:
    """The paper's floating-base model, eq. (trans), (rot), with a fixed-step RK4 integrator on SO(3).

    ``restoring_offset``: optional centre of buoyancy of the torso relative to the centre of mass, in
    the body frame (m); ``restoring_force``: the torso buoyancy B acting there (N, default m g). Both
    are beyond the paper (which assumes they coincide); the force is balanced by the rope, only the
    torque r_cb x (R^T [0, 0, B]) acts. A centre of buoyancy above the centre of mass rights the robot.
    """

    #: Plant name (:mod:`quadruped_control.sim.plants`).
    name = "paper"

    def __init__(self, params: RobotParams, restoring_offset: Optional[ArrayLike] = None,
                 restoring_force: Optional[float] = None) -> None:
        self.params = params
        self.mass = float(params.mass)
        self.inertia = np.array(params.inertia, dtype=float)
        self.inertia_inverse = np.linalg.inv(self.inertia)
        self.drag_constant = float(params.drag_constant)
        self.net_paw_buoyancy = float(params.paw_net_buoyancy)
        self.drag = hydrodynamics.body_drag_coefficients(params)
        if restoring_offset is None:
            if restoring_force is not None:
                raise ValueError("restoring_force needs a restoring_offset (where the buoyancy acts)")
            self.restoring_offset = np.zeros(3)
            self.restoring_force = 0.0
        else:
            self.restoring_offset = _vector3(restoring_offset, "restoring_offset")
            force = self.mass * params.gravity if restoring_force is None else float(restoring_force)
            if not (math.isfinite(force) and force >= 0.0):
                raise ValueError("restoring_force must be a finite non-negative force in N, got %r"
                                 % (restoring_force,))
            self.restoring_force = force
        # r_cb x (R^T B z_hat) = B hat(r_cb) R[2, :]
        self._restoring_matrix = self.restoring_force * hat(self.restoring_offset)
        # Float copies for the Runge-Kutta stages.
        self._restoring = _as_mat3(self._restoring_matrix)
        self._inertia = _as_mat3(self.inertia)
        self._inertia_inverse = _as_mat3(self.inertia_inverse)
        self._drag = tuple(self.drag.quad_force.tolist() + self.drag.quad_torque.tolist()
                           + [self.drag.visc_force, self.drag.visc_torque])
        self._paw_buoyancy_force = NUM_LEGS * self.net_paw_buoyancy  # F_buoyancy^W . z_hat, eq. (buoy_torque)
        self._stage_constants = ((-self.drag_constant,) + self._drag + self._inertia + self._inertia_inverse
                                 + (1.0 / self.mass, self._paw_buoyancy_force))

    # ---- inputs ------------------------------------------------------------------------------

    def attach(self, state: RigidBodyState) -> None:
        """Fix whatever the plant ties to the world at the start ``state`` (nothing here; the tank plant's
        rope anchor)."""

    def leg_input(self, q: ArrayLike, q_dot: ArrayLike) -> LegInput:
        """:class:`LegInput` (foot positions and joint-induced foot velocities) for q, q_dot (4 x 3)."""
        return LegInput.from_joints(q, q_dot, self.params)

    # ---- forces ------------------------------------------------------------------------------

    def wrench(self, state: RigidBodyState, q: ArrayLike, q_dot: ArrayLike) -> Wrench:
        """Breakdown of every force and torque on the torso (telemetry, tests), from the public
        :mod:`~quadruped_control.model.hydrodynamics` functions. The integrator uses an equivalent faster path."""
        state = state.validate()
        legs = self.leg_input(q, q_dot)
        R = state.rotation
        r = legs.foot_positions
        # eq. (ee_vel), (fb_jac): v_e,i^W = v_B^W - R [r]_x omega + R J q_dot, row-wise.
        relative_body = np.cross(state.omega, r) + legs.joint_foot_velocities  # omega x r_i + J q_dot_i
        foot_velocities = state.velocity + relative_body @ R.T
        leg_forces, leg_torques = hydrodynamics.leg_wrench(foot_velocities, r, R, self.params)
        buoyancy_force, buoyancy_torque = hydrodynamics.paw_buoyancy(r, R, self.params)
        drag_force, drag_torque = hydrodynamics.body_drag(R.T @ state.velocity, state.omega, self.params)
        return Wrench(
            foot_velocities_world=foot_velocities,
            leg_forces_world=leg_forces,
            leg_torques_body=leg_torques,
            buoyancy_force_world=buoyancy_force,
            buoyancy_torque_body=buoyancy_torque,
            drag_force_body=drag_force,
            drag_force_world=R @ drag_force,
            drag_torque_body=drag_torque,
            restoring_torque_body=self._restoring_matrix @ R[2, :],
        )

    def derivative(self, state: RigidBodyState, q: ArrayLike, q_dot: ArrayLike) -> StateDerivative:
        """Right-hand side of eq. (trans), (rot) and the kinematics dp/dt = v, dR/dt = R hat(omega)."""
        state = state.validate()
        context = self._context(self.leg_input(q, q_dot))
        acc = self._accelerations(context, state.velocity.tolist(), _as_mat3(state.rotation), state.omega.tolist())
        return StateDerivative(state.velocity.copy(), np.array(acc[:3]), state.rotation @ hat(state.omega),
                               np.array(acc[3:]))

    def _context(self, legs: LegInput) -> _StepContext:
        return _StepContext.from_legs(legs, self.net_paw_buoyancy, self._restoring)

    def _context_from_joints(self, q: np.ndarray, q_dot: np.ndarray) -> _StepContext:
        """Step context straight from checked (4, 3) joint arrays (floats all the way)."""
        flat = leg_kinematics_flat(q.tolist(), q_dot.tolist(), self.params)
        return _StepContext.from_flat(flat, self.net_paw_buoyancy, self._restoring)

    def _body_wrench(self, context: _StepContext, bx: float, by: float, bz: float, R: Mat3,
                     wx: float, wy: float, wz: float) -> Tuple[float, float, float, float, float, float]:
        """Force (body axes) and torque (body, about the centre of mass) of the paw drag, body drag,
        paw buoyancy and restoring terms of eq. (trans), (rot), on floats, for the body-axes velocity
        (bx, by, bz) = R^T v and rate omega. The one readable implementation of the paper's forces,
        used by :meth:`_accelerations` and by the tank plant (:mod:`quadruped_control.sim.plants.tank`).

        Leg forces are formed in body axes (|R u| = |u|, so R^T F_i^W = -k |u| u with
        u = R^T v_e,i^W = R^T v + omega x r_i + J q_dot_i). Paw buoyancy's force is left to the caller.
        """
        r6, r7, r8 = R[6], R[7], R[8]
        k = self.drag_constant
        fx = fy = fz = tx = ty = tz = 0.0
        for px, py, pz, cx, cy, cz in context.feet:
            ux = bx + wy * pz - wz * py + cx
            uy = by + wz * px - wx * pz + cy
            uz = bz + wx * py - wy * px + cz
            s = -k * math.sqrt(ux * ux + uy * uy + uz * uz)
            gx, gy, gz = s * ux, s * uy, s * uz                   # eq. (force_leg), body axes
            fx += gx
            fy += gy
            fz += gz
            tx += py * gz - pz * gy                                # eq. (torque_leg)
            ty += pz * gx - px * gz
            tz += px * gy - py * gx
        # Body drag, eq. (quad) + (visc), body frame.
        qf0, qf1, qf2, qg0, qg1, qg2, cf, cg = self._drag
        fx -= (qf0 * abs(bx) + cf) * bx
        fy -= (qf1 * abs(by) + cf) * by
        fz -= (qf2 * abs(bz) + cf) * bz
        tx -= (qg0 * abs(wx) + cg) * wx
        ty -= (qg1 * abs(wy) + cg) * wy
        tz -= (qg2 * abs(wz) + cg) * wz
        # Paw buoyancy and restoring torques: U (R^T z_hat), R^T z_hat = third row of R.
        u0, u1, u2, u3, u4, u5, u6, u7, u8 = context.up_torque
        tx += u0 * r6 + u1 * r7 + u2 * r8
        ty += u3 * r6 + u4 * r7 + u5 * r8
        tz += u6 * r6 + u7 * r7 + u8 * r8
        return fx, fy, fz, tx, ty, tz

    def _accelerations(self, context: _StepContext, v: Sequence[float], R: Mat3,
                       omega: Sequence[float]) -> Tuple[float, float, float, float, float, float]:
        """(dv/dt, domega/dt) of eq. (trans), (rot), on floats (forces from :meth:`_body_wrench`)."""
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        vx, vy, vz = v
        wx, wy, wz = omega
        bx, by, bz = r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz
        fx, fy, fz, tx, ty, tz = self._body_wrench(context, bx, by, bz, R, wx, wy, wz)
        # I domega/dt = tau - omega x I omega, eq. (rot).
        i0, i1, i2, i3, i4, i5, i6, i7, i8 = self._inertia
        hx, hy, hz = i0 * wx + i1 * wy + i2 * wz, i3 * wx + i4 * wy + i5 * wz, i6 * wx + i7 * wy + i8 * wz
        tx -= wy * hz - wz * hy
        ty -= wz * hx - wx * hz
        tz -= wx * hy - wy * hx
        j0, j1, j2, j3, j4, j5, j6, j7, j8 = self._inertia_inverse
        # m dv/dt = R f^B + F_buoyancy^W, eq. (trans).
        inv_m = 1.0 / self.mass
        return ((r0 * fx + r1 * fy + r2 * fz) * inv_m,
                (r3 * fx + r4 * fy + r5 * fz) * inv_m,
                (r6 * fx + r7 * fy + r8 * fz + self._paw_buoyancy_force) * inv_m,
                j0 * tx + j1 * ty + j2 * tz, j3 * tx + j4 * ty + j5 * tz, j6 * tx + j7 * ty + j8 * tz)

    def _chart_derivative(self, context: _StepContext, R0: Mat3, y: Sequence[float]) -> Tuple[float, ...]:
        """d/dt of the chart state y = (p, v, xi, omega), 12 floats, with R = R0 exp(hat(xi))."""
        R = _matmul(R0, _exp_rotation(y[6], y[7], y[8]))
        accelerations = self._accelerations(context, y[3:6], R, y[9:12])
        return (y[3], y[4], y[5]) + accelerations[:3] + _chart_rate(y[6], y[7], y[8], y[9], y[10], y[11]) \
            + accelerations[3:]

    def _stage9(self, context: _StepContext, R0: Mat3, vx: float, vy: float, vz: float, x: float, y_: float,
                z: float, wx: float, wy: float, wz: float) -> Tuple[float, ...]:
        """The integrator's hot path: (dv/dt, dxi/dt, domega/dt) (9 floats) of the chart state with
        velocity v, chart coordinate xi = (x, y_, z) and rate omega; dp/dt = v is left to the caller.

        The maths of :meth:`_chart_derivative` (R = R0 exp(hat(xi)), eq. (trans), (rot), chart rate J_r(xi)^-1
        omega) in the same floating-point order, with the four legs unrolled and every constant read
        from two flat tuples. At xi = 0 (the first RK4 stage) exp(hat(xi)) = I and the chart rate is
        omega, so the rotation products are skipped.
        """
        (q0x, q0y, q0z, c0x, c0y, c0z, q1x, q1y, q1z, c1x, c1y, c1z,
         q2x, q2y, q2z, c2x, c2y, c2z, q3x, q3y, q3z, c3x, c3y, c3z,
         u0, u1, u2, u3, u4, u5, u6, u7, u8) = context.flat
        identity = x == 0.0 and y_ == 0.0 and z == 0.0
        if identity:
            r0, r1, r2, r3, r4, r5, r6, r7, r8 = R0
        else:
            # exp(hat(xi)), Rodrigues (as _exp_rotation)
            t2 = x * x + y_ * y_ + z * z
            if t2 < _SMALL_ANGLE * _SMALL_ANGLE:
                a = 1.0 - t2 / 6.0
                b = 0.5 - t2 / 24.0
                c = 1.0 / 12.0 + t2 / 720.0
            else:
                t = math.sqrt(t2)
                st, ct = math.sin(t), math.cos(t)
                a = st / t
                b = (1.0 - ct) / t2
                c = 1.0 / t2 - (1.0 + ct) / (2.0 * t * st)
            bxy, bxz, byz = b * x * y_, b * x * z, b * y_ * z
            e0, e1, e2 = 1.0 - b * (y_ * y_ + z * z), bxy - a * z, bxz + a * y_
            e3, e4, e5 = bxy + a * z, 1.0 - b * (x * x + z * z), byz - a * x
            e6, e7, e8 = bxz - a * y_, byz + a * x, 1.0 - b * (x * x + y_ * y_)
            m0, m1, m2, m3, m4, m5, m6, m7, m8 = R0
            r0, r1, r2 = m0 * e0 + m1 * e3 + m2 * e6, m0 * e1 + m1 * e4 + m2 * e7, m0 * e2 + m1 * e5 + m2 * e8
            r3, r4, r5 = m3 * e0 + m4 * e3 + m5 * e6, m3 * e1 + m4 * e4 + m5 * e7, m3 * e2 + m4 * e5 + m5 * e8
            r6, r7, r8 = m6 * e0 + m7 * e3 + m8 * e6, m6 * e1 + m7 * e4 + m8 * e7, m6 * e2 + m7 * e5 + m8 * e8
        (nk, qf0, qf1, qf2, qg0, qg1, qg2, cf, cg, i0, i1, i2, i3, i4, i5, i6, i7, i8,
         j0, j1, j2, j3, j4, j5, j6, j7, j8, inv_m, paw_force) = self._stage_constants
        sqrt = math.sqrt
        # Accelerations, eq. (trans), (rot) (as _accelerations): body-axes velocity R^T v, then the legs.
        bx, by, bz = r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz
        ux = bx + wy * q0z - wz * q0y + c0x
        uy = by + wz * q0x - wx * q0z + c0y
        uz = bz + wx * q0y - wy * q0x + c0z
        sc = nk * sqrt(ux * ux + uy * uy + uz * uz)
        gx, gy, gz = sc * ux, sc * uy, sc * uz
        fx, fy, fz = gx, gy, gz
        tx = q0y * gz - q0z * gy
        ty = q0z * gx - q0x * gz
        tz = q0x * gy - q0y * gx
        ux = bx + wy * q1z - wz * q1y + c1x
        uy = by + wz * q1x - wx * q1z + c1y
        uz = bz + wx * q1y - wy * q1x + c1z
        sc = nk * sqrt(ux * ux + uy * uy + uz * uz)
        gx, gy, gz = sc * ux, sc * uy, sc * uz
        fx += gx
        fy += gy
        fz += gz
        tx += q1y * gz - q1z * gy
        ty += q1z * gx - q1x * gz
        tz += q1x * gy - q1y * gx
        ux = bx + wy * q2z - wz * q2y + c2x
        uy = by + wz * q2x - wx * q2z + c2y
        uz = bz + wx * q2y - wy * q2x + c2z
        sc = nk * sqrt(ux * ux + uy * uy + uz * uz)
        gx, gy, gz = sc * ux, sc * uy, sc * uz
        fx += gx
        fy += gy
        fz += gz
        tx += q2y * gz - q2z * gy
        ty += q2z * gx - q2x * gz
        tz += q2x * gy - q2y * gx
        ux = bx + wy * q3z - wz * q3y + c3x
        uy = by + wz * q3x - wx * q3z + c3y
        uz = bz + wx * q3y - wy * q3x + c3z
        sc = nk * sqrt(ux * ux + uy * uy + uz * uz)
        gx, gy, gz = sc * ux, sc * uy, sc * uz
        fx += gx
        fy += gy
        fz += gz
        tx += q3y * gz - q3z * gy
        ty += q3z * gx - q3x * gz
        tz += q3x * gy - q3y * gx
        # |x| inline (same value as abs(), without the call)
        fx -= (qf0 * (bx if bx >= 0.0 else -bx) + cf) * bx
        fy -= (qf1 * (by if by >= 0.0 else -by) + cf) * by
        fz -= (qf2 * (bz if bz >= 0.0 else -bz) + cf) * bz
        tx -= (qg0 * (wx if wx >= 0.0 else -wx) + cg) * wx
        ty -= (qg1 * (wy if wy >= 0.0 else -wy) + cg) * wy
        tz -= (qg2 * (wz if wz >= 0.0 else -wz) + cg) * wz
        tx += u0 * r6 + u1 * r7 + u2 * r8
        ty += u3 * r6 + u4 * r7 + u5 * r8
        tz += u6 * r6 + u7 * r7 + u8 * r8
        hx, hy, hz = i0 * wx + i1 * wy + i2 * wz, i3 * wx + i4 * wy + i5 * wz, i6 * wx + i7 * wy + i8 * wz
        tx -= wy * hz - wz * hy
        ty -= wz * hx - wx * hz
        tz -= wx * hy - wy * hx
        if identity:  # xi = 0: J_r^-1 = I
            rx, ry, rz = wx, wy, wz
        else:  # chart rate J_r(xi)^-1 omega (as _chart_rate)
            ax, ay, az = y_ * wz - z * wy, z * wx - x * wz, x * wy - y_ * wx
            cx2, cy2, cz2 = y_ * az - z * ay, z * ax - x * az, x * ay - y_ * ax
            rx, ry, rz = wx + 0.5 * ax + c * cx2, wy + 0.5 * ay + c * cy2, wz + 0.5 * az + c * cz2
        return ((r0 * fx + r1 * fy + r2 * fz) * inv_m,
                (r3 * fx + r4 * fy + r5 * fz) * inv_m,
                (r6 * fx + r7 * fy + r8 * fz + paw_force) * inv_m,
                rx, ry, rz,
                j0 * tx + j1 * ty + j2 * tz, j3 * tx + j4 * ty + j5 * tz, j6 * tx + j7 * ty + j8 * tz)

    def _rk4_held(self, state: RigidBodyState, dt: float, context: _StepContext) -> RigidBodyState:
        """:meth:`_rk4` for an input held over the step (one context for all stages), on unpacked floats.

        Same arithmetic as :meth:`_rk4` (the tests compare them): the stages only see (v, xi, omega)
        since no force depends on the position, whose stage derivatives are the stage velocities.
        """
        R0 = tuple(state.rotation.ravel().tolist())
        p0x, p0y, p0z = state.position.tolist()
        v0x, v0y, v0z = state.velocity.tolist()
        w0x, w0y, w0z = state.omega.tolist()
        h = 0.5 * dt
        stage = self._stage9
        try:
            a1x, a1y, a1z, x1, y1, z1, b1x, b1y, b1z = stage(context, R0, v0x, v0y, v0z, 0.0, 0.0, 0.0,
                                                             w0x, w0y, w0z)
            v2x, v2y, v2z = v0x + h * a1x, v0y + h * a1y, v0z + h * a1z
            a2x, a2y, a2z, x2, y2, z2, b2x, b2y, b2z = stage(context, R0, v2x, v2y, v2z, h * x1, h * y1, h * z1,
                                                             w0x + h * b1x, w0y + h * b1y, w0z + h * b1z)
            v3x, v3y, v3z = v0x + h * a2x, v0y + h * a2y, v0z + h * a2z
            a3x, a3y, a3z, x3, y3, z3, b3x, b3y, b3z = stage(context, R0, v3x, v3y, v3z, h * x2, h * y2, h * z2,
                                                             w0x + h * b2x, w0y + h * b2y, w0z + h * b2z)
            v4x, v4y, v4z = v0x + dt * a3x, v0y + dt * a3y, v0z + dt * a3z
            a4x, a4y, a4z, x4, y4, z4, b4x, b4y, b4z = stage(context, R0, v4x, v4y, v4z, dt * x3, dt * y3,
                                                             dt * z3, w0x + dt * b3x, w0y + dt * b3y,
                                                             w0z + dt * b3z)
        except (ValueError, OverflowError) as exc:  # math.sin(inf) etc. once the state has blown up
            raise DynamicsError("integration diverged in a step of %g s from %s: %s" % (dt, state, exc)) from None
        s = dt / 6.0
        y = (p0x + s * (v0x + 2.0 * (v2x + v3x) + v4x),
             p0y + s * (v0y + 2.0 * (v2y + v3y) + v4y),
             p0z + s * (v0z + 2.0 * (v2z + v3z) + v4z),
             v0x + s * (a1x + 2.0 * (a2x + a3x) + a4x),
             v0y + s * (a1y + 2.0 * (a2y + a3y) + a4y),
             v0z + s * (a1z + 2.0 * (a2z + a3z) + a4z))
        xx = s * (x1 + 2.0 * (x2 + x3) + x4)
        xy = s * (y1 + 2.0 * (y2 + y3) + y4)
        xz = s * (z1 + 2.0 * (z2 + z3) + z4)
        w = (w0x + s * (b1x + 2.0 * (b2x + b3x) + b4x),
             w0y + s * (b1y + 2.0 * (b2y + b3y) + b4y),
             w0z + s * (b1z + 2.0 * (b2z + b3z) + b4z))
        isfinite = math.isfinite
        if not isfinite(sum(y) + xx + xy + xz + sum(w)) and not all(map(isfinite, y + (xx, xy, xz) + w)):
            raise DynamicsError("integration diverged (non-finite state) in a step of %g s from %s" % (dt, state))
        R1 = _matmul(R0, _exp_rotation(xx, xy, xz))
        # One Newton-Schulz polish, R (3 I - R^T R) / 2 (as _rk4).
        a0, a1, a2, a3, a4, a5, a6, a7, a8 = R1
        n0 = 1.5 - 0.5 * (a0 * a0 + a3 * a3 + a6 * a6)
        n4 = 1.5 - 0.5 * (a1 * a1 + a4 * a4 + a7 * a7)
        n8 = 1.5 - 0.5 * (a2 * a2 + a5 * a5 + a8 * a8)
        n1 = -0.5 * (a0 * a1 + a3 * a4 + a6 * a7)
        n2 = -0.5 * (a0 * a2 + a3 * a5 + a6 * a8)
        n5 = -0.5 * (a1 * a2 + a4 * a5 + a7 * a8)
        # One array for the whole state, the fields are views of disjoint parts of it.
        data = np.array(y + _matmul(R1, (n0, n1, n2, n1, n4, n5, n2, n5, n8)) + w)
        return RigidBodyState(data[0:3], data[3:6], data[6:15].reshape(3, 3), data[15:18])

    def _rk4(self, state: RigidBodyState, dt: float, contexts: Sequence[_StepContext]) -> RigidBodyState:
        """One classic RK4 step in the chart; ``contexts`` hold the inputs at t, t + dt/2, t + dt."""
        R0 = _as_mat3(state.rotation)
        y0 = state.position.tolist() + state.velocity.tolist() + [0.0, 0.0, 0.0] + state.omega.tolist()
        start, middle, end = contexts
        h = 0.5 * dt
        try:
            stage = self._chart_derivative
            k1 = stage(start, R0, y0)
            k2 = stage(middle, R0, [a + h * b for a, b in zip(y0, k1)])
            k3 = stage(middle, R0, [a + h * b for a, b in zip(y0, k2)])
            k4 = stage(end, R0, [a + dt * b for a, b in zip(y0, k3)])
        except (ValueError, OverflowError) as exc:  # math.sin(inf) etc. once the state has blown up
            raise DynamicsError("integration diverged in a step of %g s from %s: %s" % (dt, state, exc)) from None
        s = dt / 6.0
        y1 = [a + s * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(y0, k1, k2, k3, k4)]
        if not all(map(math.isfinite, y1)):
            raise DynamicsError("integration diverged (non-finite state) in a step of %g s from %s" % (dt, state))
        R1 = _matmul(R0, _exp_rotation(y1[6], y1[7], y1[8]))
        # One Newton-Schulz polish, R (3 I - R^T R) / 2, removes the O(eps) drift that products of
        # rotations accumulate.
        a0, a1, a2, a3, a4, a5, a6, a7, a8 = R1
        n0 = 1.5 - 0.5 * (a0 * a0 + a3 * a3 + a6 * a6)
        n4 = 1.5 - 0.5 * (a1 * a1 + a4 * a4 + a7 * a7)
        n8 = 1.5 - 0.5 * (a2 * a2 + a5 * a5 + a8 * a8)
        n1 = -0.5 * (a0 * a1 + a3 * a4 + a6 * a7)
        n2 = -0.5 * (a0 * a2 + a3 * a5 + a6 * a8)
        n5 = -0.5 * (a1 * a2 + a4 * a5 + a7 * a8)
        R1 = _matmul(R1, (n0, n1, n2, n1, n4, n5, n2, n5, n8))
        return RigidBodyState(np.array(y1[0:3]), np.array(y1[3:6]), np.array(R1).reshape(3, 3),
                              np.array(y1[9:12]))

    def step(self, state: RigidBodyState, q: ArrayLike, q_dot: ArrayLike, dt: float) -> RigidBodyState:
        """Advance ``state`` by ``dt`` s with the joint command held: q (4 x 3) and q_dot (4 x 3) constant.

        Classic RK4 on SO(3) (see the module docstring). Returns a new state; ``state`` is not modified.
        Raises ValueError for bad input and :class:`DynamicsError` if the result is not finite.
        """
        dt = _check_dt(dt)
        state = state.validate()
        context = self._context_from_joints(_joint_array(q, "q"), _joint_array(q_dot, "q_dot"))
        return self._rk4_held(state, dt, context)

    def step_trusted(self, state: RigidBodyState, q: np.ndarray, q_dot: np.ndarray, dt: float) -> RigidBodyState:
        """:meth:`step` without re-validating ``state``, for a simulator loop that feeds back the states
        this model returned (finite, R in SO(3) by construction). ``q``, ``q_dot`` must be finite float
        arrays of shape (4, 3) (or such nested sequences of floats, legs x joints) and ``dt`` a positive
        float; the caller checks them. Same result as :meth:`step`; kinematics errors and
        :class:`DynamicsError` are raised as there."""
        flat = leg_kinematics_flat(q.tolist() if isinstance(q, np.ndarray) else q,
                                    q_dot.tolist() if isinstance(q_dot, np.ndarray) else q_dot, self.params)
        return self._rk4_held(state, dt, _StepContext.from_flat(flat, self.net_paw_buoyancy, self._restoring))

    def step_continuous(self, state: RigidBodyState, t: float, dt: float,
                        joint_trajectory: JointTrajectory) -> RigidBodyState:
        """RK4 step from time ``t`` with the joint inputs sampled from ``joint_trajectory(t) -> (q, q_dot)``
        at t, t + dt/2 and t + dt instead of held: the reference solution of a smooth leg motion
        (fourth order in dt), used to validate the zero-order-hold :meth:`step`."""
        dt = _check_dt(dt)
        state = state.validate()
        contexts = [self._context(self.leg_input(*joint_trajectory(t + fraction * dt)))
                    for fraction in (0.0, 0.5, 1.0)]
        return self._rk4(state, dt, contexts)

    # ---- energy ------------------------------------------------------------------------------

    def kinetic_energy(self, state: RigidBodyState) -> float:
        """1/2 m |v|^2 + 1/2 omega^T I omega, J."""
        v, w = state.velocity, state.omega
        return 0.5 * self.mass * float(v @ v) + 0.5 * float(w @ (self.inertia @ w))

    def potential_energy(self, state: RigidBodyState, q: ArrayLike) -> float:
        """Potential of the conservative forces for legs held at ``q``, J (zero at p = 0, R = I, r_cb = 0).

        Paw buoyancy: -B_net sum_i z_hat . (p + R r_e,i^B); centre-of-buoyancy torque: -B z_hat . R r_cb.
        With the legs still, kinetic + potential energy can only decrease (drag dissipates).
        """
        legs = self.leg_input(q, np.zeros((NUM_LEGS, 3)))
        R = state.rotation
        heights = state.position[2] * NUM_LEGS + float(R[2, :] @ legs.foot_positions.sum(axis=0))
        return -self.net_paw_buoyancy * heights - self.restoring_force * float(R[2, :] @ self.restoring_offset)


def _check_dt(dt: float) -> float:
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError("dt must be a positive finite number of seconds, got %r" % (dt,))
    return dt
