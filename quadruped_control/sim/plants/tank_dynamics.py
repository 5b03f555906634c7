"""The tank plant's equations of motion, eq. (tank) of docs/tank_model.md, on floats: one source for the
per-trial plant (:class:`~quadruped_control.sim.plants.tank.TankModel`, plain Python) and the batch
(:class:`~quadruped_control.sim.plants.tank_batch.TankPlantBatch`, a loop over trials compiled by numba
when it is installed, :mod:`quadruped_common.jit`).

- :func:`rope_force`, :func:`rope_twist`, :func:`whole_twist`, :func:`rope_torsion_torque`,
  :func:`twist_relaxation_update`, :func:`appendage_damping_torque`, :func:`paw_wake_update`,
  :func:`body_wake_update`, :func:`floating_block_update`, :func:`hook_friction_update`,
  :func:`wound_friction_limit`: the tank's own force laws, the paws' wake,
  the water the body's appendages set turning, the floating block the rope hangs from and the friction
  where the rope is tied to the hook, with the tether wound round it (physics and sources in
  docs/tank_model.md);
- :func:`tilt_vector`, :func:`tether_bend_torque`, :func:`tether_relaxation_update`: the tether bent where it
  leaves the body, a standard linear solid on the body's tilt;
- :func:`disturbance_update`, :func:`world_to_body`: the torque of a tank that is not still, an
  Ornstein-Uhlenbeck process per world axis, held over each step;
- :func:`leg_sums`, :func:`mass_solver`, :func:`solve_mass`: the mass matrix
  M = M_RB + M_A + sum_i M_paw(r_i) of a held step and its solution by the Schur complement;
- :func:`tank_forces`: the right-hand side of eq. (tank), the paper's forces
  (:func:`~quadruped_control.sim.plants.paper.body_wrench_f`) plus the rope, hydrostatics, candidate
  effects, Kirchhoff terms of M_RB + M_A and the paws' added-mass terms;
- :func:`tank_chart_derivative`, :func:`tank_rk4`: the classic RK4 in the SO(3) chart over the
  12-float chart state (p, v, xi, omega) (the rope makes the forces depend on the position).

The per-trial constants travel as a :data:`TankConstants` tuple (built by
:meth:`TankModel.constants <quadruped_control.sim.plants.tank.TankModel.constants>`), whose fields are
floats, 3-vectors, the body drag coefficients (8) and M_RB + M_A (36, row-major): tuples in the
per-trial plant, rows of arrays in the batch.
"""
from __future__ import annotations

import math
from typing import Any, Sequence, Tuple

from quadruped_common.jit import jitable
from quadruped_control.model.hydrodynamics import paw_drag_f, paw_velocity_f
from quadruped_control.model.kinematics import leg_jacobian_row
from quadruped_control.sim.plants.paper import body_wrench_f
from quadruped_control.sim.plants.rigid_body import Mat3, chart_point

__all__ = ["TANK_CONSTANT_AT", "TANK_CONSTANT_FIELDS", "TankConstants", "appendage_damping_torque", "body_wake_update",
           "disturbance_coefficients", "disturbance_update", "floating_block_update", "hook_friction_update",
           "leg_sums", "mass_solver", "paw_joint_loads", "paw_wake_update", "rope_force", "rope_torsion_torque",
           "rope_twist", "solve_mass", "tank_chart_derivative", "tank_forces", "tank_rk4", "tether_bend_torque",
           "tether_relaxation_update", "tilt_vector", "twist_relaxation_update", "whole_twist", "world_to_body",
           "wound_friction_limit"]

Vec3 = Tuple[float, float, float]

#: (drag_constant, body drag coefficients (8), extra lift (torso buoyancy - weight, N), suspension (bool), hook (3, m),
#: anchor (6: position (m) and velocity (m/s) of the rope's upper end, world), rope (length, stiffness, damping),
#: torsion (6: stiffness k_t, damping c_t, the rope's whole twist at the step's start, rad: :func:`whole_twist`, then
#: the relaxing branch's stiffness k_r in N m/rad, its relaxation time tau_r in s and its relaxed twist s at the step's
#: start, rad: :func:`rope_torsion_torque`), the attitude at the step's start that twist belongs to (9), appendage
#: damping linear (3), quadratic (3), M_RB + M_A (36), paw added mass m_a, paw wake (fraction kappa, time constant tau_w
#: in s, body share s_b), body wake (fraction kappa_b, time constant tau_b in s), tether (6: its elastic stiffness k_e
#: and relaxing stiffness k in N m/rad, relaxation time tau in s, and the relaxed tilt s at the step's start, world
#: axes, rad: :func:`tether_bend_torque`))
TankConstants = Tuple[Any, ...]

#: The names of :data:`TankConstants`' fields, in order: the one list that the per-trial plant (which replaces
#: the fields it carries from step to step by position, :data:`TANK_CONSTANT_AT`) and the batch (which keeps one
#: array per field) read. The tuple itself stays positional because the compiled kernels type it field by field.
TANK_CONSTANT_FIELDS = ("drag_constant", "drag", "extra_lift", "suspension", "hook", "anchor", "rope", "torsion",
                        "untwisted", "linear", "quadratic", "body_m", "paw_added_mass", "paw_wake_fraction",
                        "paw_wake_time_constant", "paw_wake_body_share", "body_wake_fraction", "body_wake_time_constant",
                        "tether")
#: Each field's position in :data:`TankConstants` by name.
TANK_CONSTANT_AT = {name: position for position, name in enumerate(TANK_CONSTANT_FIELDS)}


@jitable
def _cross(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> Vec3:
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@jitable
def _hook_motion(px: float, py: float, pz: float, vx: float, vy: float, vz: float, R: Sequence[float], wx: float,
                 wy: float, wz: float, hook: Sequence[float]) -> Tuple[float, ...]:
    """The hook's position p + R h and velocity v + R (omega x h), world (6 floats), for the body's p, v
    (world), R (row-major) and omega (body axes): what the rope sees (:func:`tank_forces`,
    :func:`floating_block_update`)."""
    hx, hy, hz = hook[0], hook[1], hook[2]
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8]
    ax, ay, az = _cross(wx, wy, wz, hx, hy, hz)
    return (px + (r0 * hx + r1 * hy + r2 * hz), py + (r3 * hx + r4 * hy + r5 * hz),
            pz + (r6 * hx + r7 * hy + r8 * hz), vx + (r0 * ax + r1 * ay + r2 * az),
            vy + (r3 * ax + r4 * ay + r5 * az), vz + (r6 * ax + r7 * ay + r8 * az))


