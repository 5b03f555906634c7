"""Floating-base dynamics of the underwater quadruped and its Runge-Kutta integrator.

Model (paper section "Body Dynamics"): the torso is a rigid body driven by the paw drag of the four
legs (eq. (force_leg), (torque_leg)), the net paw buoyancy (eq. (buoy_torque)) and the inertia-box body
drag (eq. (drag_total)):

    m dv_B^W/dt = sum_i F_i^W + F_buoyancy^W + R f_drag^B                               eq. (trans)
    I domega_B^B/dt + omega x I omega = sum_i tau_i^B + tau_buoyancy^B + tau_drag^B      eq. (rot)
    dp^W/dt = v_B^W,   dR_B^W/dt = R hat(omega_B^B)

Every force law comes from :mod:`quadruped_control.model.hydrodynamics`: the readable functions for
the telemetry breakdown :meth:`FloatingBaseModel.wrench`, their float fast paths for the integrator.

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
Runge-Kutta in the Munthe-Kaas form on SO(3) (:mod:`.rigid_body`). Within a step R = R_0 exp(hat(xi))
and the rotation vector xi obeys d xi/dt = J_r(xi)^-1 omega, so every stage uses an exact rotation,
the scheme keeps fourth order, and the new R is a rotation to machine precision.
Because q and q_dot are held constant over a step (zero-order hold of the command), the foot positions
r_e,i^B and the joint-induced foot velocities J_P,i^B q_dot_i are computed once per step
(:class:`~.rigid_body.StepContext`); the stages (:meth:`FloatingBaseModel._stage`) only re-evaluate what
depends on v, R and omega, on plain floats (faster than numpy for 3-vectors).
:meth:`FloatingBaseModel.step` and :meth:`~FloatingBaseModel.step_trusted` run that held-input RK4 on
unpacked floats (``_rk4_held``: no position in the stages, since no force depends on it); the generic
``_rk4`` over 12-float chart states (:meth:`~FloatingBaseModel._chart_derivative`) is the reference it is
tested against (the tank plant has its own, :func:`~.tank_dynamics.tank_rk4`).
:meth:`FloatingBaseModel.step_continuous` samples a smooth joint trajectory at the stage times instead
(reference solutions). A non-finite result raises :class:`DynamicsError` and leaves the input state as is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.jit import jitable
from quadruped_common.so3 import hat
from quadruped_control.model import hydrodynamics
from quadruped_control.model.hydrodynamics import body_drag_f, paw_drag_wrench_f
from quadruped_control.model.kinematics import leg_kinematics, leg_kinematics_rows
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.rigid_body import (NUM_LEGS, DynamicsError, Mat3, RigidBodyState, StateDerivative,
                                                     StepContext, as_mat3, chart_point, chart_step_end, check_dt,
                                                     diverged, joint_array, vector3)

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: A joint trajectory for :meth:`FloatingBaseModel.step_continuous`: t -> (q, q_dot), each 4 x 3.
JointTrajectory = Callable[[float], Tuple[ArrayLike, ArrayLike]]

__all__ = [
    "DynamicsError",
    "FloatingBaseModel",
    "JointTrajectory",
    "LegInput",
    "RigidBodyState",
    "StateDerivative",
    "Wrench",
    "body_wrench_f",
    "held_joint_input",
    "joint_velocity",
    "paper_rk4_held",
    "paper_stage",
]


# --------------------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------------------

def joint_velocity(q_previous: ArrayLike, q_current: ArrayLike, dt: float) -> np.ndarray:
    """Commanded joint velocity by backward finite difference, (q_k - q_(k-1)) / dt, shape (4, 3).

    The paper obtains q_dot "through finite differences" of the commanded angles (section "Body
    Dynamics"). Raises ValueError for a non-positive dt or malformed/non-finite angles.
    """
    dt = check_dt(dt)
    return (joint_array(q_current, "q_current") - joint_array(q_previous, "q_previous")) / dt


def held_joint_input(q_previous: ArrayLike, q_current: ArrayLike, dt: float) -> Tuple[np.ndarray, np.ndarray]:
    """Joint input (q_hold, q_dot) to hold over the step that moves the joints from q_(k-1) to q_k.

    The joints are taken to travel linearly between consecutive commands, so the held angles are the
    midpoint (q_(k-1) + q_k) / 2 and q_dot the finite difference (q_k - q_(k-1)) / dt. Holding the
    midpoint makes the zero-order hold second-order accurate in dt (holding either end is first
    order); the paper only says the velocities come from finite differences. Both arrays are (4, 3).
    """
    q_dot = joint_velocity(q_previous, q_current, dt)
    q_hold = 0.5 * (joint_array(q_previous, "q_previous") + joint_array(q_current, "q_current"))
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
        q_arr = joint_array(q, "q")
        q_dot_arr = joint_array(q_dot, "q_dot")
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

# --------------------------------------------------------------------------------------------------
# The equations of motion on floats (compiled too: quadruped_common.jit)
# --------------------------------------------------------------------------------------------------

@jitable
def body_wrench_f(feet: Sequence[Sequence[float]], drag_constant: float, drag: Sequence[float],
                  up_torque: Sequence[float], bx: float, by: float, bz: float, R: Mat3, wx: float, wy: float,
                  wz: float) -> Tuple[float, float, float, float, float, float]:
    """Force (body axes) and torque (body, about the centre of mass) of the paw drag, body drag, paw
    buoyancy and restoring terms of eq. (trans), (rot), on floats, for the body-axes velocity
    (bx, by, bz) = R^T v and rate omega: the hydrodynamics fast paths
    (:func:`~quadruped_control.model.hydrodynamics.paw_drag_wrench_f` over the legs' rows ``feet``,
    :func:`~quadruped_control.model.hydrodynamics.body_drag_f` with the coefficients ``drag``) and the
    buoyancy matrix U (``up_torque``, row-major) of the :class:`~.rigid_body.StepContext`. Used by
    :func:`paper_stage` and by the tank plant (:mod:`quadruped_control.sim.plants.tank_dynamics`). Paw
    buoyancy's force is left to the caller.
    """
    fx, fy, fz, tx, ty, tz = paw_drag_wrench_f(feet, drag_constant, bx, by, bz, wx, wy, wz)
    dfx, dfy, dfz, dtx, dty, dtz = body_drag_f(drag, bx, by, bz, wx, wy, wz)
    # Paw buoyancy and restoring torques: U (R^T z_hat), R^T z_hat = third row of R.
    u0, u1, u2, u3, u4, u5, u6, u7, u8 = up_torque
    r6, r7, r8 = R[6], R[7], R[8]
    return (fx + dfx, fy + dfy, fz + dfz,
            tx + dtx + (u0 * r6 + u1 * r7 + u2 * r8),
            ty + dty + (u3 * r6 + u4 * r7 + u5 * r8),
            tz + dtz + (u6 * r6 + u7 * r7 + u8 * r8))


@jitable
def paper_stage(feet: Sequence[Sequence[float]], drag_constant: float, drag: Sequence[float],
                up_torque: Sequence[float], lift: float, inertia: Mat3, inertia_inverse: Mat3, inverse_mass: float,
                R0: Mat3, vx: float, vy: float, vz: float, x: float, y: float, z: float, wx: float, wy: float,
                wz: float) -> Tuple[float, ...]:
    """(dv/dt, dxi/dt, domega/dt) (9 floats) of the chart state with velocity v, chart coordinate
    xi = (x, y, z) (R = R0 exp(hat(xi))) and rate omega: eq. (trans), (rot) and the chart rate
    J_r(xi)^-1 omega. dp/dt = v is left to the caller (no force depends on the position). The
    integrator's hot path, on floats, the forces from :func:`body_wrench_f`; ``lift`` the paw buoyancy
    force F_buoyancy^W . z_hat, ``inertia``, ``inertia_inverse`` row-major I and I^-1."""
    R, (rx, ry, rz) = chart_point(R0, x, y, z, wx, wy, wz)
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
    bx, by, bz = r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz
    fx, fy, fz, tx, ty, tz = body_wrench_f(feet, drag_constant, drag, up_torque, bx, by, bz, R, wx, wy, wz)
    # I domega/dt = tau - omega x I omega, eq. (rot).
    i0, i1, i2, i3, i4, i5, i6, i7, i8 = inertia
    hx, hy, hz = i0 * wx + i1 * wy + i2 * wz, i3 * wx + i4 * wy + i5 * wz, i6 * wx + i7 * wy + i8 * wz
    tx -= wy * hz - wz * hy
    ty -= wz * hx - wx * hz
    tz -= wx * hy - wy * hx
    j0, j1, j2, j3, j4, j5, j6, j7, j8 = inertia_inverse
    # m dv/dt = R f^B + F_buoyancy^W, eq. (trans).
    return ((r0 * fx + r1 * fy + r2 * fz) * inverse_mass,
            (r3 * fx + r4 * fy + r5 * fz) * inverse_mass,
            (r6 * fx + r7 * fy + r8 * fz + lift) * inverse_mass,
            rx, ry, rz,
            j0 * tx + j1 * ty + j2 * tz, j3 * tx + j4 * ty + j5 * tz, j6 * tx + j7 * ty + j8 * tz)


@jitable
def paper_rk4_held(feet: Sequence[Sequence[float]], drag_constant: float, drag: Sequence[float],
                   up_torque: Sequence[float], lift: float, inertia: Mat3, inertia_inverse: Mat3, inverse_mass: float,
                   R0: Mat3, p0x: float, p0y: float, p0z: float, v0x: float, v0y: float, v0z: float, w0x: float,
                   w0y: float, w0z: float, dt: float) -> Tuple[float, ...]:
    """One classic RK4 step of :func:`paper_stage` in the chart around R0, the legs held over it: the
    chart state at its end (p, v, xi, omega), 12 floats (:func:`~.rigid_body.chart_step_end` maps it
    back to a state). The stages only see (v, xi, omega) since no force depends on the position, whose
    stage derivatives are the stage velocities. Same arithmetic as the generic
    :meth:`FloatingBaseModel._rk4` (the tests compare them)."""
    h = 0.5 * dt
    a1x, a1y, a1z, x1, y1, z1, b1x, b1y, b1z = paper_stage(
        feet, drag_constant, drag, up_torque, lift, inertia, inertia_inverse, inverse_mass, R0,
        v0x, v0y, v0z, 0.0, 0.0, 0.0, w0x, w0y, w0z)
    v2x, v2y, v2z = v0x + h * a1x, v0y + h * a1y, v0z + h * a1z
    a2x, a2y, a2z, x2, y2, z2, b2x, b2y, b2z = paper_stage(
        feet, drag_constant, drag, up_torque, lift, inertia, inertia_inverse, inverse_mass, R0,
        v2x, v2y, v2z, h * x1, h * y1, h * z1, w0x + h * b1x, w0y + h * b1y, w0z + h * b1z)
    v3x, v3y, v3z = v0x + h * a2x, v0y + h * a2y, v0z + h * a2z
    a3x, a3y, a3z, x3, y3, z3, b3x, b3y, b3z = paper_stage(
        feet, drag_constant, drag, up_torque, lift, inertia, inertia_inverse, inverse_mass, R0,
        v3x, v3y, v3z, h * x2, h * y2, h * z2, w0x + h * b2x, w0y + h * b2y, w0z + h * b2z)
    v4x, v4y, v4z = v0x + dt * a3x, v0y + dt * a3y, v0z + dt * a3z
    a4x, a4y, a4z, x4, y4, z4, b4x, b4y, b4z = paper_stage(
        feet, drag_constant, drag, up_torque, lift, inertia, inertia_inverse, inverse_mass, R0,
        v4x, v4y, v4z, dt * x3, dt * y3, dt * z3, w0x + dt * b3x, w0y + dt * b3y, w0z + dt * b3z)
    s = dt / 6.0
    return (p0x + s * (v0x + 2.0 * (v2x + v3x) + v4x),
            p0y + s * (v0y + 2.0 * (v2y + v3y) + v4y),
            p0z + s * (v0z + 2.0 * (v2z + v3z) + v4z),
            v0x + s * (a1x + 2.0 * (a2x + a3x) + a4x),
            v0y + s * (a1y + 2.0 * (a2y + a3y) + a4y),
            v0z + s * (a1z + 2.0 * (a2z + a3z) + a4z),
            s * (x1 + 2.0 * (x2 + x3) + x4), s * (y1 + 2.0 * (y2 + y3) + y4), s * (z1 + 2.0 * (z2 + z3) + z4),
            w0x + s * (b1x + 2.0 * (b2x + b3x) + b4x), w0y + s * (b1y + 2.0 * (b2y + b3y) + b4y),
            w0z + s * (b1z + 2.0 * (b2z + b3z) + b4z))


# --------------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------------

class FloatingBaseModel:
    """The paper's floating-base model, eq. (trans), (rot), with a fixed-step RK4 integrator on SO(3).

    ``restoring_offset``: optional centre of buoyancy of the torso relative to the centre of mass, in
    the body frame (m); ``restoring_force``: the torso buoyancy B acting there (N, default m g). Both
    are beyond the paper (which assumes they coincide); the force is balanced by the rope, only the
    torque r_cb x (R^T [0, 0, B]) acts. A centre of buoyancy above the centre of mass rights the robot.
    """

    #: Plant name (:mod:`quadruped_control.sim.plants`).
    name = "paper"
    #: The residual magnetic field at the IMU (body axes, in units of the earth's horizontal field) when the
    #: IMU reports a heading other than the true one (:mod:`quadruped_control.sim.magnetic_heading`); None:
    #: the true attitude (the paper's plant; the tank's unless its parameters set one).
    imu_field_residual: Optional[np.ndarray] = None

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
            self.restoring_offset = vector3(restoring_offset, "restoring_offset")
            force = self.mass * params.gravity if restoring_force is None else float(restoring_force)
            if not (math.isfinite(force) and force >= 0.0):
                raise ValueError("restoring_force must be a finite non-negative force in N, got %r"
                                 % (restoring_force,))
            self.restoring_force = force
        # r_cb x (R^T B z_hat) = B hat(r_cb) R[2, :]
        self._restoring_matrix = hydrodynamics.torso_buoyancy_torque_matrix(self.restoring_force,
                                                                             self.restoring_offset)
        # Float copies for the Runge-Kutta stages.
        self._restoring = as_mat3(self._restoring_matrix)
        self._inertia = as_mat3(self.inertia)
        self._inertia_inverse = as_mat3(self.inertia_inverse)
        self._inverse_mass = 1.0 / self.mass
        self._drag = self.drag.flat

    # ---- inputs ------------------------------------------------------------------------------

    def attach(self, state: RigidBodyState) -> None:
        """Fix whatever the plant ties to the world at the start ``state`` (nothing here; the tank plant's
        rope anchor)."""

    def leg_input(self, q: ArrayLike, q_dot: ArrayLike) -> LegInput:
        """:class:`LegInput` (foot positions and joint-induced foot velocities) for q, q_dot (4 x 3)."""
        return LegInput.from_joints(q, q_dot, self.params)

    def _context(self, legs: LegInput) -> StepContext:
        return StepContext.from_rows(np.hstack((legs.foot_positions, legs.joint_foot_velocities)).tolist(),
                                     self.net_paw_buoyancy, self._restoring)

    def _context_from_joints(self, q: Sequence[Sequence[float]], q_dot: Sequence[Sequence[float]]) -> StepContext:
        """Step context straight from finite joint angles and rates (4 x 3 arrays or nested float
        sequences), floats all the way."""
        rows = leg_kinematics_rows(q.tolist() if isinstance(q, np.ndarray) else q,
                                   q_dot.tolist() if isinstance(q_dot, np.ndarray) else q_dot, self.params)
        return StepContext(rows, self.net_paw_buoyancy, self._restoring)

    # ---- forces ------------------------------------------------------------------------------

    def wrench(self, state: RigidBodyState, q: ArrayLike, q_dot: ArrayLike) -> Wrench:
        """Breakdown of every force and torque on the torso (telemetry, tests), from the readable
        :mod:`~quadruped_control.model.hydrodynamics` functions. The integrator uses their fast paths."""
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
        vx, vy, vz = state.velocity.tolist()
        wx, wy, wz = state.omega.tolist()
        rates = self._stage(context, as_mat3(state.rotation), vx, vy, vz, 0.0, 0.0, 0.0, wx, wy, wz)
        return StateDerivative(state.velocity.copy(), np.array(rates[:3]), state.rotation @ hat(state.omega),
                               np.array(rates[6:]))

    def _body_wrench(self, context: StepContext, bx: float, by: float, bz: float, R: Mat3,
                     wx: float, wy: float, wz: float) -> Tuple[float, float, float, float, float, float]:
        """:func:`body_wrench_f` with this plant's drag and the step's legs."""
        return body_wrench_f(context.feet, self.drag_constant, self._drag, context.up_torque, bx, by, bz, R, wx, wy, wz)

    def _stage(self, context: StepContext, R0: Mat3, vx: float, vy: float, vz: float, x: float, y: float,
               z: float, wx: float, wy: float, wz: float) -> Tuple[float, ...]:
        """:func:`paper_stage` of this plant and the step's legs."""
        return paper_stage(context.feet, self.drag_constant, self._drag, context.up_torque, context.lift,
                           self._inertia, self._inertia_inverse, self._inverse_mass, R0, vx, vy, vz, x, y, z,
                           wx, wy, wz)

    def _chart_derivative(self, context: StepContext, R0: Mat3, y: Sequence[float]) -> Tuple[float, ...]:
        """d/dt of the chart state y = (p, v, xi, omega), 12 floats, with R = R0 exp(hat(xi))."""
        return (y[3], y[4], y[5]) + self._stage(context, R0, *y[3:12])

    # ---- integration -------------------------------------------------------------------------

    def _rk4_held(self, state: RigidBodyState, dt: float, context: StepContext) -> RigidBodyState:
        """:meth:`_rk4` for an input held over the step (one context for all stages):
        :func:`paper_rk4_held` on unpacked floats."""
        R0 = tuple(state.rotation.ravel().tolist())
        p0x, p0y, p0z = state.position.tolist()
        v0x, v0y, v0z = state.velocity.tolist()
        w0x, w0y, w0z = state.omega.tolist()
        try:
            y = paper_rk4_held(context.feet, self.drag_constant, self._drag, context.up_torque, context.lift,
                               self._inertia, self._inertia_inverse, self._inverse_mass, R0, p0x, p0y, p0z,
                               v0x, v0y, v0z, w0x, w0y, w0z, dt)
        except (ValueError, OverflowError) as exc:  # math.sin(inf) etc. once the state has blown up
            raise diverged(dt, state, str(exc)) from None
        return chart_step_end(R0, y[0:6], y[6:9], y[9:12], dt, state)

    def _rk4(self, state: RigidBodyState, dt: float, contexts: Sequence[StepContext]) -> RigidBodyState:
        """One classic RK4 step in the chart; ``contexts`` hold the inputs at t, t + dt/2, t + dt."""
        R0 = as_mat3(state.rotation)
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
            raise diverged(dt, state, str(exc)) from None
        s = dt / 6.0
        y1 = tuple(a + s * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(y0, k1, k2, k3, k4))
        return chart_step_end(R0, y1[0:6], y1[6:9], y1[9:12], dt, state)

    def step(self, state: RigidBodyState, q: ArrayLike, q_dot: ArrayLike, dt: float) -> RigidBodyState:
        """Advance ``state`` by ``dt`` s with the joint command held: q (4 x 3) and q_dot (4 x 3) constant.

        Classic RK4 on SO(3) (see the module docstring). Returns a new state; ``state`` is not modified.
        Raises ValueError for bad input and :class:`DynamicsError` if the result is not finite.
        """
        dt = check_dt(dt)
        state = state.validate()
        context = self._context_from_joints(joint_array(q, "q"), joint_array(q_dot, "q_dot"))
        return self._rk4_held(state, dt, context)

    def step_trusted(self, state: RigidBodyState, q: np.ndarray, q_dot: np.ndarray, dt: float) -> RigidBodyState:
        """:meth:`step` without re-validating ``state``, for a simulator loop that feeds back the states
        this model returned (finite, R in SO(3) by construction). ``q``, ``q_dot`` must be finite float
        arrays of shape (4, 3) (or such nested sequences of floats, legs x joints) and ``dt`` a positive
        float; the caller checks them. Same result as :meth:`step`; kinematics errors and
        :class:`DynamicsError` are raised as there."""
        return self._rk4_held(state, dt, self._context_from_joints(q, q_dot))

    def step_continuous(self, state: RigidBodyState, t: float, dt: float,
                        joint_trajectory: JointTrajectory) -> RigidBodyState:
        """RK4 step from time ``t`` with the joint inputs sampled from ``joint_trajectory(t) -> (q, q_dot)``
        at t, t + dt/2 and t + dt instead of held: the reference solution of a smooth leg motion
        (fourth order in dt), used to validate the zero-order-hold :meth:`step`."""
        dt = check_dt(dt)
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
