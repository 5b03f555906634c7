"""Leg kinematics of the underwater quadruped (paper section "Mathematical Modeling").

Each leg is a symmetric planar five-bar linkage (actuated angles theta1, theta2; passive angles theta4,
theta5, phi; Fig. 3b) whose plane is rotated about the leg frame's x axis by the hip servo (theta3,
Fig. 3c). This module implements:

- eq. (fk_EFG), (fk_phi), (fk_planar): five-bar forward kinematics, :func:`five_bar_fk`;
- eq. (ik_dists), (ik_alphas), (ik_theta1245): five-bar inverse kinematics, :func:`five_bar_ik`;
- eq. (fk_T), (ee_body): leg and body-frame foot position, :func:`leg_fk`, :func:`foot_position`;
- eq. (ik_theta3) and the planar IK: :func:`joint_angles` (body-frame target -> servo angles), and
  :func:`joint_angles_floats`, the same on plain floats (the controller's per-step IK);
- eq. (J_leg): translational leg Jacobian, :func:`five_bar_jacobian`, :func:`foot_jacobian`;
- eq. (ee_vel): floating-base Jacobian, :func:`floating_base_jacobian`;
- the simulator's fast path :func:`leg_kinematics_rows`: r_e,i^B and J_P,i^B q_dot_i of all legs on
  floats, without numpy (the plant needs them at every integration step).

Each forward-kinematics equation is written once, in a float core that the readable functions and the
fast path share: ``_five_bar_closure`` (eq. (fk_EFG), (fk_phi), (fk_planar)), ``_five_bar_rates``
(the five-bar block of eq. (J_leg)), ``_leg_point`` (eq. (fk_T)), ``_leg_rate`` (eq. (J_leg) times the
joint rates) and ``_ee_body`` (eq. (ee_body)).

Geometry of the five-bar in its plane frame F_P: motor 1 at the origin, motor 2 at (c, 0); actuated
link a1 ends at A = a1 (cos theta1, sin theta1), link a2 at B = (c, 0) + a2 (cos theta2, sin theta2);
passive link a3 joins A to the foot, a4 joins B to the foot. theta4 = angle(a3) - theta1 and
theta5 = angle(a4) - theta2 = phi - theta2 are the passive joint angles.

Decisions (see also the docstrings):

- Working mode: the IK of eq. (ik_theta1245) is the "elbows out" branch (theta1 turned clockwise from
  the motor-1-to-foot line, theta2 counter-clockwise), i.e. theta4 in [0, pi], theta5 in [-pi, 0].
  The "+" root of eq. (fk_phi) as printed picks the matching assembly mode (foot always on the
  clockwise side of the line from elbow A to elbow B, one mode for all angles), so FK(IK(p)) == p;
  both facts are checked by the tests. FK itself accepts any closable
  (theta1, theta2); IK(FK(q)) == q only holds for elbows-out configurations.
- Hip branch: eq. (ik_theta3) solves R_x(theta3) (l_y + y', l_z) = (y_d, z_d) with the root
  l_y + y' = -sqrt(R^2 - l_z^2) <= 0, i.e. the five-bar points away from the hip axis (foot "below"
  the motors in its plane). Joint configurations with l_y + y' > 0 (foot folded above the motors)
  are valid for FK but IK maps their foot position to the other hip solution.
- The hip formula eq. (ik_theta3) returns values in (-2 pi - pi/2, pi/2]; servo angles are brought
  into their configured ranges by adding multiples of 2 pi, as are theta1 and theta2. A target whose
  angles cannot be brought into range raises :class:`UnreachableError`; nothing here returns NaN.
- eq. (J_leg) writes the five-bar columns as R_x(theta3) [-C11, C21, 0]^T, [-C12, C22, 0]^T with
  Chavdarov's C_ij; here the 2x2 block is the exact derivative d(x_d, y')/d(theta1, theta2), derived
  from the rigidity of the passive links (see :func:`five_bar_jacobian`), so [-C11, C21] and
  [-C12, C22] are its columns whatever sign convention C_ij carry. The tests compare every Jacobian
  with finite differences.
"""
from __future__ import annotations

import math
from typing import Any, Dict, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.jit import hypot2, jitable
from quadruped_common.robot import LEGS, MIRROR_DIAG
from quadruped_common.so3 import TWO_PI, hat, wrap_angle
from quadruped_common.vec3 import Mat3
from quadruped_control.model.params import FiveBar, RobotParams

NUM_LEGS = len(LEGS)

ArrayLike = Union[Sequence[float], np.ndarray]

#: Rounding slack for arccos arguments and range checks (targets exactly on the boundary).
_ROUND_TOL = 1e-12
#: Angle slack (rad) when wrapping an angle into a servo range that ends exactly at it.
_ANGLE_TOL = 1e-9
#: |sin(phi - psi)| below this: the passive links are aligned (type-2 singularity, no Jacobian).
_SINGULAR_TOL = 1e-9


class UnreachableError(ValueError):
    """A foot target (or joint configuration) the leg cannot realise.

    Raised when a target is outside the five-bar reach, inside the hip offset (R < l_z), outside the
    servo ranges, or not finite. ``leg`` is the leg number when known, ``reason`` the cause.
    """

    def __init__(self, reason: str, leg: Optional[int] = None) -> None:
        self.reason = reason
        self.leg = leg
        message = reason if leg is None else "leg %d: %s" % (leg, reason)
        super().__init__(message)


# --------------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------------

def _check_leg(leg: int) -> None:
    if leg not in MIRROR_DIAG:
        raise ValueError("leg must be one of %s, got %r" % (LEGS, leg))


def _acos_checked(value: float, what: str) -> float:
    """arccos that refuses arguments outside [-1, 1] (beyond rounding) instead of clipping silently."""
    if value > 1.0:
        if value > 1.0 + _ROUND_TOL:
            raise UnreachableError("%s: arccos argument %.6g > 1" % (what, value))
        return 0.0
    if value < -1.0:
        if value < -1.0 - _ROUND_TOL:
            raise UnreachableError("%s: arccos argument %.6g < -1" % (what, value))
        return math.pi
    return math.acos(value)


