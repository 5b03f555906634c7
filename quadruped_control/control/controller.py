"""SO(3) attitude controller of the underwater quadruped (paper section "Attitude Controller Design").

:meth:`AttitudeController.step` (100 Hz) computes the orientation error, eq. (error), the control law
with anti-windup, eq. (pid), and the saturation, eq. (sat) (:func:`control_law_f`), then advances the
stroke scheme (:mod:`quadruped_control.control.strokes`), which latches the allocation of eq.
(foot_speed), (foot_vel) (:mod:`quadruped_control.control.allocation`) at each power-phase start,
integrates the foot positions, eq. (foot_integration), and solves the leg IK for the joint targets.
The setpoint R_d is a world attitude; with ``yaw_free`` only its tilt is tracked and no torque about the world
vertical is commanded (:meth:`AttitudeController.set_setpoint`; how operator setpoints become R_d:
:mod:`quadruped_control.control.yaw_reference`).

Contract: bad measurements (non-finite, not a rotation, omega beyond ``max_angular_rate``) raise
ValueError from :meth:`~AttitudeController.step` without changing any state, and the caller then calls
:meth:`~AttitudeController.hold`; no output ever contains NaN; joint targets are always within the
servo ranges; the integral stays bounded (norm ``integral_limit``) for every gain and step. Pure
Python/numpy, no ROS: the ROS node and the offline simulator wrap the same object. The discretisation
of the integral and the stability argument: docs/controller.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

# estimate_body_torque (eq. (torque_leg) from measured joint motion) lives in allocation; re-exported here.
from quadruped_common.config import ParameterError
from quadruped_common.jit import jitable
from quadruped_common.so3 import rpy_to_rot
from quadruped_common.vec3 import ZERO, Mat3, Vec3, add, cross, mat_vec, norm, row, scale, sub, transpose_times
from quadruped_control.control.allocation import estimate_body_torque, foot_velocity_command_f
from quadruped_control.control.controller_config import ControllerConfig, Gains
from quadruped_control.control.strokes import StrokeScheme, make_stroke_scheme
from quadruped_control.control.yaw_reference import reject, tilt_setpoint
from quadruped_control.model.params import RobotParams

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

__all__ = [
    "AttitudeController",
    "ControllerOutput",
    "ControllerStateRecord",
    "Feedforward",
    "LawGains",
    "LawResult",
    "control_law_f",
    "control_torque",
    "estimate_body_torque",
    "pid_torque",
    "saturate",
    "saturate_f",
    "without_yaw",
]


# --------------------------------------------------------------------------------------------------
# The control law, eq. (error), (pid), (sat), on named quantities
# --------------------------------------------------------------------------------------------------

class LawGains(NamedTuple):
    """The gains and limits of eq. (pid), (sat): K_p, K_i, K_d, K_aw, tau_max (N m) and the norm the
    integral z is clipped to (s)."""

    k_p: float
    k_i: float
    k_d: float
    k_aw: float
    tau_max: float
    integral_limit: float


class Feedforward(NamedTuple):
    """The model terms of eq. (pid): omega x (I omega) when ``gyroscopic`` (``inertia`` I, body frame), and
    -tau_buoyancy^B of eq. (buoy_torque) when ``buoyancy`` (``paw_net_buoyancy`` B of one paw, N)."""

    gyroscopic: bool
    inertia: Mat3
    buoyancy: bool
    paw_net_buoyancy: float


class LawResult(NamedTuple):
    """One step of :func:`control_law_f`: the error e_R of eq. (error) and the geodesic angle of R_d^T R
    (rad), the integral z_k (s), tau_cmd of eq. (pid), tau_sat of eq. (sat) and whether it clipped, and
    the feedforward part of tau_cmd (N m)."""

    e_R: Vec3
    geodesic: float
    z: Vec3
    tau_cmd: Vec3
    tau_sat: Vec3
    saturated: bool
    feedforward: Vec3


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
    x, y, z = np.asarray(tau_cmd, dtype=float).reshape(3).tolist()
    tau_sat, saturated = saturate_f((x, y, z), float(tau_max))
    return np.array(tau_sat), saturated


@jitable
def saturate_f(tau_cmd: Vec3, tau_max: float) -> Tuple[Vec3, bool]:
    """eq. (sat) on floats: (tau_sat, saturated)."""
    magnitude = norm(tau_cmd)
    if magnitude <= tau_max:
        return tau_cmd, False
    return scale(tau_max / magnitude, tau_cmd), True


@jitable
def pid_torque(e_R: Vec3, z: Vec3, omega: Vec3, gains: LawGains, feedforward: Vec3) -> Vec3:
    """tau = -K_p e_R - K_i z - K_d omega + feedforward, eq. (pid), summed left to right."""
    return add(sub(sub(scale(-gains.k_p, e_R), scale(gains.k_i, z)), scale(gains.k_d, omega)), feedforward)


@jitable
def control_law_f(R_d: Mat3, R: Mat3, omega: Vec3, z: Vec3, delta_sat: Vec3, h: float, gains: LawGains,
                  model: Feedforward, feet_sum: Vec3) -> LawResult:
    """One step of eq. (error), (pid) and (sat): the controller's law, the one implementation (the robot's
    :class:`AttitudeController` runs it as Python, the simulator's batched controller compiled).

    ``R_d``, ``R``: setpoint and measured attitude; ``omega``: measured rate; ``z``: the integral z_(k-1);
    ``delta_sat``: Delta_sat = tau_cmd - tau_sat of the previous command; ``h``: the step (s); ``gains``;
    ``model``: the feedforward terms; ``feet_sum``: sum of the commanded foot positions (for the buoyancy
    feedforward). The integral's two
    discretisations are those of docs/controller.md. The operations and their order are those of the
    first release: the paper-sim limit cycles are sensitive to the last bit, and their numbers are kept.
    """
    # eq. (error): E = R_d^T R, e_R = 1/2 vee(E - E^T), geodesic angle of E.
    E = transpose_times(R_d, R)
    e_R = scale(0.5, (E.zy - E.yz, E.xz - E.zx, E.yx - E.xy))
    geodesic = math.atan2(norm(e_R), 0.5 * ((E.xx + E.yy + E.zz) - 1.0))

    # Feedforward of eq. (pid): omega x (I omega) - tau_buoyancy^B, eq. (buoy_torque) at the commanded feet:
    # tau_buoyancy^B = sum_i r_i x (R^T B z_hat) = (sum_i r_i) x (B * third row of R).
    feedforward = ZERO
    if model.gyroscopic:
        feedforward = add(feedforward, cross(omega, mat_vec(model.inertia, omega)))
    if model.buoyancy:
        feedforward = sub(feedforward, cross(feet_sum, scale(model.paw_net_buoyancy, row(R, 2))))

    # The integral dz/dt = e_R + K_aw Delta_sat: forward in the anti-windup excess while the loop gain
    # g = h K_aw K_i of one step is at most 1, backward Euler in closed form beyond (docs/controller.md).
    g = h * gains.k_aw * gains.k_i
    if g <= 1.0:
        z = add(z, scale(h, add(e_R, scale(gains.k_aw, delta_sat))))
    else:
        z = add(z, scale(h, e_R))  # predictor, and its command u
        u = pid_torque(e_R, z, omega, gains, feedforward)
        norm_u = norm(u)
        if norm_u > gains.tau_max:  # h K_aw |Delta_sat| / |u|
            z = add(z, scale(h * gains.k_aw * (norm_u - gains.tau_max) / ((1.0 + g) * norm_u), u))
    norm_z = norm(z)
    if norm_z > gains.integral_limit:
        z = scale(gains.integral_limit / norm_z, z)

    tau_cmd = pid_torque(e_R, z, omega, gains, feedforward)  # eq. (pid)
    tau_sat, saturated = saturate_f(tau_cmd, gains.tau_max)  # eq. (sat)
    return LawResult(e_R, geodesic, z, tau_cmd, tau_sat, saturated, feedforward)


def without_yaw(law: LawResult, vertical: Vec3, tau_max: float) -> LawResult:
    """``law`` with no component about the world ``vertical`` (unit, body frame) in z, the feedforward and
    tau_cmd, and tau_sat of eq. (sat) taken again from that tau_cmd: the tilt-only law (yaw reference ``tilt``)."""
    tau_cmd = reject(law.tau_cmd, vertical)
    tau_sat, saturated = saturate_f(tau_cmd, tau_max)
    return law._replace(z=reject(law.z, vertical), tau_cmd=tau_cmd, tau_sat=tau_sat, saturated=saturated,
                        feedforward=reject(law.feedforward, vertical))


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

def _rotation_floats(R: ArrayLike, name: str, tol: float) -> Mat3:
    """R as a :class:`~quadruped_common.vec3.Mat3`; ValueError unless finite, 3x3, |R^T R - I| <= tol and
    det > 0."""
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3):
        raise ValueError("%s must be a 3x3 rotation matrix, got shape %s" % (name, M.shape))
    a, b, c, d, e, f, g, h, i = rotation = Mat3(*M.ravel().tolist())
    if not math.isfinite(a + b + c + d + e + f + g + h + i):
        raise ValueError("%s has non-finite elements" % name)
    # Columns must be orthonormal: R^T R = I.
    err = max(abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0), abs(c * c + f * f + i * i - 1.0),
              abs(a * b + d * e + g * h), abs(a * c + d * f + g * i), abs(b * c + e * f + h * i))
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not (err <= tol and det > 0.0):
        raise ValueError("%s is not a rotation matrix (|R^T R - I| = %.3g, det = %.6g)" % (name, err, det))
    return rotation


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
        self._inertia = Mat3(*inertia.ravel().tolist())
        self._k_drag = float(robot.drag_constant)
        self._net_buoyancy = float(robot.paw_net_buoyancy)
        self._stroke = self._make_stroke(config.stroke_scheme)
        self._pending_scheme: Optional[str] = None
        self._R_d = Mat3(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        self._R_d_array = np.eye(3)
        self._yaw_free = False
        self._hold_reason = ""
        self._law_gains_cache: Optional[Tuple[ControllerConfig, LawGains]] = None
        self._feedforward_cache: Optional[Tuple[ControllerConfig, Feedforward]] = None
        self._tau_sat: Vec3 = ZERO
        self._omega: Vec3 = ZERO
        self.reset()

    # ---- configuration -----------------------------------------------------------------------

    @property
    def config(self) -> ControllerConfig:
        """The configuration in force (replaced, never mutated, by the setters)."""
        return self._config

    @property
    def setpoint(self) -> np.ndarray:
        """Desired attitude R_d (copy): as set, or with ``yaw_free`` the last step's (:meth:`set_setpoint`)."""
        return self._R_d_array.copy()

    @property
    def yaw_free(self) -> bool:
        """Is only the setpoint's tilt tracked (:meth:`set_setpoint`)?"""
        return self._yaw_free

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

    def set_setpoint(self, R_d: ArrayLike, yaw_free: bool = False) -> None:
        """Desired attitude R_d (body -> world rotation); ValueError unless a finite rotation matrix.

        ``yaw_free`` (yaw reference ``tilt``, :mod:`~quadruped_control.control.yaw_reference`): only R_d's tilt is
        tracked, its yaw not at all. Each step then controls towards the rotation with R_d's tilt closest to the
        measured attitude (:func:`~quadruped_control.control.yaw_reference.tilt_setpoint`), whose e_R of eq.
        (error) has no component about the world vertical, and :func:`without_yaw` removes that component from
        the integral and from tau_cmd of eq. (pid) before eq. (sat): no torque about the world vertical is
        demanded from the allocation (docs/controller.md). That rotation is the step's R_d in the record.

        The integral is kept (the paper does not reset it on setpoint changes).
        """
        R_d = _rotation_floats(R_d, "setpoint R_d", self._config.rotation_tolerance)
        self._R_d = R_d
        self._R_d_array = np.array(R_d).reshape(3, 3)
        self._yaw_free = bool(yaw_free)

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
        self._integral: Vec3 = ZERO  # z of eq. (pid)
        self._delta_sat: Vec3 = ZERO  # Delta_sat of the last command (forward form)
        self._t_prev: Optional[float] = None
        self._e_R: Vec3 = ZERO
        self._geodesic = 0.0
        self._hold_reason = ""
        if self._pending_scheme is not None:
            self._stroke = self._make_stroke(self._pending_scheme)
            self._pending_scheme = None
        self._stroke.reset()

    # ---- helpers -----------------------------------------------------------------------------

    def _law_gains(self) -> LawGains:
        """The gains and limits in force, for :func:`control_law_f` (built once per configuration)."""
        config = self._config
        cached = self._law_gains_cache
        if cached is None or cached[0] is not config:
            gains = config.gains
            cached = self._law_gains_cache = (config, LawGains(gains.k_p, gains.k_i, gains.k_d, gains.k_aw,
                                                                config.tau_max, config.integral_limit))
        return cached[1]

    def _feedforward(self) -> Feedforward:
        """The feedforward switches in force and the robot's terms, for :func:`control_law_f`."""
        config = self._config
        cached = self._feedforward_cache
        if cached is None or cached[0] is not config:
            cached = self._feedforward_cache = (config, Feedforward(config.gyroscopic_feedforward, self._inertia,
                                                                    config.buoyancy_feedforward,
                                                                    self._net_buoyancy))
        return cached[1]

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
        return foot_velocity_command_f(scale(share, self._tau_sat), r, self._omega, self._k_drag,
                                       self._config.normalize_force_direction)

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
        R_measured = _rotation_floats(R, "attitude R", config.rotation_tolerance)
        omega_measured = _vector_floats(omega, "angular velocity omega")
        w_max = config.max_angular_rate
        if not all(abs(w) <= w_max for w in omega_measured):
            raise ValueError("angular velocity omega %r exceeds max_angular_rate %g rad/s" % (omega_measured, w_max))
        h = self._elapsed(t)
        if self._stroke.holding:
            self._hold_reason = ""
        feet_sum = ZERO
        if config.buoyancy_feedforward:
            for foot in self._stroke.positions:
                feet_sum = add(feet_sum, foot)
        if self._yaw_free:  # tilt only: R_d with the setpoint's tilt nearest R, nothing about the vertical
            vertical = row(R_measured, 2)  # the world vertical in the body frame
            R_d = tilt_setpoint(self._R_d, R_measured)
            self._R_d_array = np.array(R_d).reshape(3, 3)
            law = without_yaw(control_law_f(R_d, R_measured, omega_measured, reject(self._integral, vertical),
                                            self._delta_sat, h, self._law_gains(), self._feedforward(), feet_sum),
                              vertical, config.tau_max)
        else:
            law = control_law_f(self._R_d, R_measured, omega_measured, self._integral, self._delta_sat, h,
                                self._law_gains(), self._feedforward(), feet_sum)
        self._e_R, self._geodesic, self._integral = law.e_R, law.geodesic, law.z
        self._delta_sat = sub(law.tau_cmd, law.tau_sat)
        self._tau_sat = law.tau_sat
        self._omega = omega_measured

        # Allocation (latched at power starts), eq. (foot_integration) and IK.
        if self._pending_scheme is not None:
            self._switch_step(h)
        else:
            self._stroke.advance(h, self._velocity_command)
        return self._output(t, h, law.tau_cmd, law.tau_sat, law.saturated, law.feedforward)

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
        self._delta_sat = ZERO
        self._tau_sat = ZERO
        self._stroke.hold(h)
        zero = (0.0, 0.0, 0.0)
        return self._output(t_value if math.isfinite(t_value) else (self._t_prev or 0.0), h, zero, zero, False, zero)

