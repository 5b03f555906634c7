"""SO(3) attitude controller of the underwater quadruped (paper section "Attitude Controller Design").

One :meth:`AttitudeController.step` (100 Hz) runs the three layers of the paper and the stroke cycle:

1. Orientation error, eq. (error): [e_R]_x = 1/2 (R_d^T R - R^T R_d), recovered with the vee map
   (:func:`quadruped_common.so3.attitude_error`), and the geodesic error angle of R_d^T R.
2. Control law, eq. (pid):
       tau_cmd = -K_p e_R - K_i int(e_R + K_aw Delta_sat) - K_d omega + omega x (I omega) - tau_buoyancy^B
   with the saturation eq. (sat), tau_sat = tau_hat_cmd min(|tau_cmd|, tau_max), and the anti-windup
   difference Delta_sat = tau_cmd - tau_sat fed back into the integrand through K_aw. The paw buoyancy
   torque (eq. (buoy_torque)) is evaluated at the currently commanded foot positions and the measured
   attitude.
3. Allocation, eq. (foot_speed), (foot_vel) (:mod:`quadruped_control.control.allocation`), latched at each
   power-phase start by the stroke scheme (:mod:`quadruped_control.control.strokes`: the paper's cycle or the
   coordinated scheme, ``config.stroke_scheme``), Euler integration of the foot position, eq.
   (foot_integration), and the leg IK -> joint targets (4 x 3, rad).

Switching the stroke scheme at run time (:meth:`AttitudeController.set_stroke_scheme`) is smooth: the
current scheme holds (power strokes retrace, recoveries complete, the feet return to the nominal pose;
the record shows 'hold' with the reason), then the new scheme starts from the nominal pose.

Discretisation of the integral (the paper gives the continuous law dz/dt = e_R + K_aw Delta_sat): with
h the elapsed time of this step, c_k the P, D and feedforward terms of eq. (pid) at this step, so that
tau_cmd,k = c_k - K_i z_k, and g = h K_aw K_i >= 0 the anti-windup loop gain of one step:

* g <= 1 (every gain set of config/controller.yaml at 100 Hz; the discretisation of the first release,
  so ``--study paper-sim`` keeps its numbers): forward in the anti-windup term,
      z_k = z_(k-1) + h (e_R,k + K_aw Delta_sat,(k-1)),  Delta_sat,(k-1) = tau_cmd,(k-1) - sat(tau_cmd,(k-1)),
  the saturation excess of the torque commanded over the interval that just ended (zero after start,
  reset and hold);
* g > 1: backward (implicit) Euler,
      z_k = z_(k-1) + h (e_R,k + K_aw Delta_sat,k),
  the excess of the torque this step commands. It has a closed form: with the predictor
  u = c_k - K_i (z_(k-1) + h e_R,k), tau_cmd,k = u when |u| <= tau_max and otherwise
  tau_cmd,k = u_hat (|u| + g tau_max) / (1 + g), i.e. Delta_sat,k = u_hat (|u| - tau_max) / (1 + g).

Then z_k is clipped to the norm ``integral_limit`` (on by default). h is the actual elapsed time
t_k - t_(k-1) clipped to [0, max_step_factor * dt]; the first step after construction/reset uses dt.
While holding, the integral is frozen.

Stability for EVERY gain and step the interfaces allow (K_p, K_i, K_d, K_aw >= 0, any h >= 0). The
dead-zone phi(tau) = tau - sat(tau) = tau - P(tau), P the projection onto the ball |tau| <= tau_max, is
the gradient of the convex function 1/2 dist(tau, ball)^2, so it is monotone and firmly non-expansive:
<phi(a) - phi(b), a - b> >= |phi(a) - phi(b)|^2. Take two integral states z, z' fed the same
measurements, d = z_(k-1) - z'_(k-1), and K_i > 0 (for K_i = 0 the integral does not act on the torque).

* Forward form: d_k = d + h K_aw delta with delta = phi(a) - phi(b), a - b = -K_i d (a, b the previous
  commands). Firm non-expansiveness gives <delta, d> <= -|delta|^2 / K_i, so
  |d_k|^2 <= |d|^2 + (h K_aw / K_i) |delta|^2 (g - 2) <= |d|^2 for g <= 2; with g <= 1 the deviation is
  not even reversed in sign (in saturation along a fixed direction it is multiplied by 1 - g in [0, 1]).
  Beyond g = 2 this form diverges (e.g. K_i 20, K_aw 10 and h >= 12.5 ms: the integral passed 1e6 in
  under a second), which is why it is used only up to g = 1.
* Backward form: the step solves tau + g phi(tau) = u, i.e. tau_cmd,k = (I + g phi)^(-1)(u), the resolvent
  of a monotone operator, firmly non-expansive for every g >= 0: |tau_k - tau'_k| <= |u - u'|. As
  z_k = (c_k - tau_k) / K_i, |z_k - z'_k| <= |u - u'| / K_i = |d|.

Each step is therefore non-expansive in z whichever form it takes (gains and h may change between
steps), the clip to ``integral_limit`` is a projection onto a ball, non-expansive too, and it bounds |z|
absolutely: no growth and no sign-alternating oscillation for any gain or step.

No overflow, no NaN: step() refuses non-finite inputs and angular rates beyond ``max_angular_rate``
(ValueError; the supervisor then holds), so with |e_R| <= 1, bounded gains (cfg bounds), |z| <=
integral_limit, h <= max_step and the feet within the legs' reach every term of eq. (pid), the
saturation and the allocation is bounded by a modest number (|omega x I omega| <= |I| w_max^2).
The controller is pure Python/numpy (no ROS): the ROS node and the offline simulator wrap the same
object. Bad measurements raise ValueError from :meth:`step` (the caller then calls :meth:`hold`); no
output ever contains NaN, and joint targets are always within the servo ranges.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple, Union

import numpy as np

# estimate_body_torque (eq. (torque_leg) from measured joint motion) lives in allocation; re-exported here.
from quadruped_common.config import ParameterError
from quadruped_common.jit import hypot3, jitable
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.control.allocation import estimate_body_torque, foot_velocity_command_f
from quadruped_control.control.controller_config import ControllerConfig, Gains
from quadruped_control.control.strokes import StrokeScheme, make_stroke_scheme
from quadruped_control.model.params import RobotParams

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]
Vec3 = Tuple[float, float, float]

__all__ = [
    "AttitudeController",
    "ControllerOutput",
    "ControllerStateRecord",
    "control_law_f",
    "control_torque",
    "estimate_body_torque",
    "saturate",
]


# --------------------------------------------------------------------------------------------------
# Pure control-law pieces (also used by the tests)
# --------------------------------------------------------------------------------------------------

def control_torque(e_R: ArrayLike, omega: ArrayLike, integral: ArrayLike, gains: Gains,
                   inertia: Optional[ArrayLike] = None, tau_buoyancy: Optional[ArrayLike] = None) -> np.ndarray:
    """tau_cmd of eq. (pid) for a given integral state z = int(e_R + K_aw Delta_sat):

        tau_cmd = -K_p e_R - K_i z - K_d omega + omega x (I omega) - tau_buoyancy

    The gyroscopic term is included when ``inertia`` (3x3) is given, the buoyancy term when
    ``tau_buoyancy`` is given.
    """
    e = np.asarray(e_R, dtype=float).reshape(3)
    w = np.asarray(omega, dtype=float).reshape(3)
    z = np.asarray(integral, dtype=float).reshape(3)
    tau = -gains.k_p * e - gains.k_i * z - gains.k_d * w
    if inertia is not None:
        tau = tau + np.cross(w, np.asarray(inertia, dtype=float).reshape(3, 3) @ w)
    if tau_buoyancy is not None:
        tau = tau - np.asarray(tau_buoyancy, dtype=float).reshape(3)
    return tau


def saturate(tau_cmd: ArrayLike, tau_max: float) -> Tuple[np.ndarray, bool]:
    """eq. (sat): tau_sat = tau_hat_cmd min(|tau_cmd|, tau_max); returns (tau_sat, saturated)."""
    tau = np.asarray(tau_cmd, dtype=float).reshape(3)
    x, y, z = tau.tolist()
    sx, sy, sz, saturated = _saturate_f(x, y, z, float(tau_max))
    return np.array([sx, sy, sz]), saturated


@jitable
def _saturate_f(x: float, y: float, z: float, tau_max: float) -> Tuple[float, float, float, bool]:
    norm = hypot3(x, y, z)
    if norm <= tau_max:
        return x, y, z, False
    scale = tau_max / norm
    return x * scale, y * scale, z * scale, True


@jitable
def control_law_f(R_d: Sequence[float], R: Sequence[float], wx: float, wy: float, wz: float, z: Sequence[float],
                  delta_sat: Sequence[float], h: float, k_p: float, k_i: float, k_d: float, k_aw: float,
                  tau_max: float, integral_limit: float, inertia: Sequence[float], gyroscopic: bool,
                  buoyancy: bool, feet_sum: Sequence[float], net_buoyancy: float) -> Tuple[float, ...]:
    """One step of eq. (error), (pid) and (sat) on floats: the controller's law, the one implementation
    (:meth:`AttitudeController.step` calls it from Python, the batched controller from compiled code).

    ``R_d``, ``R``: setpoint and measured attitude, row-major; omega = (wx, wy, wz); ``z``: the integral
    z_(k-1); ``delta_sat``: Delta_sat of the last command (the forward form's anti-windup term); ``h``:
    the step; ``inertia`` row-major I for the gyroscopic feedforward; ``feet_sum``: sum of the commanded
    foot positions for the buoyancy feedforward, ``net_buoyancy`` B of one paw. The integral's two
    discretisations are those of the module docstring. Returns the 17 floats (e_R (3), geodesic angle,
    z_k (3), tau_cmd (3), tau_sat (3), saturated, feedforward (3)).
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8]
    d00, d01, d02, d10, d11, d12, d20, d21, d22 = R_d[0], R_d[1], R_d[2], R_d[3], R_d[4], R_d[5], R_d[6], R_d[7], \
        R_d[8]
    # eq. (error): E = R_d^T R, e_R = vee(1/2 (E - E^T)).
    e01 = d00 * r01 + d10 * r11 + d20 * r21
    e02 = d00 * r02 + d10 * r12 + d20 * r22
    e10 = d01 * r00 + d11 * r10 + d21 * r20
    e12 = d01 * r02 + d11 * r12 + d21 * r22
    e20 = d02 * r00 + d12 * r10 + d22 * r20
    e21 = d02 * r01 + d12 * r11 + d22 * r21
    ex, ey, ez = 0.5 * (e21 - e12), 0.5 * (e02 - e20), 0.5 * (e10 - e01)
    trace = (d00 * r00 + d10 * r10 + d20 * r20) + (d01 * r01 + d11 * r11 + d21 * r21) \
        + (d02 * r02 + d12 * r12 + d22 * r22)
    geodesic = math.atan2(hypot3(ex, ey, ez), 0.5 * (trace - 1.0))

    # Feedforward: omega x (I omega) and -tau_buoyancy^B, eq. (pid), (buoy_torque).
    fx = fy = fz = 0.0
    if gyroscopic:
        i0, i1, i2, i3, i4, i5, i6, i7, i8 = inertia[0], inertia[1], inertia[2], inertia[3], inertia[4], \
            inertia[5], inertia[6], inertia[7], inertia[8]
        hx, hy, hz = i0 * wx + i1 * wy + i2 * wz, i3 * wx + i4 * wy + i5 * wz, i6 * wx + i7 * wy + i8 * wz
        fx += wy * hz - wz * hy
        fy += wz * hx - wx * hz
        fz += wx * hy - wy * hx
    if buoyancy:
        # tau_b = sum_i r_i x (R^T B z_hat) = (sum_i r_i) x (B * third row of R), at the commanded feet.
        sx, sy, sz = feet_sum[0], feet_sum[1], feet_sum[2]
        ux, uy, uz = net_buoyancy * r20, net_buoyancy * r21, net_buoyancy * r22
        fx -= sy * uz - sz * uy
        fy -= sz * ux - sx * uz
        fz -= sx * uy - sy * ux

    # Integral of eq. (pid) (module docstring): forward in the anti-windup excess while the loop gain
    # g = h K_aw K_i of one step is at most 1 (the first release's form), backward Euler beyond.
    g = h * k_aw * k_i
    if g <= 1.0:
        zx = z[0] + h * (ex + k_aw * delta_sat[0])
        zy = z[1] + h * (ey + k_aw * delta_sat[1])
        zz = z[2] + h * (ez + k_aw * delta_sat[2])
    else:
        # Predictor z + h e_R and its command u; in saturation add h K_aw Delta_sat in closed form.
        zx, zy, zz = z[0] + h * ex, z[1] + h * ey, z[2] + h * ez
        ux = -k_p * ex - k_i * zx - k_d * wx + fx
        uy = -k_p * ey - k_i * zy - k_d * wy + fy
        uz = -k_p * ez - k_i * zz - k_d * wz + fz
        norm_u = hypot3(ux, uy, uz)
        if norm_u > tau_max:
            step = h * k_aw * (norm_u - tau_max) / ((1.0 + g) * norm_u)  # h K_aw |Delta_sat| / |u|
            zx, zy, zz = zx + step * ux, zy + step * uy, zz + step * uz
    norm_z = hypot3(zx, zy, zz)
    if norm_z > integral_limit:
        scale = integral_limit / norm_z
        zx, zy, zz = zx * scale, zy * scale, zz * scale

    # Summed in the order of eq. (pid) as the first release did: the paper-sim limit cycles are
    # sensitive to the last bit, and their published numbers are kept.
    cx = -k_p * ex - k_i * zx - k_d * wx + fx
    cy = -k_p * ey - k_i * zy - k_d * wy + fy
    cz = -k_p * ez - k_i * zz - k_d * wz + fz
    sx_, sy_, sz_, saturated = _saturate_f(cx, cy, cz, tau_max)  # eq. (sat)
    return ex, ey, ez, geodesic, zx, zy, zz, cx, cy, cz, sx_, sy_, sz_, saturated, fx, fy, fz