def wrap_into_range(angle: float, low: float, high: float) -> Optional[float]:
    """``angle + 2 pi k`` inside [low, high] (with a 1e-9 rad slack), or None if there is none."""
    k = math.ceil((low - _ANGLE_TOL - angle) / TWO_PI)
    wrapped = angle + k * TWO_PI
    if wrapped > high + _ANGLE_TOL:
        return None
    return wrapped


# --------------------------------------------------------------------------------------------------
# Five-bar linkage (plane frame F_P)
# --------------------------------------------------------------------------------------------------

@jitable
def _closure_scale(a1: float, a3: float, c: float) -> float:
    """Magnitude of E^2 + F^2 of eq. (fk_EFG), for the relative tolerance of the closure test."""
    return 4.0 * a3 * a3 * (c + 2.0 * a1) ** 2


def _closure_error(theta1: float, theta2: float, disc: float, g: float, a1: float, a3: float, a4: float,
                   c: float) -> UnreachableError:
    """Why :func:`_five_bar_closure` cannot assemble the five-bar at (theta1, theta2)."""
    if not (math.isfinite(theta1) and math.isfinite(theta2)):
        return UnreachableError("five-bar angles must be finite, got (%r, %r)" % (theta1, theta2))
    if disc < -_ROUND_TOL * _closure_scale(a1, a3, c):
        return UnreachableError("five-bar cannot close at theta1=%.2f deg, theta2=%.2f deg (elbows %.4f m "
                                "apart, passive links reach %.4f m)"
                                % (math.degrees(theta1), math.degrees(theta2), math.sqrt(max(g, 0.0)), a3 + a4))
    return UnreachableError("five-bar elbows coincide at theta1=%.2f deg, theta2=%.2f deg: foot undefined"
                            % (math.degrees(theta1), math.degrees(theta2)))


@jitable
def _closure_terms(c1: Any, s1: Any, c2: Any, s2: Any, c21: Any, a1: float, a3: float, c: float) -> Tuple[Any, ...]:
    """E, F, G of eq. (fk_EFG) and the discriminant E^2 + F^2 - G^2, from the cosines and sines of theta1,
    theta2 and cos(theta2 - theta1); valid for the symmetric mechanism a1 = a2, a3 = a4 (enforced by
    params). Plain arithmetic on floats (compiled too, :mod:`quadruped_common.jit`)."""
    e = 2.0 * a3 * (c + a1 * (c2 - c1))
    f = 2.0 * a1 * a3 * (s2 - s1)
    g = c * c + 2.0 * a1 * a1 + 2.0 * c * a1 * c2 - 2.0 * c * a1 * c1 - 2.0 * a1 * a1 * c21
    return e, f, g, e * e + f * f - g * g


class LinkDirections(NamedTuple):
    """The directions of the five-bar's four links: cos and sin of theta1 (a1), theta2 (a2), phi (a4) and
    psi (a3)."""

    cos_theta1: float
    sin_theta1: float
    cos_theta2: float
    sin_theta2: float
    cos_phi: float
    sin_phi: float
    cos_psi: float
    sin_psi: float


@jitable
def _closure_point(theta1: float, theta2: float, a1: float, a2: float, a3: float, a4: float,
                   c: float) -> Tuple[bool, float, float, LinkDirections, float, float]:
    """The one implementation of the five-bar forward kinematics, eq. (fk_EFG), (fk_phi), (fk_planar), on
    floats, without raising (compiled code calls it too, :mod:`quadruped_common.jit`): ``(closes, x_d,
    y_prime, links, disc, g)``. ``links`` (:class:`LinkDirections`) are the directions of the four links
    (phi of a4, psi of a3), which is all
    the Jacobian (:func:`_five_bar_rates_core`) needs: the angles phi and psi themselves only
    :func:`five_bar_fk` reports. ``closes`` is False where E^2 + F^2 - G^2 < 0 (the passive links cannot
    close) or the two elbows coincide (phi undefined); the other values are then meaningless, but for
    ``disc`` and ``g`` that say why (:func:`_five_bar_closure` raises with them).

    Four sines and cosines and two square roots per call (the simulator calls it for every leg at every
    step): cos(theta2 - theta1) by its addition formula, phi's direction by the half-angle identities
    of eq. (fk_phi) instead of an arctangent and its cosine and sine, psi's as the unit vector from
    elbow A to the foot."""
    c1, s1 = math.cos(theta1), math.sin(theta1)
    c2, s2 = math.cos(theta2), math.sin(theta2)
    e, f, g, disc = _closure_terms(c1, s1, c2, s2, c2 * c1 + s2 * s1, a1, a3, c)
    # The relative tolerance only matters at the edge of the workspace; NaN fails every comparison.
    if not ((disc >= 0.0 or disc >= -_ROUND_TOL * _closure_scale(a1, a3, c)) and g >= 1e-24):
        return False, 0.0, 0.0, LinkDirections(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), disc, g
    # eq. (fk_phi): phi = 2 atan2(num, den), so cos phi = (den^2 - num^2) / r2, sin phi = 2 num den / r2
    num = -f + math.sqrt(disc if disc > 0.0 else 0.0)
    den = g - e
    r2 = num * num + den * den
    if r2 > 0.0:
        c_phi, s_phi = (den * den - num * num) / r2, 2.0 * num * den / r2
    else:
        c_phi, s_phi = 1.0, 0.0  # atan2(0, 0) = 0, as the arctangent form gives
    x_d = c + a2 * c2 + a4 * c_phi  # eq. (fk_planar)
    y_prime = a2 * s2 + a4 * s_phi
    u_x, u_y = x_d - a1 * c1, y_prime - a1 * s1  # link a3, from elbow A to the foot
    length = hypot2(u_x, u_y)
    if not length > 0.0:
        return False, 0.0, 0.0, LinkDirections(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), disc, g
    return True, x_d, y_prime, LinkDirections(c1, s1, c2, s2, c_phi, s_phi, u_x / length, u_y / length), disc, g


