"""Added mass of the torso (a submerged ellipsoid) and of the paws (spheres).

A body accelerating in still water also accelerates the water around it. For ideal (potential) flow the
fluid's kinetic energy is T_A = 1/2 nu^T M_A nu with nu = (v, omega) in body axes, and Kirchhoff's
equations give the fluid's force and moment on the body (Fossen, "Handbook of Marine Craft
Hydrodynamics and Motion Control", 2011, sections 6.3.1 and 6.4, which the paper cites):

    [f_A; tau_A] = -M_A nu_dot - C_A(nu) nu,
    C_A(nu) nu = [ omega x p ;  v x p + omega x h ],   [p; h] = M_A nu,                  (Fossen eq. 6.43)

so that (M_RB + M_A) nu_dot + C_RB(nu) nu + C_A(nu) nu = tau. C_A(nu) is skew-symmetric in the sense
nu^T C_A(nu) nu = 0: the added-mass terms exchange energy, never create it.

Ellipsoid with semi-axes a, b, c along body x, y, z (Lamb, "Hydrodynamics", art. 114; Fossen
section 6.4.1 for the spheroid): with Delta(l) = sqrt((a^2 + l)(b^2 + l)(c^2 + l)),

    alpha_0 = a b c int_0^inf dl / ((a^2 + l) Delta),  beta_0 (b^2), gamma_0 (c^2) likewise,
    X_udot = -alpha_0 / (2 - alpha_0) m_f,  Y_vdot = -beta_0 / (2 - beta_0) m_f,  Z_wdot = -gamma_0 / (2 - gamma_0) m_f,
    K_pdot = -1/5 m_f (b^2 - c^2)^2 (gamma_0 - beta_0) / (2 (b^2 - c^2) + (b^2 + c^2)(beta_0 - gamma_0)),
    M_qdot, N_rdot by cyclic permutation (a, b, c), (alpha_0, beta_0, gamma_0),

m_f = rho 4/3 pi a b c the displaced fluid mass. M_A = -diag(X_udot, ..., N_rdot) (the ellipsoid's three
planes of symmetry make it diagonal about its centre). A sphere has alpha_0 = beta_0 = gamma_0 = 2/3:
translational added mass m_f / 2 and no rotational added inertia.

A paw is a sphere of volume V: added mass rho V / 2 in every direction. It is carried at the foot
position r_i^B, so its inertial force on the torso is that of a point mass m_a = rho V / 2 at r_i:
-m_a a_i with a_i = v_dot + omega_dot x r_i + omega x v + omega x (omega x r_i) + 2 omega x c_i
(body axes, c_i = J_P,i q_dot_i the joint-induced foot velocity, eq. (J_leg); the joints' acceleration
is zero within a held step). :func:`point_mass_matrix` is its acceleration part.
"""
from __future__ import annotations

import math
from typing import Sequence, Tuple

import numpy as np
from scipy import integrate

__all__ = ["ellipsoid_added_mass", "ellipsoid_coefficients", "kirchhoff_terms", "point_mass_matrix",
           "sphere_added_mass"]


def ellipsoid_coefficients(a: float, b: float, c: float) -> Tuple[float, float, float]:
    """Lamb's (alpha_0, beta_0, gamma_0) of an ellipsoid with semi-axes a, b, c (m); they sum to 2."""
    for name, value in (("a", a), ("b", b), ("c", c)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError("ellipsoid semi-axis %s must be a positive finite length, got %r" % (name, value))

    def coefficient(s2: float) -> float:
        # substitution l = t^2 / (1 - t)^2 maps [0, 1) onto [0, inf) for a well-behaved integrand
        def f(t: float) -> float:
            lam = (t / (1.0 - t)) ** 2
            dl = 2.0 * t / (1.0 - t) ** 3
            delta = math.sqrt((a * a + lam) * (b * b + lam) * (c * c + lam))
            return dl / ((s2 + lam) * delta)
        value, _ = integrate.quad(f, 0.0, 1.0, epsabs=1e-13, epsrel=1e-11, limit=200)
        return a * b * c * value

    return coefficient(a * a), coefficient(b * b), coefficient(c * c)


def _rotational(m_f: float, s1: float, s2: float, k1: float, k2: float) -> float:
    """1/5 m_f (s1 - s2)^2 (k2 - k1) / (2 (s1 - s2) + (s1 + s2)(k1 - k2)); 0 for s1 = s2 (axisymmetric)."""
    d = s1 - s2
    denominator = 2.0 * d + (s1 + s2) * (k1 - k2)
    if abs(d) <= 1e-12 * (s1 + s2) or denominator == 0.0:
        return 0.0
    return 0.2 * m_f * d * d * (k2 - k1) / denominator


def ellipsoid_added_mass(a: float, b: float, c: float, rho: float) -> np.ndarray:
    """6x6 added-mass matrix M_A (body axes, about the centre) of an ellipsoid; see the module docstring."""
    if not (math.isfinite(rho) and rho > 0.0):
        raise ValueError("fluid density must be positive, got %r" % (rho,))
    alpha, beta, gamma = ellipsoid_coefficients(a, b, c)
    m_f = rho * 4.0 / 3.0 * math.pi * a * b * c
    a2, b2, c2 = a * a, b * b, c * c
    diagonal = [alpha / (2.0 - alpha) * m_f, beta / (2.0 - beta) * m_f, gamma / (2.0 - gamma) * m_f,
                _rotational(m_f, b2, c2, beta, gamma),
                _rotational(m_f, c2, a2, gamma, alpha),
                _rotational(m_f, a2, b2, alpha, beta)]
    return np.diag(diagonal)


def sphere_added_mass(volume: float, rho: float) -> float:
    """Added mass of a sphere, rho V / 2 (kg)."""
    if not (math.isfinite(volume) and volume >= 0.0 and math.isfinite(rho) and rho > 0.0):
        raise ValueError("sphere volume must be >= 0 and density > 0, got %r, %r" % (volume, rho))
    return 0.5 * rho * volume


def point_mass_matrix(mass: float, r: Sequence[float]) -> np.ndarray:
    """6x6 generalised mass of a point mass at r (body axes) for nu = (v, omega) about the origin:
    [[m I, -m hat(r)], [m hat(r), -m hat(r)^2]] (kinetic energy 1/2 m |v + omega x r|^2)."""
    x, y, z = (float(v) for v in r)
    H = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    out = np.zeros((6, 6))
    out[:3, :3] = mass * np.eye(3)
    out[:3, 3:] = -mass * H
    out[3:, :3] = mass * H
    out[3:, 3:] = -mass * H @ H
    return out


def kirchhoff_terms(M: np.ndarray, nu: Sequence[float]) -> np.ndarray:
    """C(nu) nu = [omega x p; v x p + omega x h] with [p; h] = M nu (Fossen eq. 6.43); for a rigid body
    about its centre of mass, M = diag(m I, I) gives [m omega x v; omega x I omega]."""
    nu = np.asarray(nu, dtype=float)
    ph = M @ nu
    v, w, p, h = nu[:3], nu[3:], ph[:3], ph[3:]
    return np.concatenate((np.cross(w, p), np.cross(v, p) + np.cross(w, h)))