# --------------------------------------------------------------------------------------------------
# Outputs
# --------------------------------------------------------------------------------------------------

@dataclass
class ControllerStateRecord:
    """Telemetry of one controller step (all vectors in the body frame, SI units, radians).

    ``e_R``: attitude error eq. (error); ``tau_cmd``, ``tau_sat``: eq. (pid), (sat) (N m);
    ``saturated``: |tau_cmd| > tau_max; ``integral``: z = int(e_R + K_aw Delta_sat) (s);
    ``geodesic_error``: angle of R_d^T R (rad); ``pair_phase``: 'power'/'recovery'/'hold' per pair (in
    config order); ``pair_phase_time``: time in that phase (s); ``foot_targets``: commanded r_e,i^B
    (4 x 3, m); ``holding``/``hold_reason``: safe state; ``R_d``: the setpoint; ``dt``: integrated step
    (s); ``tau_feedforward``: the feedforward part omega x I omega - tau_buoyancy (N m);
    ``foot_velocity_commands``: latched v_i^cmd (4 x 3, m/s; zero outside power phases).
    During a hold the attitude is not measured: ``e_R`` and ``geodesic_error`` repeat the last measured
    values and the torques are zero.
    """

    t: float
    e_R: np.ndarray
    tau_cmd: np.ndarray
    tau_sat: np.ndarray
    saturated: bool
    integral: np.ndarray
    geodesic_error: float
    pair_phase: Tuple[str, str]
    pair_phase_time: Tuple[float, float]
    foot_targets: np.ndarray
    holding: bool
    hold_reason: str
    R_d: np.ndarray
    dt: float
    tau_feedforward: np.ndarray
    foot_velocity_commands: np.ndarray

    @property
    def setpoint(self) -> np.ndarray:
        """Alias of ``R_d``."""
        return self.R_d