def _five_bar_closure(theta1: float, theta2: float, a1: float, a2: float, a3: float, a4: float,
                      c: float) -> Tuple[float, float, LinkDirections]:
    """The five-bar forward kinematics of :func:`_closure_point`, raising: the core of :func:`five_bar_fk`,
    :func:`five_bar_jacobian`, :func:`foot_position` and :func:`foot_jacobian`.

    Returns ``(x_d, y_prime, links)``: the foot in F_P and the cosines and sines of theta1, theta2 and of
    the absolute angles of the passive links a4 (phi, the "+" root of eq. (fk_phi)) and a3 (psi).
    ``theta1``, ``theta2`` must be
    finite (the callers check). Raises :class:`UnreachableError` if E^2 + F^2 - G^2 < 0 (the passive
    links cannot close) or if the two elbows coincide (phi undefined).
    """
    closes, x_d, y_prime, links, disc, g = _closure_point(theta1, theta2, a1, a2, a3, a4, c)
    if not closes:
        raise _closure_error(theta1, theta2, disc, g, a1, a3, a4, c)
    return x_d, y_prime, links


def _checked_closure(theta1: float, theta2: float, geometry: FiveBar) -> Tuple[float, float, LinkDirections]:
    """:func:`_five_bar_closure` for the public functions: refuses non-finite angles first."""
    if not (math.isfinite(theta1) and math.isfinite(theta2)):
        raise UnreachableError("five-bar angles must be finite, got (%r, %r)" % (theta1, theta2))
    return _five_bar_closure(theta1, theta2, geometry.a1, geometry.a2, geometry.a3, geometry.a4, geometry.c)


def five_bar_fk(theta1: float, theta2: float, geometry: FiveBar) -> Tuple[float, float, float, float, float]:
    """Foot position of the five-bar from the actuated angles, eq. (fk_EFG), (fk_phi), (fk_planar).

    Returns ``(x_d, y_prime, phi, theta4, theta5)``: the foot in F_P, the absolute angle phi of link
    a4, and the passive joint angles theta4 (link a3 relative to a1) and theta5 (a4 relative to a2,
    phi = theta2 + theta5), all three wrapped into [-pi, pi). Uses the "+" root of eq. (fk_phi), the
    assembly mode that matches the elbows-out IK of eq. (ik_theta1245). Computed by the float core
    :func:`_five_bar_closure`.

    Raises :class:`UnreachableError` for non-finite angles, if E^2 + F^2 - G^2 < 0 (the passive links
    cannot close) or if the two elbows coincide (phi undefined).
    """
    x_d, y_prime, links = _checked_closure(theta1, theta2, geometry)
    phi, psi = math.atan2(links.sin_phi, links.cos_phi), math.atan2(links.sin_psi, links.cos_psi)
    return x_d, y_prime, wrap_angle(phi), wrap_angle(psi - theta1), wrap_angle(phi - theta2)


def five_bar_ik(x_d: float, y_prime: float, geometry: FiveBar) -> Tuple[float, float, float, float]:
    """Elbows-out inverse kinematics, eq. (ik_dists), (ik_alphas), (ik_theta1245).

    Returns ``(theta1, theta2, theta4, theta5)`` with theta1 in (-2 pi, pi], theta2 in (-pi, 2 pi)
    as the formulas give them (the caller wraps them into servo ranges), theta4 in [0, pi],
    theta5 in [-pi, 0]. Raises :class:`UnreachableError` when an arccos argument leaves [-1, 1]
    (foot out of reach of either side chain).
    """
    if not (math.isfinite(x_d) and math.isfinite(y_prime)):
        raise UnreachableError("five-bar target must be finite, got (%r, %r)" % (x_d, y_prime))
    a1, a2, a3, a4, c = geometry.a1, geometry.a2, geometry.a3, geometry.a4, geometry.c
    d13 = hypot2(x_d, y_prime)            # eq. (ik_dists)
    d24 = hypot2(x_d - c, y_prime)
    if d13 < _ROUND_TOL or d24 < _ROUND_TOL:
        raise UnreachableError("five-bar target (%.4f, %.4f) m is on a motor axis: out of reach"
                               % (x_d, y_prime))
    where = "five-bar target (%.4f, %.4f) m" % (x_d, y_prime)
    alpha1 = _acos_checked((d13 * d13 + a1 * a1 - a3 * a3) / (2.0 * a1 * d13),
                           where + " out of reach of motor 1 (distance %.4f m, reach [%.4f, %.4f] m)"
                           % (d13, abs(a1 - a3), a1 + a3))
    alpha2 = _acos_checked((d24 * d24 + a2 * a2 - a4 * a4) / (2.0 * a2 * d24),
                           where + " out of reach of motor 2 (distance %.4f m, reach [%.4f, %.4f] m)"
                           % (d24, abs(a2 - a4), a2 + a4))
    theta1 = math.atan2(y_prime, x_d) - alpha1           # eq. (ik_theta1245)
    theta2 = math.atan2(y_prime, x_d - c) + alpha2
    theta4 = _acos_checked((d13 * d13 - a1 * a1 - a3 * a3) / (2.0 * a1 * a3), where + " (theta4)")
    theta5 = -_acos_checked((d24 * d24 - a2 * a2 - a4 * a4) / (2.0 * a2 * a4), where + " (theta5)")
    return theta1, theta2, theta4, theta5


@jitable
def _five_bar_rates_core(links: LinkDirections, a1: float, a2: float) -> Tuple[bool, float, float, float, float]:
    """The one implementation of the five-bar Jacobian d(x_d, y')/d(theta1, theta2) (the five-bar block
    of eq. (J_leg), see :func:`five_bar_jacobian`), on floats, at a configuration of
    :func:`_closure_point` (its ``links``: cosines and sines of theta1, theta2, phi of a4 and psi of a3),
    without raising: (regular, J11, J12, J21, J22), ``regular`` False at the type-2 singularity
    sin(phi - psi) = 0. The sines of the angle differences by their addition formulas."""
    c1, s1, c2, s2, c_phi, s_phi, c_psi, s_psi = links
    det = s_phi * c_psi - c_phi * s_psi  # sin(phi - psi)
    if not abs(det) >= _SINGULAR_TOL:
        return False, 0.0, 0.0, 0.0, 0.0
    k1 = a1 * (s_psi * c1 - c_psi * s1) / det  # a1 sin(theta4) / sin(phi - psi), theta4 = psi - theta1
    k2 = a2 * (s_phi * c2 - c_phi * s2) / det  # a2 sin(theta5) / sin(phi - psi), theta5 = phi - theta2
    return True, k1 * s_phi, -(k2 * s_psi), -k1 * c_phi, k2 * c_psi