@jitable
def rope_force(hook_world: Sequence[float], hook_velocity: Sequence[float], anchor: Sequence[float],
               length: float, stiffness: float, damping: float) -> Vec3:
    """Rope force on the hook, world frame (N): T d / |d| with d = anchor - hook and
    T = max(0, k (|d| - L_0) + c d|d|/dt) while |d| > L_0, zero when slack (a rope only pulls).
    ``hook_velocity``: the hook's velocity relative to the anchor (the anchor's own, a moving block's,
    subtracted: :func:`floating_block_update`)."""
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


@jitable
def appendage_damping_torque(omega: Sequence[float], linear: Sequence[float], quadratic: Sequence[float]) -> Vec3:
    """tau_appendage = -(c_lin + c_quad |omega|) omega per body axis (N m): linear plus quadratic
    rotational damping of the legs, housings and corners the inertia box leaves out (docs/tank_model.md)."""
    return (-(linear[0] + quadratic[0] * abs(omega[0])) * omega[0],
            -(linear[1] + quadratic[1] * abs(omega[1])) * omega[1],
            -(linear[2] + quadratic[2] * abs(omega[2])) * omega[2])


@jitable
def rope_twist(R: Sequence[float], R0: Sequence[float]) -> float:
    """Twist (rad, [-pi, pi]) of the rotation Q = R R0^T about the world vertical: the angle of the twist
    part of its swing-twist decomposition, 2 atan2(q_z, q_w) = 2 atan2(Q_10 - Q_01, 1 + tr Q).
    ``R``, ``R0``: row-major 3x3 (9 floats)."""
    q10 = R[3] * R0[0] + R[4] * R0[1] + R[5] * R0[2]
    q01 = R[0] * R0[3] + R[1] * R0[4] + R[2] * R0[5]
    trace = 0.0
    for k in range(9):
        trace += R[k] * R0[k]
    return 2.0 * math.atan2(q10 - q01, 1.0 + trace)


@jitable
def whole_twist(R: Sequence[float], reference_rotation: Sequence[float], reference_twist: float) -> float:
    """The rope's whole twist (rad, any number of turns) at ``R``: ``reference_twist``, its twist at the
    attitude ``reference_rotation`` a moment before, plus the :func:`rope_twist` of ``R`` from there.

    The twist is the integral of the body's rate about the world vertical, every turn counted: it depends on
    the path, so the plants carry it as state (:attr:`TankModel.twist
    <quadruped_control.sim.plants.tank.TankModel.twist>`), the reference moved to each step's start and end."""
    return reference_twist + rope_twist(R, reference_rotation)


@jitable
def rope_torsion_torque(R: Sequence[float], R0: Sequence[float], omega: Sequence[float], stiffness: float,
                        damping: float, reference: float, relaxing: float, relaxed: float) -> Vec3:
    """Body-axes torque (N m) of a rope twisted by theta = :func:`whole_twist` (R, R0, ``reference``): the spring's
    potential k_t theta^2 / 2, a damper on the twist's rate and the relaxing branch k_r (``relaxing``) against the
    relaxed twist s (``relaxed``, held over the step, :func:`twist_relaxation_update`), tau = -(k_t theta + k_r (theta -
    s) + c_t theta_dot) g, g the twist's gradient (theta_dot = g . omega, world axes; with Q = R R0^T,
    g = (Q_02, Q_12, 1 + Q_22) / (1 + Q_22)). ``R``, ``R0`` row-major (``R0`` the attitude where the twist was
    ``reference``: the plants' step start, so that g stays the world vertical to first order); ``omega`` body axes.
    Past a swing of 179.9 deg from R0 the twist is undefined and the rope exerts no torsion. Derivation:
    docs/tank_model.md, "rope torsion"."""
    q02 = R[0] * R0[6] + R[1] * R0[7] + R[2] * R0[8]
    q12 = R[3] * R0[6] + R[4] * R0[7] + R[5] * R0[8]
    level = 1.0 + R[6] * R0[6] + R[7] * R0[7] + R[8] * R0[8]
    if level < 1e-6:
        return (0.0, 0.0, 0.0)
    gx, gy = q02 / level, q12 / level
    # g in body axes, R^T g (g_z = 1)
    bx = R[0] * gx + R[3] * gy + R[6]
    by = R[1] * gx + R[4] * gy + R[7]
    bz = R[2] * gx + R[5] * gy + R[8]
    twist_rate = bx * omega[0] + by * omega[1] + bz * omega[2]
    theta = whole_twist(R, R0, reference)
    torque = -(stiffness * theta + damping * twist_rate)
    if relaxing > 0.0:  # exactly the two-branch torque without it
        torque -= relaxing * (theta - relaxed)
    return (torque * bx, torque * by, torque * bz)


@jitable
def twist_relaxation_update(twist: float, relaxed: float, relaxation_time: float, dt: float) -> float:
    """The relaxing twist's relaxed twist s (rad) after a step of ``dt`` s that ended at the whole twist
    ``twist`` (:func:`whole_twist`): ds/dt = (theta - s) / tau_r with theta held over the step, exactly,
    s + (1 - exp(-dt / tau_r)) (theta - s) (:func:`rope_torsion_torque`; as :func:`tether_relaxation_update`
    for the tilt)."""
    return relaxed + (1.0 - math.exp(-dt / relaxation_time)) * (twist - relaxed)


def disturbance_update(torque: Any, decay: Any, spread: Any, noise: Any) -> Any:
    """The tank's disturbance torque (N m, world axes) one step on: ``decay`` torque + ``spread`` noise, the exact
    step of an Ornstein-Uhlenbeck process dd = -d / tau_d dt + sigma sqrt(2 / tau_d) dW with decay = exp(-dt /
    tau_d) and spread = sigma sqrt(1 - decay^2) (:func:`disturbance_coefficients`), ``noise`` standard normal draws.
    Its stationary law is N(0, sigma^2) per axis and its autocorrelation exp(-|lag| / tau_d), whatever the step.
    Element-wise on numpy arrays: one trial's (3,) or a batch's (N, 3) with (N, 1) coefficients, the same
    operations in the same order either way (the two engines agree to the bit). Physics in docs/tank_model.md
    ("disturbance")."""
    return decay * torque + spread * noise