@dataclass
class ControllerOutput:
    """Result of :meth:`AttitudeController.step` / :meth:`AttitudeController.hold`.

    ``joint_targets``: (4, 3) servo angles (theta1, theta2, theta3) per leg 1..4, rad, within the servo
    ranges; ``state``: telemetry.
    """

    joint_targets: np.ndarray
    state: ControllerStateRecord


# --------------------------------------------------------------------------------------------------
# Controller
# --------------------------------------------------------------------------------------------------

def _rotation_floats(R: ArrayLike, name: str, tol: float) -> Tuple[float, ...]:
    """R as 9 row-major floats; ValueError unless finite, 3x3, |R^T R - I| <= tol and det > 0."""
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3):
        raise ValueError("%s must be a 3x3 rotation matrix, got shape %s" % (name, M.shape))
    a, b, c, d, e, f, g, h, i = M.ravel().tolist()
    if not math.isfinite(a + b + c + d + e + f + g + h + i):
        raise ValueError("%s has non-finite elements" % name)
    # Columns must be orthonormal: R^T R = I.
    err = max(abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0), abs(c * c + f * f + i * i - 1.0),
              abs(a * b + d * e + g * h), abs(a * c + d * f + g * i), abs(b * c + e * f + h * i))
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not (err <= tol and det > 0.0):
        raise ValueError("%s is not a rotation matrix (|R^T R - I| = %.3g, det = %.6g)" % (name, err, det))
    return a, b, c, d, e, f, g, h, i