def _five_bar_rates(theta1: float, theta2: float, links: LinkDirections, a1: float,
                    a2: float) -> Tuple[float, float, float, float]:
    """:func:`_five_bar_rates_core`, raising :class:`UnreachableError` at the singularity (at the
    actuated angles theta1, theta2)."""
    regular, j11, j12, j21, j22 = _five_bar_rates_core(links, a1, a2)
    if not regular:
        raise UnreachableError("five-bar singular at theta1=%.2f deg, theta2=%.2f deg: passive links aligned"
                               % (math.degrees(theta1), math.degrees(theta2)))
    return j11, j12, j21, j22


def five_bar_jacobian(theta1: float, theta2: float, geometry: FiveBar) -> np.ndarray:
    """Closed-chain Jacobian d(x_d, y')/d(theta1, theta2) of the five-bar (2x2, analytic).

    The passive links are rigid, so with unit vectors e3 = (cos psi, sin psi) along a3 and
    e4 = (cos phi, sin phi) along a4: e3 . dp = e3 . dA = a1 sin(theta4) dtheta1 and
    e4 . dp = e4 . dB = a2 sin(theta5) dtheta2. Solving the 2x2 system:

        J = 1/sin(phi - psi) [[ a1 sin(theta4) sin(phi), -a2 sin(theta5) sin(psi)],
                              [-a1 sin(theta4) cos(phi),  a2 sin(theta5) cos(psi)]]

    This is the matrix whose columns eq. (J_leg) writes as [-C11, C21]^T and [-C12, C22]^T
    (Chavdarov's closed-chain coefficients). Raises :class:`UnreachableError` at the type-2
    singularity sin(phi - psi) = 0 (passive links aligned), where the foot velocity is undefined.
    Computed by the float cores :func:`_five_bar_closure` and :func:`_five_bar_rates`.
    """
    _, _, links = _checked_closure(theta1, theta2, geometry)
    j11, j12, j21, j22 = _five_bar_rates(theta1, theta2, links, geometry.a1, geometry.a2)
    return np.array([[j11, j12], [j21, j22]])


#: How far (rad) a safe five-bar configuration stays from folding a link onto the next (:func:`five_bar_problem`).
FIVE_BAR_MARGIN = math.radians(15.0)


def five_bar_problem(theta1: float, theta2: float, geometry: FiveBar,
                     margin: float = FIVE_BAR_MARGIN) -> Optional[str]:
    """Why the five-bar may not be driven to (theta1, theta2), or None when it may: the passive links close
    (eq. (fk_EFG)), the elbows stay out (theta4 in [margin, pi - margin], theta5 in [-pi + margin, -margin]: no
    link crosses its neighbour, the IK's working mode) and the passive links stay ``margin`` from aligned (the
    type-2 singularity of eq. (J_leg)). The calibration's sweeps and the reference poses keep to it."""
    try:
        _, _, phi, theta4, theta5 = five_bar_fk(theta1, theta2, geometry)
    except UnreachableError as exc:
        return str(exc)
    where = "at theta1=%.1f deg, theta2=%.1f deg" % (math.degrees(theta1), math.degrees(theta2))
    bound = math.degrees(margin)
    if not margin <= theta4 <= math.pi - margin:
        return "links a1 and a3 fold or cross (theta4 %.1f deg, safe [%.0f, %.0f]) %s" % (
            math.degrees(theta4), bound, 180.0 - bound, where)
    if not -math.pi + margin <= theta5 <= -margin:
        return "links a2 and a4 fold or cross (theta5 %.1f deg, safe [%.0f, %.0f]) %s" % (
            math.degrees(theta5), bound - 180.0, -bound, where)
    psi = theta1 + theta4
    if abs(math.sin(phi - psi)) < math.sin(margin):
        return "passive links nearly aligned (singular, %.1f deg) %s" % (math.degrees(wrap_angle(phi - psi)), where)
    return None


# --------------------------------------------------------------------------------------------------
# Whole leg
# --------------------------------------------------------------------------------------------------

def _floats3(v: ArrayLike, what: str) -> Tuple[float, float, float]:
    """Three Python floats from a 3-sequence or array (cheap; ValueError for another length)."""
    values = v.tolist() if isinstance(v, np.ndarray) else v
    if len(values) != 3:
        raise ValueError("%s must have 3 elements, got %d" % (what, len(values)))
    return float(values[0]), float(values[1]), float(values[2])


def _q3(q: ArrayLike) -> Tuple[float, float, float]:
    t1, t2, t3 = _floats3(q, "joint vector (theta1, theta2, theta3)")
    if not (math.isfinite(t1) and math.isfinite(t2) and math.isfinite(t3)):
        raise UnreachableError("joint angles must be finite, got (%r, %r, %r)" % (t1, t2, t3))
    return t1, t2, t3


@jitable
def _leg_point(x_d: float, y_prime: float, c3: float, s3: float, l_y: float,
               l_z: float) -> Tuple[float, float, float]:
    """eq. (fk_T): planar point (x_d, y') of F_P -> leg frame, rotated by the hip angle theta3
    (c3, s3 = cos theta3, sin theta3)."""
    u = l_y + y_prime  # t_y + c3 y' = c3 (l_y + y') - s3 l_z, t_z + s3 y' = s3 (l_y + y') + c3 l_z
    return x_d, c3 * u - s3 * l_z, s3 * u + c3 * l_z


@jitable
def _leg_rate(j11: float, j12: float, j21: float, j22: float, c3: float, s3: float, p_y: float, p_z: float,
              d1: float, d2: float, d3: float) -> Tuple[float, float, float]:
    """eq. (J_leg) applied to joint rates: the leg-frame foot velocity for (d1, d2, d3) = q_dot, i.e.
    R_x(theta3) [J_fb (d1, d2), 0] + (x_hat x p_e^L) d3, with J_fb = [[j11, j12], [j21, j22]] from
    :func:`_five_bar_rates`, c3, s3 = cos theta3, sin theta3 and (p_y, p_z) the leg-frame foot of
    :func:`_leg_point`. The one implementation of the leg Jacobian: :func:`foot_jacobian` evaluates it
    at unit joint rates."""
    jx = j11 * d1 + j12 * d2
    jy = j21 * d1 + j22 * d2
    return jx, c3 * jy - p_z * d3, s3 * jy + p_y * d3  # x_hat x p = (0, -p_z, p_y)