def disturbance_coefficients(std: float, correlation_time: float, dt: float) -> Tuple[float, float]:
    """(decay, spread) of :func:`disturbance_update` for a step of ``dt`` s: exp(-dt / tau_d) and
    sigma sqrt(1 - exp(-2 dt / tau_d)) (``std`` sigma in N m, ``correlation_time`` tau_d in s)."""
    decay = math.exp(-dt / correlation_time)
    return decay, std * math.sqrt(-math.expm1(-2.0 * dt / correlation_time))


@jitable
def world_to_body(R: Sequence[float], x: float, y: float, z: float) -> Vec3:
    """R^T (x, y, z): a world-axes vector in body axes (``R`` row-major, 9 floats, body to world)."""
    return (R[0] * x + R[3] * y + R[6] * z, R[1] * x + R[4] * y + R[7] * z, R[2] * x + R[5] * y + R[8] * z)


@jitable
def tilt_vector(R: Sequence[float]) -> Vec3:
    """The body's tilt theta (rad, world axes): the rotation vector of the shortest rotation that takes the
    world's up z_hat to the body's z axis R z_hat = (R_02, R_12, R_22), about the horizontal axis
    z_hat x R z_hat, by the angle between them. Its vertical component is 0: a turn about the vertical
    does not tilt. Exactly upside down (no horizontal axis) it is taken as 0. ``R`` row-major (9 floats)."""
    ax, ay = -R[5], R[2]
    sine = math.sqrt(ax * ax + ay * ay)
    scale = math.atan2(sine, R[8]) / sine if sine > 1e-12 else 1.0
    return ax * scale, ay * scale, 0.0


@jitable
def tether_bend_torque(R: Sequence[float], tether: Sequence[float]) -> Vec3:
    """Body-axes torque (N m) of the tether bent where it leaves the body, a standard linear solid on the
    tilt theta = :func:`tilt_vector` (R): R^T (-k_e theta - k (theta - s)), with ``tether`` = (k_e, k, tau,
    s_x, s_y, s_z) (:data:`TankConstants`): the elastic branch k_e (a cable that always springs back to
    hanging straight), the Maxwell branch k (the bend's resistance that fades as the cable re-hangs and its
    jacket creeps) and its relaxed tilt s, held over a step (:func:`tether_relaxation_update`). The elastic
    branch is the gradient of k_e |theta|^2 / 2: d|theta| = (theta / |theta|) . delta_phi for a rotation
    delta_phi about a horizontal world axis, and a turn about the vertical leaves |theta| as it is. Physics
    and sources in docs/tank_model.md ("tether bend")."""
    elastic, relaxing = tether[0], tether[1]
    tx, ty, tz = tilt_vector(R)
    mx = -elastic * tx - relaxing * (tx - tether[3])
    my = -elastic * ty - relaxing * (ty - tether[4])
    mz = -elastic * tz - relaxing * (tz - tether[5])
    return (R[0] * mx + R[3] * my + R[6] * mz, R[1] * mx + R[4] * my + R[7] * mz,
            R[2] * mx + R[5] * my + R[8] * mz)


@jitable
def tether_relaxation_update(R: Sequence[float], tether: Sequence[float], dt: float) -> Vec3:
    """The tether's relaxed tilt s after a step of ``dt`` s that ended at the attitude ``R`` (row-major):
    ds/dt = (theta - s) / tau with theta = :func:`tilt_vector` (R) held over the step, exactly,
    s + (1 - exp(-dt / tau)) (theta - s). ``tether`` as :func:`tether_bend_torque` (s at the step's start)."""
    tx, ty, tz = tilt_vector(R)
    a = 1.0 - math.exp(-dt / tether[2])
    return (tether[3] + a * (tx - tether[3]), tether[4] + a * (ty - tether[4]), tether[5] + a * (tz - tether[5]))


@jitable
def paw_wake_update(feet: Sequence[Sequence[float]], wake: Any, fraction: float, time_constant: float,
                    body_share: float, bx: float, by: float, bz: float, wx: float, wy: float, wz: float, dt: float,
                    drag_feet: Any) -> None:
    """Advance each paw's wake over a held step and write the rows its drag sees (docs/tank_model.md).

    ``wake`` (4 x 3, body axes, m/s, in place): the water each paw has set moving; it relaxes towards the
    fraction kappa of the paw's velocity that builds it, u_w,i = c_i + s_b (b + omega x r_i): the stroke's
    own velocity c_i (the legs' rows ``feet``) and the share s_b (``body_share``) of the velocity the
    body's motion gives the paw (body velocity b, rate omega; s_b = 1: the paw's whole velocity u_i of
    :func:`~quadruped_control.model.hydrodynamics.paw_velocity_f`), held over the step:
    dw/dt = -omega x w + (kappa u_w,i - w) / tau_w. The first term is the transport: the wake is water
    moving in the tank, so in the turning body's axes it turns the other way (-omega x w, as any
    world-fixed vector seen from the body). Split over the step: the turn exp(-hat(omega) dt) first
    (Rodrigues, exact for the held omega), then the relaxation solved exactly,
    w <- kappa u_w,i + (w - kappa u_w,i) exp(-dt / tau_w).
    ``drag_feet`` (4 x 6, out): the rows (r_i, c_i - w_i), so that the drag law sees u_i - w_i, the paw's
    velocity relative to its wake."""
    decay = math.exp(-dt / time_constant)
    rate = math.sqrt(wx * wx + wy * wy + wz * wz)
    turning = rate > 0.0
    kx, ky, kz, cos_a, sin_a = 0.0, 0.0, 0.0, 1.0, 0.0
    if turning:  # exp(-hat(omega) dt) w = w cos a - sin a (k x w) + (1 - cos a) (k . w) k, a = |omega| dt
        kx, ky, kz = wx / rate, wy / rate, wz / rate
        cos_a, sin_a = math.cos(rate * dt), math.sin(rate * dt)
    for leg in range(4):
        if turning:
            ox, oy, oz = wake[leg, 0], wake[leg, 1], wake[leg, 2]
            cross_x, cross_y, cross_z = _cross(kx, ky, kz, ox, oy, oz)
            along = (1.0 - cos_a) * (kx * ox + ky * oy + kz * oz)
            wake[leg, 0] = ox * cos_a - sin_a * cross_x + along * kx
            wake[leg, 1] = oy * cos_a - sin_a * cross_y + along * ky
            wake[leg, 2] = oz * cos_a - sin_a * cross_z + along * kz
        px, py, pz, cx, cy, cz = feet[leg][0], feet[leg][1], feet[leg][2], feet[leg][3], feet[leg][4], feet[leg][5]
        # the body's part of the paw's velocity; c + 1.0 * g is u of paw_velocity_f bit for bit
        gx, gy, gz = paw_velocity_f(px, py, pz, 0.0, 0.0, 0.0, bx, by, bz, wx, wy, wz)
        ux, uy, uz = cx + body_share * gx, cy + body_share * gy, cz + body_share * gz
        tx, ty, tz = fraction * ux, fraction * uy, fraction * uz
        wake[leg, 0] = tx + (wake[leg, 0] - tx) * decay
        wake[leg, 1] = ty + (wake[leg, 1] - ty) * decay
        wake[leg, 2] = tz + (wake[leg, 2] - tz) * decay
        drag_feet[leg, 0] = px
        drag_feet[leg, 1] = py
        drag_feet[leg, 2] = pz
        drag_feet[leg, 3] = cx - wake[leg, 0]
        drag_feet[leg, 4] = cy - wake[leg, 1]
        drag_feet[leg, 5] = cz - wake[leg, 2]