def _vector_floats(v: ArrayLike, name: str) -> Vec3:
    arr = np.asarray(v, dtype=float)
    if arr.shape != (3,):
        raise ValueError("%s must have 3 elements, got shape %s" % (name, arr.shape))
    x, y, z = arr.tolist()
    if not math.isfinite(x + y + z):
        raise ValueError("%s has non-finite elements: %r" % (name, (x, y, z)))
    return x, y, z


class AttitudeController:
    """The paper's attitude controller: SO(3) PID with anti-windup, saturation, allocation, stroke cycle, IK.

    ``robot``: the robot model (inertia, drag constant, paw buoyancy, kinematics, nominal feet);
    ``config``: gains, limits and timing (:func:`~quadruped_control.control.controller_config.load_controller_config`).
    The setpoint starts at the identity (level, heading along the world x axis).
    """

    def __init__(self, robot: RobotParams, config: ControllerConfig) -> None:
        if not isinstance(config, ControllerConfig):
            raise ParameterError("config must be a ControllerConfig, got %r" % (config,))
        self.robot = robot
        self._config = config
        inertia = np.asarray(robot.inertia, dtype=float)
        if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
            raise ParameterError("robot inertia must be a finite 3x3 matrix")
        self._inertia: Tuple[float, ...] = tuple(inertia.ravel().tolist())
        self._k_drag = float(robot.drag_constant)
        self._net_buoyancy = float(robot.paw_net_buoyancy)
        self._stroke = self._make_stroke(config.stroke_scheme)
        self._pending_scheme: Optional[str] = None
        self._R_d: Tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        self._R_d_array = np.eye(3)
        self._hold_reason = ""
        self._tau_sat: Vec3 = (0.0, 0.0, 0.0)
        self._omega: Vec3 = (0.0, 0.0, 0.0)
        self.reset()

    # ---- configuration -----------------------------------------------------------------------

    @property
    def config(self) -> ControllerConfig:
        """The configuration in force (replaced, never mutated, by the setters)."""
        return self._config

    @property
    def setpoint(self) -> np.ndarray:
        """Desired attitude R_d (copy)."""
        return self._R_d_array.copy()

    @property
    def holding(self) -> bool:
        return self._stroke.holding

    @property
    def stroke(self) -> StrokeScheme:
        """The stroke scheme in use (read-only use: phases, recorded paths)."""
        return self._stroke

    def _make_stroke(self, name: str) -> StrokeScheme:
        config = self._config
        return make_stroke_scheme(name, self.robot, config.pairs, config.t_rec, config.t_pow_max, config.coordinated)

    def set_stroke_scheme(self, name: str) -> None:
        """Switch to the stroke scheme ``name`` ('paper', 'coordinated'; ParameterError otherwise).

        The switch is smooth: the current scheme holds until every foot is back at the nominal pose
        (strokes retrace or complete), then the new scheme starts there. ``config.stroke_scheme`` names
        the scheme being switched to from the call on.
        """
        config = self._config.replace(stroke_scheme=name)  # validates the name
        if name != self._stroke.name:
            self._make_stroke(name)  # fail early (e.g. an unreachable nominal pose), before anything changes
        self._config = config
        self._pending_scheme = None if name == self._stroke.name else name

    def set_setpoint(self, R_d: ArrayLike) -> None:
        """Desired attitude R_d (body -> world rotation); ValueError unless a finite rotation matrix.

        The integral is kept (the paper does not reset it on setpoint changes).
        """
        floats = _rotation_floats(R_d, "setpoint R_d", self._config.rotation_tolerance)
        self._R_d = floats
        self._R_d_array = np.array(floats).reshape(3, 3)

    def set_setpoint_rpy(self, roll: float, pitch: float, yaw: float) -> None:
        """Desired attitude from REP-103 roll, pitch, yaw in radians (R = Rz(yaw) Ry(pitch) Rx(roll))."""
        self.set_setpoint(rpy_to_rot(float(roll), float(pitch), float(yaw)))

    def set_gains(self, gains: Gains) -> None:
        """New K_p, K_i, K_d, K_aw (validated by :class:`Gains`); effective at the next step."""
        if not isinstance(gains, Gains):
            raise ParameterError("gains must be a Gains instance, got %r" % (gains,))
        self._config = self._config.with_gains(gains)

    def set_timing(self, t_rec: Optional[float] = None, t_pow_max: Optional[float] = None,
                   tau_max: Optional[float] = None) -> None:
        """New timing/limits, validated together (e.g. t_rec >= 2 t_pow_max; ParameterError otherwise).

        tau_max applies at the next step; t_pow_max at the next power-phase start; t_rec at the next
        recovery start.
        """
        changes = {}
        if t_rec is not None:
            changes["t_rec"] = t_rec
        if t_pow_max is not None:
            changes["t_pow_max"] = t_pow_max
        if tau_max is not None:
            changes["tau_max"] = tau_max
        if not changes:
            return
        config = self._config.replace(**changes)
        self._stroke.set_timing(config.t_rec, config.t_pow_max)
        self._config = config

    def reset(self) -> None:
        """Clear the integral and the stroke state: feet at the nominal pose, cycle restarted.

        The next step integrates over dt. If the legs are mid-stroke, the next targets jump to the
        nominal pose: call :meth:`hold` first to retract them smoothly.
        """
        self._integral = [0.0, 0.0, 0.0]
        self._delta_sat: Vec3 = (0.0, 0.0, 0.0)  # Delta_sat of the last command (forward form)
        self._t_prev: Optional[float] = None
        self._e_R: Vec3 = (0.0, 0.0, 0.0)
        self._geodesic = 0.0
        self._hold_reason = ""
        if self._pending_scheme is not None:
            self._stroke = self._make_stroke(self._pending_scheme)
            self._pending_scheme = None
        self._stroke.reset()

    # ---- helpers -----------------------------------------------------------------------------

    def _elapsed(self, t: float) -> float:
        """Elapsed time since the previous step/hold, clipped to [0, max_step]; dt for the first call."""
        config = self._config
        if self._t_prev is None:
            h = config.dt
        else:
            h = min(max(t - self._t_prev, 0.0), config.max_step)
        self._t_prev = t
        return h

    def _velocity_command(self, leg: int, r: Vec3, share: float = 0.25) -> Vec3:
        """eq. (foot_vel) for one leg at a power-phase start, from the latest tau_sat and omega, with the
        leg's torque tau_i = share * tau_sat (the paper: tau_sat / 4)."""
        tx, ty, tz = self._tau_sat
        tau_i = (share * tx, share * ty, share * tz)
        return foot_velocity_command_f(tau_i, r, self._omega, self._k_drag, self._config.normalize_force_direction)

    def _output(self, t: float, h: float, tau_cmd: Vec3, tau_sat: Vec3, saturated: bool,
                feedforward: Vec3) -> ControllerOutput:
        stroke = self._stroke
        p0, p1, p2, p3 = stroke.positions
        v0, v1, v2, v3 = stroke.velocity_commands
        j0, j1, j2, j3 = stroke.joints
        # One array for all vectors of the record (one numpy call instead of nine); the fields are views
        # of disjoint rows of it.
        rows = np.array([*self._e_R, *tau_cmd, *tau_sat, *self._integral, *feedforward, *p0, *p1, *p2, *p3,
                         *v0, *v1, *v2, *v3, *j0, *j1, *j2, *j3], dtype=float).reshape(17, 3)
        state = ControllerStateRecord(
            t=t,
            e_R=rows[0],
            tau_cmd=rows[1],
            tau_sat=rows[2],
            saturated=saturated,
            integral=rows[3],
            geodesic_error=self._geodesic,
            pair_phase=stroke.pair_phase,
            pair_phase_time=stroke.pair_phase_time,
            foot_targets=rows[5:9],
            holding=stroke.holding,
            hold_reason=self._hold_reason,
            R_d=self._R_d_array.copy(),
            dt=h,
            tau_feedforward=rows[4],
            foot_velocity_commands=rows[9:13],
        )
        return ControllerOutput(joint_targets=rows[13:17], state=state)

    # ---- main loop -----------------------------------------------------------------------------

    def step(self, t: float, R: ArrayLike, omega: ArrayLike) -> ControllerOutput:
        """One control step at time ``t`` (s) with the measured attitude R = R_B^W and rate omega_B^B (rad/s).

        Raises ValueError (without changing any state) for a non-finite time, a non-rotation R or a
        non-finite omega or one beyond ``config.max_angular_rate``; the caller should then :meth:`hold`.
        After a hold, the first step restarts the stroke cycle (first pair: half recovery).
        """
        t = float(t)
        if not math.isfinite(t):
            raise ValueError("time must be finite, got %r" % (t,))
        config = self._config
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation_floats(R, "attitude R", config.rotation_tolerance)
        wx, wy, wz = _vector_floats(omega, "angular velocity omega")
        w_max = config.max_angular_rate
        if not (abs(wx) <= w_max and abs(wy) <= w_max and abs(wz) <= w_max):
            raise ValueError("angular velocity omega %r exceeds max_angular_rate %g rad/s" % ((wx, wy, wz), w_max))
        h = self._elapsed(t)
        if self._stroke.holding:
            self._hold_reason = ""
        gains = config.gains
        sx = sy = sz = 0.0
        if config.buoyancy_feedforward:
            for px, py, pz in self._stroke.positions:
                sx += px
                sy += py
                sz += pz
        z = self._integral
        (ex, ey, ez, self._geodesic, z[0], z[1], z[2], cx, cy, cz, sx_, sy_, sz_, saturated, fx, fy,
         fz) = control_law_f(self._R_d, (r00, r01, r02, r10, r11, r12, r20, r21, r22), wx, wy, wz, z,
                             self._delta_sat, h, gains.k_p, gains.k_i, gains.k_d, gains.k_aw, config.tau_max,
                             config.integral_limit, self._inertia, config.gyroscopic_feedforward,
                             config.buoyancy_feedforward, (sx, sy, sz), self._net_buoyancy)
        self._e_R = (ex, ey, ez)
        self._delta_sat = (cx - sx_, cy - sy_, cz - sz_)
        self._tau_sat = (sx_, sy_, sz_)
        self._omega = (wx, wy, wz)

        # Allocation (latched at power starts), eq. (foot_integration) and IK.
        if self._pending_scheme is not None:
            self._switch_step(h)
        else:
            self._stroke.advance(h, self._velocity_command)
        return self._output(t, h, (cx, cy, cz), (sx_, sy_, sz_), saturated, (fx, fy, fz))

    def _switch_step(self, h: float) -> None:
        """One step of a scheme switch: the old scheme holds until its feet are at the nominal pose."""
        self._stroke.hold(h)
        self._hold_reason = "switching stroke scheme to %s" % self._pending_scheme
        if self._stroke.at_rest:
            assert self._pending_scheme is not None
            self._stroke = self._make_stroke(self._pending_scheme)
            self._pending_scheme = None

    def hold(self, t: float, reason: str) -> ControllerOutput:
        """Safe state: no new strokes, integral frozen, feet retrace back to the nominal pose.

        Never raises for a bad ``t`` (a non-finite time counts as one period dt). Joint targets are IK
        solutions along the recorded stroke (then the nominal pose), within the servo ranges.
        """
        try:
            t_value = float(t)
        except (TypeError, ValueError):
            t_value = math.nan
        if math.isfinite(t_value):
            h = self._elapsed(t_value)
        else:
            h = self._config.dt
        self._hold_reason = str(reason)
        self._delta_sat = (0.0, 0.0, 0.0)
        self._tau_sat = (0.0, 0.0, 0.0)
        self._stroke.hold(h)
        zero = (0.0, 0.0, 0.0)
        return self._output(t_value if math.isfinite(t_value) else (self._t_prev or 0.0), h, zero, zero, False, zero)