@jitable
def _ee_body(frame: Tuple[float, ...], px: float, py: float, pz: float) -> Tuple[float, float, float]:
    """eq. (ee_body): r_e,i^B = o_i^B + M_i p_e^L for a leg ``frame`` (o_x, o_y, o_z, m_x, m_y, m_z) of
    :func:`_geometry` (M_i = diag(m_x, m_y, m_z))."""
    ox, oy, oz, mx, my, mz = frame
    return ox + mx * px, oy + my * py, oz + mz * pz


def leg_fk(q: ArrayLike, params: RobotParams) -> np.ndarray:
    """Foot position p_e^L in the leg frame for q = (theta1, theta2, theta3), eq. (fk_T)."""
    t1, t2, t3 = _q3(q)
    x_d, y_prime, _ = _checked_closure(t1, t2, params.five_bar)
    return np.array(_leg_point(x_d, y_prime, math.cos(t3), math.sin(t3), params.l_y, params.l_z))


def foot_position(q: ArrayLike, leg: int, params: RobotParams) -> np.ndarray:
    """Foot position r_e,i^B = o_i^B + M_i p_e^L in the body frame, eq. (ee_body), legs 1..4."""
    _check_leg(leg)
    t1, t2, t3 = _q3(q)
    x_d, y_prime, _ = _checked_closure(t1, t2, params.five_bar)
    px, py, pz = _leg_point(x_d, y_prime, math.cos(t3), math.sin(t3), params.l_y, params.l_z)
    return np.array(_ee_body(_geometry(params).frames[leg], px, py, pz))


def body_to_leg(r: ArrayLike, leg: int, params: RobotParams) -> np.ndarray:
    """p_e^L = M_i^-1 (r_e,i^B - o_i^B) (start of section "Leg Inverse Kinematics"); M_i^-1 = M_i."""
    _check_leg(leg)
    rx, ry, rz = _floats3(r, "foot target")
    mx, my, mz = MIRROR_DIAG[leg]
    ox, oy, oz = params.leg_origins[leg].tolist()
    return np.array([mx * (rx - ox), my * (ry - oy), mz * (rz - oz)])


def leg_ik_full(p: ArrayLike, params: RobotParams, leg: Optional[int] = None) -> np.ndarray:
    """All joint angles (theta1, theta2, theta3, theta4, theta5) for a leg-frame target p_e^L.

    eq. (ik_theta3) for the hip, then y' = y_d cos theta3 + z_d sin theta3 - l_y and the five-bar IK.
    theta1, theta2, theta3 are wrapped by multiples of 2 pi into ``params.joint_limits``.
    Raises :class:`UnreachableError` (naming ``leg`` if given) when the target is not finite, inside
    the hip offset (R < l_z), out of the five-bar reach, or needs an angle outside a servo range.
    """
    x_d, y_d, z_d = _floats3(p, "leg-frame target")
    try:
        return _leg_ik_full(x_d, y_d, z_d, params)
    except UnreachableError as exc:
        if leg is None:
            raise
        raise UnreachableError(exc.reason, leg) from None


@jitable
def _hip_solution(y_d: float, z_d: float, radius: float, l_y: float, l_z: float) -> Tuple[float, float]:
    """eq. (ik_theta3) for a leg-frame target with (y_d, z_d) at ``radius`` >= l_z from the hip axis:
    (theta3 before wrapping into the servo range, the five-bar's y'). The root of R_x(theta3) (l_y + y',
    l_z) = (y_d, z_d) with l_y + y' = -sqrt(R^2 - l_z^2) (module docstring); y' from that root, not from
    the rotation by theta3 (two sines and cosines fewer on the controller's path)."""
    # min() guards l_z / R against rounding just above 1 at R == l_z, max() the root at the same point
    theta3 = math.atan2(z_d, y_d) - math.acos(min(l_z / radius, 1.0)) - 0.5 * math.pi
    return theta3, -math.sqrt(max(y_d * y_d + z_d * z_d - l_z * l_z, 0.0)) - l_y


def _leg_ik_full(x_d: float, y_d: float, z_d: float, params: RobotParams) -> np.ndarray:
    if not (math.isfinite(x_d) and math.isfinite(y_d) and math.isfinite(z_d)):
        raise UnreachableError("target (%r, %r, %r) is not finite" % (x_d, y_d, z_d))
    l_z = params.l_z
    radius = hypot2(y_d, z_d)
    if radius < l_z:
        raise UnreachableError("target (%.4f, %.4f, %.4f) m is %.4f m from the hip axis, closer than the "
                               "five-bar plane offset l_z = %.4f m" % (x_d, y_d, z_d, radius, l_z))
    theta3_raw, y_prime = _hip_solution(y_d, z_d, radius, params.l_y, l_z)
    limits = params.joint_limits
    theta3 = wrap_into_range(theta3_raw, limits.theta3[0], limits.theta3[1])
    if theta3 is None:
        raise UnreachableError("hip angle %.2f deg (mod 360) is outside the hip servo range [%.1f, %.1f] deg"
                               % (math.degrees(wrap_angle(theta3_raw)), math.degrees(limits.theta3[0]),
                                  math.degrees(limits.theta3[1])))
    theta1_raw, theta2_raw, theta4, theta5 = five_bar_ik(x_d, y_prime, params.five_bar)
    theta1 = wrap_into_range(theta1_raw, limits.theta1[0], limits.theta1[1])
    if theta1 is None:
        raise UnreachableError("theta1 = %.2f deg (mod 360) is outside its servo range [%.1f, %.1f] deg"
                               % (math.degrees(wrap_angle(theta1_raw)), math.degrees(limits.theta1[0]),
                                  math.degrees(limits.theta1[1])))
    theta2 = wrap_into_range(theta2_raw, limits.theta2[0], limits.theta2[1])
    if theta2 is None:
        raise UnreachableError("theta2 = %.2f deg (mod 360) is outside its servo range [%.1f, %.1f] deg"
                               % (math.degrees(wrap_angle(theta2_raw)), math.degrees(limits.theta2[0]),
                                  math.degrees(limits.theta2[1])))
    return np.array([theta1, theta2, theta3, theta4, theta5])