@jitable
def body_wake_update(water: Any, fraction: float, time_constant: float, R: Sequence[float], wx: float, wy: float,
                     wz: float, dt: float) -> Vec3:
    """Advance the water the body's appendages set turning over a held step; its rate in body axes.

    ``water`` (3, world axes, rad/s, in place): the rate W of the water turning with the body. It relaxes
    towards the fraction kappa_b of the body's rate, R omega, with the time constant tau_b:
    dW/dt = (kappa_b R omega - W) / tau_b, solved exactly with R and omega of the step's start held,
    W <- kappa_b R omega + (W - kappa_b R omega) exp(-dt / tau_b). World axes because the water does not
    turn with the body. Returns R^T W: the rate the appendage damping measures the body's against
    (:func:`tank_forces`). ``R`` row-major 3x3 (9 floats), ``omega`` body axes."""
    decay = math.exp(-dt / time_constant)
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8]
    tx = fraction * (r0 * wx + r1 * wy + r2 * wz)
    ty = fraction * (r3 * wx + r4 * wy + r5 * wz)
    tz = fraction * (r6 * wx + r7 * wy + r8 * wz)
    water[0] = tx + (water[0] - tx) * decay
    water[1] = ty + (water[1] - ty) * decay
    water[2] = tz + (water[2] - tz) * decay
    return (r0 * water[0] + r3 * water[1] + r6 * water[2], r1 * water[0] + r4 * water[1] + r7 * water[2],
            r2 * water[0] + r5 * water[1] + r8 * water[2])


@jitable
def floating_block_update(anchor: Any, rest: Sequence[float], p: Sequence[float], v: Sequence[float],
                          R: Sequence[float], w: Sequence[float], hook: Sequence[float], rope: Sequence[float],
                          mass: float, drag: float, tie: float, dt: float) -> None:
    """Advance the floating block the rope hangs from over a held step, in place on ``anchor`` (6 floats,
    world: the block's position a, i.e. the rope's upper end, and its velocity a_dot).

    The block floats at the surface, so only its horizontal motion is free (its waterplane holds its
    height to millimetres): m_b a_dd = -T u_h - c_b |a_dot| a_dot - k_g (a - a_0), horizontal components,
    with T u the rope's pull on the hook (:func:`rope_force`: u the unit vector from the hook to the block,
    T = k (|d| - L_0) + c u . (a_dot - v_hook) while taut and positive, else 0), c_b the block's quadratic
    drag (1/2 rho C_D A of its draft), k_g the horizontal stiffness of its tie to the gantry around its rest
    position ``rest`` (a_0, where :meth:`TankModel.attach <quadruped_control.sim.plants.tank.TankModel.attach>`
    put it) and m_b its mass with its added mass. The body's state is the step's start (p, v world, R
    row-major, omega body axes; ``hook`` h^B, ``rope`` (L_0, k, c)). Semi-implicit Euler with the rope's
    dashpot and the block's drag implicit in the new velocity (the dashpot, there to kill the rope's own
    bounce, is far stiffer than a light block: explicit, it would need dt < 2 m_b / c), solved by
    Sherman-Morrison: ((m_b / dt + c_b |a_dot|) I + c u_h u_h^T) a_dot' = m_b a_dot / dt - T_0 u_h
    - k_g (a - a_0), T_0 the tension with the block still; then a <- a + dt a_dot'. The rope's elastic pull
    stays explicit: stable while dt^2 (k + k_g) / m_b < 4
    (:meth:`~quadruped_control.sim.plants.tank.TankModel.check_step_stability` checks it)."""
    qx, qy, qz, qvx, qvy, qvz = _hook_motion(p[0], p[1], p[2], v[0], v[1], v[2], R, w[0], w[1], w[2], hook)
    dx, dy, dz = anchor[0] - qx, anchor[1] - qy, anchor[2] - qz
    inertia = mass / dt
    alpha = inertia + drag * math.sqrt(anchor[3] * anchor[3] + anchor[4] * anchor[4])
    bx = inertia * anchor[3] - tie * (anchor[0] - rest[0])
    by = inertia * anchor[4] - tie * (anchor[1] - rest[1])
    vx, vy = bx / alpha, by / alpha  # the block's new velocity with the rope slack
    distance = math.sqrt(dx * dx + dy * dy + dz * dz)
    if distance > rope[0]:
        ux, uy, uz = dx / distance, dy / distance, dz / distance
        hook_rate = ux * qvx + uy * qvy + uz * qvz
        still = rope[1] * (distance - rope[0]) - rope[2] * hook_rate  # T_0
        ex, ey = bx - still * ux, by - still * uy
        k = rope[2] * (ux * ex + uy * ey) / (alpha + rope[2] * (ux * ux + uy * uy))
        tx, ty = (ex - k * ux) / alpha, (ey - k * uy) / alpha
        if still + rope[2] * (ux * tx + uy * ty) > 0.0:  # taut: the rope pulls the block towards the hook
            vx, vy = tx, ty
    anchor[3], anchor[4] = vx, vy
    anchor[0] += dt * vx
    anchor[1] += dt * vy


@jitable
def wound_friction_limit(limit: float, wrap: float, twist: float) -> float:
    """The hook's Coulomb torque (N m) once the tether has wound round the rope: tau_c exp(mu_w |phi|) (the capstan
    law), with phi (``twist``, rad) the body's whole turn about the world vertical since the rope hung untwisted
    (:func:`whole_twist`) and mu_w (``wrap``, per rad) the tether's friction on the rope. ``wrap`` 0 returns
    ``limit`` itself (the unwound tie, bit for bit). Physics: docs/tank_model.md, "hook friction"."""
    if wrap == 0.0:
        return limit
    return limit * math.exp(wrap * abs(twist))


@jitable
def hook_friction_update(friction: Any, limit: float, angle: float, static_ratio: float, stribeck_rate: float,
                         roll_ratio: float, p: Sequence[float], v: Sequence[float], R: Sequence[float],
                         w: Sequence[float], hook: Sequence[float], anchor: Sequence[float], length: float,
                         dt: float) -> Vec3:
    """Advance the friction torque where the rope is tied to the hook over a held step, in place on
    ``friction`` (3, body axes, N m: the torque the tie exerts on the rope; the body feels its opposite),
    and return the body-axes torque held over the step.

    Dahl's model on the body's rate s relative to the rope, across the rope, with LuGre's Stribeck curve:
    g(|s|) = tau_c (1 + (tau_s / tau_c - 1) exp(-(|s| / s_s)^2)) (``limit`` tau_c, ``static_ratio`` tau_s / tau_c,
    ``stribeck_rate`` s_s), solved exactly with s held over the step, tau_f <- g s^ + (tau_f - g s^)
    exp(-sigma_0 |s| dt / g), sigma_0 = tau_c / theta_p (``angle`` theta_p); ``static_ratio`` 1 is Dahl's
    tau_f <- tau_c s^ + (tau_f - tau_c s^) exp(-|s| dt / theta_p) bit for bit. The limit is the ellipse
    tau_c (m_x s_x, s_y, s_z) / |s| (``roll_ratio`` m_x about the body's x axis). What the tie stores beyond its
    largest torque r tau_c (r = max(1, tau_s / tau_c)) slips back to it at once (a falling ``limit``:
    :func:`wound_friction_limit`). A slack rope carries no friction. The body's state (p, v world, R row-major,
    omega body) is the step's start; ``anchor`` (6 floats) the rope's upper end and its velocity. Physics and
    sources: docs/tank_model.md, "hook friction"."""
    qx, qy, qz, qvx, qvy, qvz = _hook_motion(p[0], p[1], p[2], v[0], v[1], v[2], R, w[0], w[1], w[2], hook)
    dx, dy, dz = anchor[0] - qx, anchor[1] - qy, anchor[2] - qz
    distance = math.sqrt(dx * dx + dy * dy + dz * dz)
    if distance <= length:
        friction[0] = friction[1] = friction[2] = 0.0
        return (0.0, 0.0, 0.0)
    ux, uy, uz = dx / distance, dy / distance, dz / distance
    # the rope's swing rate Omega = -(u x q_dot_rel) / d, world axes, then in body axes
    ox, oy, oz = _cross(ux, uy, uz, qvx - anchor[3], qvy - anchor[4], qvz - anchor[5])
    ox, oy, oz = -ox / distance, -oy / distance, -oz / distance
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8]
    sx = w[0] - (r0 * ox + r3 * oy + r6 * oz)
    sy = w[1] - (r1 * ox + r4 * oy + r7 * oz)
    sz = w[2] - (r2 * ox + r5 * oy + r8 * oz)
    bx, by, bz = r0 * ux + r3 * uy + r6 * uz, r1 * ux + r4 * uy + r7 * uz, r2 * ux + r5 * uy + r8 * uz  # u, body
    along = sx * bx + sy * by + sz * bz
    sx, sy, sz = sx - along * bx, sy - along * by, sz - along * bz
    rate = math.sqrt(sx * sx + sy * sy + sz * sz)
    if rate > 0.0:
        level = limit
        if static_ratio > 1.0:  # the Stribeck curve g(|s|)
            level = limit * (1.0 + (static_ratio - 1.0) * math.exp(-(rate / stribeck_rate) ** 2))
            decay = math.exp(-rate * dt * limit / (angle * level))
        else:  # Dahl's own arithmetic, so that ratio 1 is the model without static friction bit for bit
            decay = math.exp(-rate * dt / angle)
        tx, ty, tz = roll_ratio * level * sx / rate, level * sy / rate, level * sz / rate
        friction[0] = tx + (friction[0] - tx) * decay
        friction[1] = ty + (friction[1] - ty) * decay
        friction[2] = tz + (friction[2] - tz) * decay
    # the tie turns with the body; the rope's direction in it moves: keep the part across the rope
    along = friction[0] * bx + friction[1] * by + friction[2] * bz
    friction[0] -= along * bx
    friction[1] -= along * by
    friction[2] -= along * bz
    # a tie holds no more than it grips now: when the limit has fallen (a tether unwinding), what it stored
    # above its largest torque r tau_c slips at once; the 1e-12 leaves rounding alone, so a constant limit
    # is the update above bit for bit
    most = limit * (static_ratio if static_ratio > 1.0 else 1.0)
    stored = (friction[0] / roll_ratio) ** 2 + friction[1] ** 2 + friction[2] ** 2
    if stored > most * most * (1.0 + 1e-12):
        scale = most / math.sqrt(stored)
        friction[0] *= scale
        friction[1] *= scale
        friction[2] *= scale
    return (-friction[0], -friction[1], -friction[2])


@jitable
def paw_joint_loads(q: Any, frames: Any, five_bar: Sequence[float], drag_rows: Any, drag_constant: float, bx: float,
                    by: float, bz: float, wx: float, wy: float, wz: float, loads: Any) -> bool:
    """The torque each joint feels from its paw's drag, tau_j = J_P,i^B[:, j] . F_i (N m, along the joint
    angle; J from :func:`~quadruped_control.model.kinematics.leg_jacobian_row` at the joint angles ``q``
    (4 x 3), F_i = -k |u_i| u_i the paw drag of eq. (drag) in body axes with u_i from the rows the drag
    sees, ``drag_rows`` (r_i, c_i or c_i - w_i), the body velocity b and rate omega), into ``loads``
    (4 x 3 array). What a loaded servo works against
    (:func:`~quadruped_control.sim.servo_model.loaded_speed`). False, with the loads zero, if a five-bar
    cannot close or is singular."""
    a1, a2, a3, a4, c, l_y, l_z = five_bar
    for leg in range(4):
        ok, J = leg_jacobian_row(q[leg, 0], q[leg, 1], q[leg, 2], frames[leg], a1, a2, a3, a4, c, l_y, l_z)
        if not ok:
            for other in range(4):
                for k in range(3):
                    loads[other, k] = 0.0
            return False
        fx, fy, fz = paw_drag_f(drag_rows[leg, 0], drag_rows[leg, 1], drag_rows[leg, 2], drag_rows[leg, 3],
                                drag_rows[leg, 4], drag_rows[leg, 5], drag_constant, bx, by, bz, wx, wy, wz)
        for k in range(3):
            loads[leg, k] = J[k] * fx + J[3 + k] * fy + J[6 + k] * fz
    return True