def joint_angles_full(r: ArrayLike, leg: int, params: RobotParams) -> np.ndarray:
    """(theta1, theta2, theta3, theta4, theta5) for body-frame foot target ``r`` of ``leg``.

    See :func:`leg_ik_full`; the target is first mapped to the leg frame by inverting eq. (ee_body).
    """
    _check_leg(leg)
    rx, ry, rz = _floats3(r, "foot target")
    mx, my, mz = MIRROR_DIAG[leg]
    ox, oy, oz = params.leg_origins[leg].tolist()  # plain floats: numpy scalars make this 2x slower
    try:
        return _leg_ik_full(mx * (rx - ox), my * (ry - oy), mz * (rz - oz), params)
    except UnreachableError as exc:
        raise UnreachableError(exc.reason, leg) from None


def joint_angles(r: ArrayLike, leg: int, params: RobotParams) -> np.ndarray:
    """Servo angles (theta1, theta2, theta3) within their ranges that put the foot of ``leg`` at ``r``.

    ``r`` is the body-frame target r_e,i^B; eq. (ee_body) inverted, eq. (ik_theta3) .. (ik_theta1245).
    Raises :class:`UnreachableError` (a ValueError) naming the leg and the cause; never returns NaN.
    Computed by :func:`joint_angles_floats` (the same values as ``joint_angles_full(r, leg, params)[:3]``).
    """
    rx, ry, rz = _floats3(r, "foot target")
    return np.array(joint_angles_floats(rx, ry, rz, leg, params))


class IkConstants(NamedTuple):
    """The constants of :func:`ik_row`: the five-bar (a1, a2, a3, a4, c), the hip offsets (l_y, l_z), m, and
    the servo ranges [theta_k_min, theta_k_max], rad."""

    a1: float
    a2: float
    a3: float
    a4: float
    c: float
    l_y: float
    l_z: float
    theta1_min: float
    theta1_max: float
    theta2_min: float
    theta2_max: float
    theta3_min: float
    theta3_max: float


class LegGeometry(NamedTuple):
    """The geometry of the float paths (:func:`joint_angles_floats`, :func:`leg_kinematics_rows`,
    :func:`foot_position`) as floats: ``frames[leg]`` = (o_x, o_y, o_z, m_x, m_y, m_z) of eq. (ee_body),
    ``frame_rows`` the same in the order of LEGS, and the five-bar, hip and servo-range constants
    (``ik``, as :func:`ik_row` takes them)."""

    frames: Dict[int, Tuple[float, ...]]
    frame_rows: Tuple[Tuple[float, ...], ...]
    ik: IkConstants

    @property
    def five_bar_hip(self) -> Tuple[float, ...]:
        """(a1, a2, a3, a4, c, l_y, l_z), as :func:`leg_row` takes them."""
        return tuple(self.ik[:7])


# The LegGeometry of each RobotParams object (frozen, so safe to cache).
_GEOMETRY_CACHE: "dict[int, Tuple[RobotParams, LegGeometry]]" = {}
#: The most recently used entry of _GEOMETRY_CACHE (rebound atomically), checked first.
_GEOMETRY_LAST: "Tuple[Optional[RobotParams], Optional[LegGeometry]]" = (None, None)


def _geometry(params: RobotParams) -> LegGeometry:
    """The :class:`LegGeometry` of ``params`` (cached)."""
    global _GEOMETRY_LAST
    last = _GEOMETRY_LAST
    if last[0] is params:
        return last[1]
    entry = _GEOMETRY_CACHE.get(id(params))
    if entry is not None and entry[0] is params:
        _GEOMETRY_LAST = entry
        return entry[1]
    fb, limits = params.five_bar, params.joint_limits
    frames = {leg: tuple(float(x) for x in params.leg_origins[leg].tolist()) + tuple(MIRROR_DIAG[leg])
              for leg in LEGS}
    ik = IkConstants(float(fb.a1), float(fb.a2), float(fb.a3), float(fb.a4), float(fb.c), float(params.l_y),
                     float(params.l_z), *(float(x) for x in limits.theta1 + limits.theta2 + limits.theta3))
    values = LegGeometry(frames, tuple(frames[leg] for leg in LEGS), ik)
    if len(_GEOMETRY_CACHE) > 64:
        _GEOMETRY_CACHE.clear()
    _GEOMETRY_CACHE[id(params)] = _GEOMETRY_LAST = (params, values)
    return values


def joint_angles_floats(rx: float, ry: float, rz: float, leg: int, params: RobotParams) -> Tuple[float, float, float]:
    """:func:`joint_angles` on plain floats: (theta1, theta2, theta3) for the body-frame target (rx, ry, rz).

    The same formulas in the same floating-point order (eq. (ee_body) inverted, eq. (ik_theta3),
    (ik_dists), (ik_alphas), (ik_theta1245), wrapped into the servo ranges), without numpy and with the
    geometry read from a per-``params`` cache: the controller's per-step IK. Any target that is not
    plainly reachable is handed to :func:`joint_angles_full`, which raises the proper
    :class:`UnreachableError` (or returns its result for the rare rounding-boundary cases). The tests
    compare the two bit for bit.
    """
    last = _GEOMETRY_LAST
    geometry = last[1] if last[0] is params else _geometry(params)
    frame = geometry.frames.get(leg)
    if frame is not None:
        reached, theta1, theta2, theta3 = ik_row(rx, ry, rz, frame, geometry.ik)
        if reached:
            return theta1, theta2, theta3
    t1, t2, t3 = joint_angles_full((rx, ry, rz), leg, params)[:3].tolist()
    return t1, t2, t3