# --------------------------------------------------------------------------------------------------
# Mass matrix of a held step
# --------------------------------------------------------------------------------------------------

@jitable
def leg_sums(feet: Sequence[Sequence[float]]) -> Tuple[Any, ...]:
    """(sr, sc, S, P, rc) over the legs' rows (r_i, c_i): sr = sum r_i, sc = sum c_i, S = sum r_i r_i^T,
    P = sum c_i r_i^T (row-major 9-tuples), rc = sum r_i . c_i: what the paws' added mass needs."""
    sx = sy = sz = cx = cy = cz = rc = 0.0
    s0 = s1 = s2 = s4 = s5 = s8 = 0.0
    p0 = p1 = p2 = p3 = p4 = p5 = p6 = p7 = p8 = 0.0
    for foot in feet:
        x, y, z, u, v, w = foot[0], foot[1], foot[2], foot[3], foot[4], foot[5]
        sx += x
        sy += y
        sz += z
        cx += u
        cy += v
        cz += w
        s0 += x * x
        s1 += x * y
        s2 += x * z
        s4 += y * y
        s5 += y * z
        s8 += z * z
        p0 += u * x
        p1 += u * y
        p2 += u * z
        p3 += v * x
        p4 += v * y
        p5 += v * z
        p6 += w * x
        p7 += w * y
        p8 += w * z
        rc += x * u + y * v + z * w
    return ((sx, sy, sz), (cx, cy, cz), (s0, s1, s2, s1, s4, s5, s2, s5, s8), (p0, p1, p2, p3, p4, p5, p6, p7, p8), rc)


@jitable
def _inverse3(m: Sequence[float]) -> Tuple[float, ...]:
    """Inverse of a row-major 3x3 matrix by cofactors (nan where it is singular)."""
    a, b, c, d, e, f, g, h, i = m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8]
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    k = 1.0 / det if det != 0.0 else math.nan
    return (A * k, (c * h - b * i) * k, (b * f - c * e) * k,
            B * k, (a * i - c * g) * k, (c * d - a * f) * k,
            C * k, (b * g - a * h) * k, (a * e - b * d) * k)


@jitable
def mass_solver(body_m: Sequence[float], ma: float, sr: Sequence[float], S: Sequence[float]) -> Tuple[Any, ...]:
    """(diag A^-1, B, S^-1) of :func:`solve_mass` for M = M_RB + M_A + sum_i M_paw(r_i): the paws add
    m_a [[4 I, -hat(sr)], [hat(sr), tr(S) I - S]] (sr = sum r_i, S = sum r_i r_i^T) to ``body_m``
    (M_RB + M_A, row-major 6x6, its translational block diagonal: checked by the model). nan if singular."""
    a0, a1, a2 = 1.0 / (body_m[0] + 4.0 * ma), 1.0 / (body_m[7] + 4.0 * ma), 1.0 / (body_m[14] + 4.0 * ma)
    x, y, z = sr[0], sr[1], sr[2]
    B = (0.0, ma * z, -ma * y, -ma * z, 0.0, ma * x, ma * y, -ma * x, 0.0)  # -m_a hat(sr)
    trace = S[0] + S[4] + S[8]
    D = (body_m[21] + ma * (trace - S[0]), body_m[22] - ma * S[1], body_m[23] - ma * S[2],
         body_m[27] - ma * S[3], body_m[28] + ma * (trace - S[4]), body_m[29] - ma * S[5],
         body_m[33] - ma * S[6], body_m[34] - ma * S[7], body_m[35] + ma * (trace - S[8]))
    # S = D - B^T A^-1 B
    schur = (D[0] - (B[0] * a0 * B[0] + B[3] * a1 * B[3] + B[6] * a2 * B[6]),
             D[1] - (B[0] * a0 * B[1] + B[3] * a1 * B[4] + B[6] * a2 * B[7]),
             D[2] - (B[0] * a0 * B[2] + B[3] * a1 * B[5] + B[6] * a2 * B[8]),
             D[3] - (B[1] * a0 * B[0] + B[4] * a1 * B[3] + B[7] * a2 * B[6]),
             D[4] - (B[1] * a0 * B[1] + B[4] * a1 * B[4] + B[7] * a2 * B[7]),
             D[5] - (B[1] * a0 * B[2] + B[4] * a1 * B[5] + B[7] * a2 * B[8]),
             D[6] - (B[2] * a0 * B[0] + B[5] * a1 * B[3] + B[8] * a2 * B[6]),
             D[7] - (B[2] * a0 * B[1] + B[5] * a1 * B[4] + B[8] * a2 * B[7]),
             D[8] - (B[2] * a0 * B[2] + B[5] * a1 * B[5] + B[8] * a2 * B[8]))
    return (a0, a1, a2), B, _inverse3(schur)


@jitable
def solve_mass(solver: Tuple[Any, ...], g0: float, g1: float, g2: float, g3: float, g4: float,
               g5: float) -> Tuple[float, ...]:
    """nu_dot = M^-1 g for M = [[A, B], [B^T, D]] with A diagonal, by the Schur complement
    S = D - B^T A^-1 B: x2 = S^-1 (g2 - B^T A^-1 g1), x1 = A^-1 (g1 - B x2). ``solver`` is
    (diag A^-1, B, S^-1) from :func:`mass_solver`; tested against numpy.linalg.solve."""
    (a0, a1, a2), B, Si = solver
    y0, y1, y2 = a0 * g0, a1 * g1, a2 * g2  # A^-1 g1
    h0 = g3 - (B[0] * y0 + B[3] * y1 + B[6] * y2)  # g2 - B^T A^-1 g1
    h1 = g4 - (B[1] * y0 + B[4] * y1 + B[7] * y2)
    h2 = g5 - (B[2] * y0 + B[5] * y1 + B[8] * y2)
    x3 = Si[0] * h0 + Si[1] * h1 + Si[2] * h2
    x4 = Si[3] * h0 + Si[4] * h1 + Si[5] * h2
    x5 = Si[6] * h0 + Si[7] * h1 + Si[8] * h2
    return (a0 * (g0 - (B[0] * x3 + B[1] * x4 + B[2] * x5)),
            a1 * (g1 - (B[3] * x3 + B[4] * x4 + B[5] * x5)),
            a2 * (g2 - (B[6] * x3 + B[7] * x4 + B[8] * x5)), x3, x4, x5)


# --------------------------------------------------------------------------------------------------
# Equations of motion
# --------------------------------------------------------------------------------------------------

@jitable
def tank_forces(k: TankConstants, feet: Sequence[Sequence[float]], drag_feet: Sequence[Sequence[float]],
                water: Sequence[float], held_torque: Sequence[float], lift: float, up_torque: Sequence[float],
                sums: Tuple[Any, ...], px: float, py: float, pz: float, vx: float, vy: float, vz: float, R: Mat3,
                wx: float, wy: float, wz: float) -> Tuple[float, ...]:
    """Right-hand side of eq. (tank): the 6 body-axes generalised forces minus C(nu) nu and f_paw, for
    the constants ``k`` (:data:`TankConstants`), the step's legs (``feet`` rows, paw buoyancy ``lift`` and
    torque matrix ``up_torque`` with the torso's buoyancy moment, :func:`leg_sums` ``sums``; ``drag_feet``
    the rows the paw drag sees: ``feet`` itself, or with each paw's wake taken off, :func:`paw_wake_update`;
    ``water`` the body-axes rate of the water the appendages set turning, :func:`body_wake_update`, zeros
    without it; ``held_torque`` a body-axes torque held over the step, the hook's friction,
    :func:`hook_friction_update`, plus the tank's disturbance, :func:`disturbance_update`, zeros without
    them) and the state p, v (world), R (row-major), omega (body)."""
    (drag_constant, drag, extra_lift, suspension, hook, anchor, rope, torsion, untwisted, linear, quadratic,
     body_m, ma, _wake_fraction, _wake_time_constant, _wake_body_share, _body_wake_fraction,
     _body_wake_time_constant, tether) = k
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
    bx, by, bz = r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz
    fx, fy, fz, tx, ty, tz = body_wrench_f(drag_feet, drag_constant, drag, up_torque, bx, by, bz, R, wx, wy, wz)
    # world-up forces: paw buoyancy, then torso hydrostatics (its moment is in up_torque); R^T z_hat = (r6, r7, r8)
    up_force = lift + extra_lift
    fx, fy, fz = fx + up_force * r6, fy + up_force * r7, fz + up_force * r8
    if suspension:
        qx, qy, qz, qvx, qvy, qvz = _hook_motion(px, py, pz, vx, vy, vz, R, wx, wy, wz, hook)
        # the hook's velocity relative to the rope's upper end (exactly the hook's with a fixed anchor: x - 0.0 == x)
        Fx, Fy, Fz = rope_force((qx, qy, qz), (qvx - anchor[3], qvy - anchor[4], qvz - anchor[5]), anchor,
                                rope[0], rope[1], rope[2])
        Fbx, Fby, Fbz = r0 * Fx + r3 * Fy + r6 * Fz, r1 * Fx + r4 * Fy + r7 * Fz, r2 * Fx + r5 * Fy + r8 * Fz
        mx, my, mz = _cross(hook[0], hook[1], hook[2], Fbx, Fby, Fbz)
        fx, fy, fz, tx, ty, tz = fx + Fbx, fy + Fby, fz + Fbz, tx + mx, ty + my, tz + mz
        if torsion[0] > 0.0 or torsion[1] > 0.0 or torsion[3] > 0.0:
            mx, my, mz = rope_torsion_torque(R, untwisted, (wx, wy, wz), torsion[0], torsion[1],
                                             torsion[2], torsion[3], torsion[5])
            tx, ty, tz = tx + mx, ty + my, tz + mz
    # the hook's friction and the tank's disturbance (exactly today's torque without them: x + 0.0 == x)
    tx, ty, tz = tx + held_torque[0], ty + held_torque[1], tz + held_torque[2]
    if tether[0] > 0.0 or tether[1] > 0.0:
        mx, my, mz = tether_bend_torque(R, tether)
        tx, ty, tz = tx + mx, ty + my, tz + mz
    if linear[0] > 0.0 or linear[1] > 0.0 or linear[2] > 0.0 or quadratic[0] > 0.0 or quadratic[1] > 0.0 \
            or quadratic[2] > 0.0:
        # against the water the appendages set turning (exactly omega without it: x - 0.0 == x)
        mx, my, mz = appendage_damping_torque((wx - water[0], wy - water[1], wz - water[2]), linear, quadratic)
        tx, ty, tz = tx + mx, ty + my, tz + mz
    # Kirchhoff terms of M_RB + M_A: [omega x p; v x p + omega x h], [p; h] = M nu.
    m = body_m
    lx = m[0] * bx + m[1] * by + m[2] * bz + m[3] * wx + m[4] * wy + m[5] * wz
    ly = m[6] * bx + m[7] * by + m[8] * bz + m[9] * wx + m[10] * wy + m[11] * wz
    lz = m[12] * bx + m[13] * by + m[14] * bz + m[15] * wx + m[16] * wy + m[17] * wz
    ax_ = m[18] * bx + m[19] * by + m[20] * bz + m[21] * wx + m[22] * wy + m[23] * wz
    ay_ = m[24] * bx + m[25] * by + m[26] * bz + m[27] * wx + m[28] * wy + m[29] * wz
    az_ = m[30] * bx + m[31] * by + m[32] * bz + m[33] * wx + m[34] * wy + m[35] * wz
    c0x, c0y, c0z = _cross(wx, wy, wz, lx, ly, lz)
    c1x, c1y, c1z = _cross(bx, by, bz, lx, ly, lz)
    c2x, c2y, c2z = _cross(wx, wy, wz, ax_, ay_, az_)
    fx, fy, fz = fx - c0x, fy - c0y, fz - c0z
    tx, ty, tz = tx - c1x - c2x, ty - c1y - c2y, tz - c1z - c2z
    if ma > 0.0:
        # Paw added mass, summed over the legs: f_i = -m_a (omega x v + omega x (omega x r_i)
        # + 2 omega x c_i), moments r_i x f_i; with sr = sum r_i, sc = sum c_i, S = sum r_i r_i^T,
        # P = sum c_i r_i^T, rc = sum r_i . c_i:
        #   sum f_i = -m_a (4 omega x v + omega x (omega x sr) + 2 omega x sc)
        #   sum r_i x f_i = -m_a (sr x (omega x v) + (S omega) x omega + 2 (omega rc - P omega))
        sr, sc, S, P, rc = sums
        wvx, wvy, wvz = _cross(wx, wy, wz, bx, by, bz)
        qx, qy, qz = _cross(wx, wy, wz, sr[0], sr[1], sr[2])
        wwrx, wwry, wwrz = _cross(wx, wy, wz, qx, qy, qz)
        wcx, wcy, wcz = _cross(wx, wy, wz, sc[0], sc[1], sc[2])
        fx -= ma * (4.0 * wvx + wwrx + 2.0 * wcx)
        fy -= ma * (4.0 * wvy + wwry + 2.0 * wcy)
        fz -= ma * (4.0 * wvz + wwrz + 2.0 * wcz)
        rwvx, rwvy, rwvz = _cross(sr[0], sr[1], sr[2], wvx, wvy, wvz)
        Swx, Swy, Swz = (S[0] * wx + S[1] * wy + S[2] * wz, S[3] * wx + S[4] * wy + S[5] * wz,
                         S[6] * wx + S[7] * wy + S[8] * wz)
        Pwx, Pwy, Pwz = (P[0] * wx + P[1] * wy + P[2] * wz, P[3] * wx + P[4] * wy + P[5] * wz,
                         P[6] * wx + P[7] * wy + P[8] * wz)
        swwx, swwy, swwz = _cross(Swx, Swy, Swz, wx, wy, wz)
        tx -= ma * (rwvx + swwx + 2.0 * (wx * rc - Pwx))
        ty -= ma * (rwvy + swwy + 2.0 * (wy * rc - Pwy))
        tz -= ma * (rwvz + swwz + 2.0 * (wz * rc - Pwz))
    return fx, fy, fz, tx, ty, tz