@jitable
def ik_row(rx: float, ry: float, rz: float, frame: Sequence[float],
           constants: IkConstants) -> Tuple[bool, float, float, float]:
    """The one implementation of the leg IK on floats, without raising (compiled code calls it too):
    (reached, theta1, theta2, theta3) for the body-frame target (rx, ry, rz) of the leg ``frame``
    (o_x, o_y, o_z, m_x, m_y, m_z) and the :class:`IkConstants` ``constants``: eq. (ee_body) inverted,
    eq. (ik_theta3), (ik_dists), (ik_alphas), (ik_theta1245), wrapped into the servo ranges. ``reached``
    False where the target is not plainly reachable (the angles are then 0); :func:`joint_angles_floats`
    then asks :func:`joint_angles_full` for the proper error (or its result for the rare rounding-boundary
    cases)."""
    ox, oy, oz, mx, my, mz = frame[0], frame[1], frame[2], frame[3], frame[4], frame[5]
    a1, a2, a3, a4, c = constants.a1, constants.a2, constants.a3, constants.a4, constants.c
    low1, high1 = constants.theta1_min, constants.theta1_max
    low2, high2 = constants.theta2_min, constants.theta2_max
    low3, high3 = constants.theta3_min, constants.theta3_max
    x_d, y_d, z_d = mx * (rx - ox), my * (ry - oy), mz * (rz - oz)
    radius = hypot2(y_d, z_d)
    if radius >= constants.l_z and math.isfinite(x_d + radius):  # also rejects NaN
        # eq. (ik_theta3), then wrap_into_range into the hip servo range
        theta3, y_prime = _hip_solution(y_d, z_d, radius, constants.l_y, constants.l_z)
        theta3 = theta3 + math.ceil((low3 - _ANGLE_TOL - theta3) / TWO_PI) * TWO_PI
        if theta3 <= high3 + _ANGLE_TOL:
            # five_bar_ik without theta4, theta5 (their arccos arguments are only range-checked)
            d13 = hypot2(x_d, y_prime)
            d24 = hypot2(x_d - c, y_prime)
            if d13 >= _ROUND_TOL and d24 >= _ROUND_TOL:
                k1 = (d13 * d13 + a1 * a1 - a3 * a3) / (2.0 * a1 * d13)
                k2 = (d24 * d24 + a2 * a2 - a4 * a4) / (2.0 * a2 * d24)
                k4 = (d13 * d13 - a1 * a1 - a3 * a3) / (2.0 * a1 * a3)
                k5 = (d24 * d24 - a2 * a2 - a4 * a4) / (2.0 * a2 * a4)
                if -1.0 <= k1 <= 1.0 and -1.0 <= k2 <= 1.0 and abs(k4) <= 1.0 + _ROUND_TOL \
                        and abs(k5) <= 1.0 + _ROUND_TOL:
                    theta1 = math.atan2(y_prime, x_d) - math.acos(k1)
                    theta2 = math.atan2(y_prime, x_d - c) + math.acos(k2)
                    theta1 = theta1 + math.ceil((low1 - _ANGLE_TOL - theta1) / TWO_PI) * TWO_PI
                    theta2 = theta2 + math.ceil((low2 - _ANGLE_TOL - theta2) / TWO_PI) * TWO_PI
                    if theta1 <= high1 + _ANGLE_TOL and theta2 <= high2 + _ANGLE_TOL:
                        return True, theta1, theta2, theta3
    return False, 0.0, 0.0, 0.0


@jitable
def _jacobian_entries(j11: float, j12: float, j21: float, j22: float, c3: float, s3: float, p_y: float, p_z: float,
                      m_x: float, m_y: float, m_z: float) -> Mat3:
    """J_P,i^B = M_i [columns]: the columns are the leg-frame foot velocities of :func:`_leg_rate`
    for unit joint rates, M_i = diag(m_x, m_y, m_z) the leg's mirror (eq. (J_leg), (ee_body))."""
    a = _leg_rate(j11, j12, j21, j22, c3, s3, p_y, p_z, 1.0, 0.0, 0.0)
    b = _leg_rate(j11, j12, j21, j22, c3, s3, p_y, p_z, 0.0, 1.0, 0.0)
    d = _leg_rate(j11, j12, j21, j22, c3, s3, p_y, p_z, 0.0, 0.0, 1.0)
    return Mat3(m_x * a[0], m_x * b[0], m_x * d[0], m_y * a[1], m_y * b[1], m_y * d[1], m_z * a[2], m_z * b[2],
                m_z * d[2])


@jitable
def leg_jacobian_row(t1: float, t2: float, t3: float, frame: Sequence[float], a1: float, a2: float, a3: float,
                     a4: float, c: float, l_y: float, l_z: float) -> Tuple[bool, Mat3]:
    """:func:`foot_jacobian` on floats, without raising (compiled code calls it too): (ok, J_P,i^B)
    for joint angles (t1, t2, t3) and the leg ``frame`` (o_x, o_y, o_z, m_x, m_y, m_z) of :func:`_geometry`;
    ``ok`` False where the five-bar cannot close or is singular (the values are then meaningless)."""
    closes, x_d, y_prime, links, _, _ = _closure_point(t1, t2, a1, a2, a3, a4, c)
    regular, j11, j12, j21, j22 = _five_bar_rates_core(links, a1, a2)
    c3, s3 = math.cos(t3), math.sin(t3)
    _, py, pz = _leg_point(x_d, y_prime, c3, s3, l_y, l_z)
    return closes and regular, _jacobian_entries(j11, j12, j21, j22, c3, s3, py, pz, frame[3], frame[4], frame[5])


def foot_jacobian(q: ArrayLike, leg: int, params: RobotParams) -> np.ndarray:
    """Translational leg Jacobian J_P,i^B = d r_e,i^B / d(theta1, theta2, theta3), eq. (J_leg), 3x3.

    Columns: M_i R_x(theta3) [J_fb[:, k], 0] for the five-bar motors (J_fb from
    :func:`five_bar_jacobian`) and M_i (x_hat x p_e^L) for the hip: the foot velocities of
    :func:`_leg_rate` for unit joint rates.
    """
    _check_leg(leg)
    t1, t2, t3 = _q3(q)
    fb = params.five_bar
    x_d, y_prime, links = _checked_closure(t1, t2, fb)
    j11, j12, j21, j22 = _five_bar_rates(t1, t2, links, fb.a1, fb.a2)
    c3, s3 = math.cos(t3), math.sin(t3)
    _, py, pz = _leg_point(x_d, y_prime, c3, s3, params.l_y, params.l_z)
    return np.array(_jacobian_entries(j11, j12, j21, j22, c3, s3, py, pz, *MIRROR_DIAG[leg])).reshape(3, 3)