@jitable
def tank_chart_derivative(k: TankConstants, feet: Sequence[Sequence[float]], drag_feet: Sequence[Sequence[float]],
                          water: Sequence[float], held_torque: Sequence[float], lift: float, up_torque: Sequence[float],
                          sums: Tuple[Any, ...], solver: Tuple[Any, ...], R0: Mat3,
                          y: Sequence[float]) -> Tuple[float, ...]:
    """d/dt of the chart state y = (p, v, xi, omega) (12 floats) under eq. (tank), R = R0 exp(hat(xi))."""
    px, py, pz, vx, vy, vz, x, y_, z, wx, wy, wz = y
    R, (rx, ry, rz) = chart_point(R0, x, y_, z, wx, wy, wz)
    g0, g1, g2, g3, g4, g5 = tank_forces(k, feet, drag_feet, water, held_torque, lift, up_torque, sums, px, py, pz,
                                         vx, vy, vz, R, wx, wy, wz)
    n0, n1, n2, n3, n4, n5 = solve_mass(solver, g0, g1, g2, g3, g4, g5)
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
    bx, by, bz = r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz
    cx, cy, cz = _cross(wx, wy, wz, bx, by, bz)
    ax, ay, az = n0 + cx, n1 + cy, n2 + cz
    return (vx, vy, vz, r0 * ax + r1 * ay + r2 * az, r3 * ax + r4 * ay + r5 * az, r6 * ax + r7 * ay + r8 * az,
            rx, ry, rz, n3, n4, n5)


@jitable
def _axpy12(y: Sequence[float], a: float, k: Sequence[float]) -> Tuple[float, ...]:
    """y + a k for 12-float chart states."""
    return (y[0] + a * k[0], y[1] + a * k[1], y[2] + a * k[2], y[3] + a * k[3], y[4] + a * k[4], y[5] + a * k[5],
            y[6] + a * k[6], y[7] + a * k[7], y[8] + a * k[8], y[9] + a * k[9], y[10] + a * k[10],
            y[11] + a * k[11])


@jitable
def tank_rk4(k: TankConstants, feet: Sequence[Sequence[float]], drag_feet: Sequence[Sequence[float]],
             water: Sequence[float], held_torque: Sequence[float], lift: float, up_torque: Sequence[float],
             sums: Tuple[Any, ...], solver: Tuple[Any, ...], R0: Mat3, y0: Sequence[float],
             dt: float) -> Tuple[float, ...]:
    """One classic RK4 step of :func:`tank_chart_derivative` in the chart around R0 from the chart state
    y0 = (p, v, 0, omega), the legs (the paws' wake, ``drag_feet``, the water turning with the body,
    ``water``, and the hook's friction with the tank's disturbance, ``held_torque``) held over it: the chart
    state at its end (12 floats; the caller maps it back with :func:`~.rigid_body.chart_step_end`)."""
    h = 0.5 * dt
    k1 = tank_chart_derivative(k, feet, drag_feet, water, held_torque, lift, up_torque, sums, solver, R0, y0)
    k2 = tank_chart_derivative(k, feet, drag_feet, water, held_torque, lift, up_torque, sums, solver, R0,
                               _axpy12(y0, h, k1))
    k3 = tank_chart_derivative(k, feet, drag_feet, water, held_torque, lift, up_torque, sums, solver, R0,
                               _axpy12(y0, h, k2))
    k4 = tank_chart_derivative(k, feet, drag_feet, water, held_torque, lift, up_torque, sums, solver, R0,
                               _axpy12(y0, dt, k3))
    s = dt / 6.0
    return (y0[0] + s * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]), y0[1] + s * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
            y0[2] + s * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]), y0[3] + s * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]),
            y0[4] + s * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]), y0[5] + s * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5]),
            y0[6] + s * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6]), y0[7] + s * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7]),
            y0[8] + s * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8]), y0[9] + s * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9]),
            y0[10] + s * (k1[10] + 2.0 * (k2[10] + k3[10]) + k4[10]),
            y0[11] + s * (k1[11] + 2.0 * (k2[11] + k3[11]) + k4[11]))