def floating_base_jacobian(q: ArrayLike, leg: int, R: ArrayLike, params: RobotParams) -> np.ndarray:
    """J_P,i^W = [I_3, -R [r_e,i^B]_x, R J_P,i^B], eq. (ee_vel), 3x9.

    Maps u = (v_B^W, omega_B^B, theta_dot_i) to the foot's world-frame velocity, eq. (fb_jac).
    """
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError("R must be 3x3, got shape %s" % (R.shape,))
    r = foot_position(q, leg, params)
    out = np.empty((3, 9))
    out[:, 0:3] = np.eye(3)
    out[:, 3:6] = -R @ hat(r)
    out[:, 6:9] = R @ foot_jacobian(q, leg, params)
    return out


# --------------------------------------------------------------------------------------------------
# Limits
# --------------------------------------------------------------------------------------------------

def within_limits(q: ArrayLike, params: RobotParams, tol: float = 1e-9) -> bool:
    """True if (theta1, theta2, theta3) are finite and inside their servo ranges (+ ``tol`` rad)."""
    if len(q) != 3:
        raise ValueError("joint vector must have 3 elements, got %d" % len(q))
    limits = params.joint_limits
    for value, (low, high) in zip(q, (limits.theta1, limits.theta2, limits.theta3)):
        value = float(value)
        if not (math.isfinite(value) and low - tol <= value <= high + tol):
            return False
    return True


def clamp_to_limits(q: ArrayLike, params: RobotParams) -> np.ndarray:
    """(theta1, theta2, theta3) clipped into the servo ranges; ValueError for non-finite input."""
    arr = np.asarray(q, dtype=float).reshape(-1)
    if arr.shape != (3,):
        raise ValueError("joint vector must have 3 elements, got shape %s" % (np.shape(q),))
    if not np.all(np.isfinite(arr)):
        raise ValueError("joint vector has non-finite elements: %s" % (arr,))
    bounds = params.joint_limits.as_array()
    return np.clip(arr, bounds[:, 0], bounds[:, 1])


def leg_kinematics(q: Sequence[Sequence[float]], q_dot: Sequence[Sequence[float]],
                   params: RobotParams) -> list:
    """Foot positions and joint-induced foot velocities of all legs in one pass, on floats.

    For each leg i (rows of ``q``, ``q_dot``: legs 1..4 x (theta1, theta2, theta3)) returns the list
    [x, y, z, vx, vy, vz] of r_e,i^B (eq. (ee_body)) and J_P,i^B(q_i) q_dot_i (eq. (J_leg)), body frame.
    See :func:`leg_kinematics_rows`.
    """
    if len(q) != NUM_LEGS or len(q_dot) != NUM_LEGS:
        raise ValueError("q and q_dot must have %d rows (legs), got %d and %d" % (NUM_LEGS, len(q), len(q_dot)))
    return [list(row) for row in leg_kinematics_rows(q, q_dot, params)]


def leg_kinematics_rows(q: Sequence[Sequence[float]], q_dot: Sequence[Sequence[float]],
                        params: RobotParams) -> Tuple[Tuple[float, ...], ...]:
    """:func:`leg_kinematics` as a tuple of the legs' rows (x, y, z, vx, vy, vz), legs 1..4: the simulator's path.

    The float fast path of :func:`foot_position` and :func:`foot_jacobian` times q_dot: the same float
    cores (:func:`_five_bar_closure`, :func:`_five_bar_rates`, :func:`_leg_point`, :func:`_leg_rate`,
    :func:`_ee_body`), with the five-bar closed once per leg instead of once per function and no numpy
    (the tests compare the two). It exists for speed: the plant evaluates it at every integration step
    and the supervisor at every tick. Angles must be finite (the callers check); a configuration the
    five-bar cannot assemble, or a singular one, raises :class:`UnreachableError`.
    """
    last = _GEOMETRY_LAST
    geometry = last[1] if last[0] is params else _geometry(params)
    frames = geometry.frame_rows
    a1, a2, a3, a4, c, l_y, l_z = geometry.five_bar_hip
    rows: Tuple[Tuple[float, ...], ...] = ()
    for (t1, t2, t3), (d1, d2, d3), frame in zip(q, q_dot, frames):
        ok, x, y, z, vx, vy, vz = leg_row(t1, t2, t3, d1, d2, d3, frame, a1, a2, a3, a4, c, l_y, l_z)
        if not ok:  # say why, with the raising forms of the same cores
            _five_bar_rates(t1, t2, _five_bar_closure(t1, t2, a1, a2, a3, a4, c)[2], a1, a2)
        rows += ((x, y, z, vx, vy, vz),)
    return rows


class LegRow(NamedTuple):
    """One leg of :func:`leg_row`: ``ok``, the foot r_e,i^B = (x, y, z) and its joint-induced velocity
    J_P,i^B q_dot_i = (vx, vy, vz), body frame."""

    ok: bool
    x: float
    y: float
    z: float
    vx: float
    vy: float
    vz: float


@jitable
def leg_row(t1: float, t2: float, t3: float, d1: float, d2: float, d3: float, frame: Sequence[float], a1: float,
            a2: float, a3: float, a4: float, c: float, l_y: float, l_z: float) -> LegRow:
    """One leg of :func:`leg_kinematics_rows`, without raising (compiled code calls it too): the
    :class:`LegRow` (ok, r_e,i^B, J_P,i^B q_dot_i) for joint angles (t1, t2, t3), rates (d1, d2, d3) and
    the leg ``frame`` (o_x, o_y, o_z, m_x, m_y, m_z) of :func:`_geometry`; ``ok`` False where the
    five-bar cannot close or is singular (the values are then meaningless). eq. (fk_EFG), (fk_phi),
    (fk_planar), (fk_T), (J_leg), (ee_body)."""
    closes, x_d, y_prime, links, _, _ = _closure_point(t1, t2, a1, a2, a3, a4, c)
    regular, j11, j12, j21, j22 = _five_bar_rates_core(links, a1, a2)
    c3, s3 = math.cos(t3), math.sin(t3)
    px, py, pz = _leg_point(x_d, y_prime, c3, s3, l_y, l_z)
    vx, vy, vz = _leg_rate(j11, j12, j21, j22, c3, s3, py, pz, d1, d2, d3)
    x, y, z = _ee_body(frame, px, py, pz)
    return LegRow(closes and regular, x, y, z, frame[3] * vx, frame[4] * vy, frame[5] * vz)  # M_i J^L q_dot
