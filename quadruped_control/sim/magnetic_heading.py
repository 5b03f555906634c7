"""The heading a tilt-compensating AHRS (the VN-100) reports when a residual magnetic field rides with the body.

Beyond the paper. The VN-100 takes its heading from its magnetometer: it levels the measured field with the
tilt it knows (accelerometers and gyros) and points its yaw at the field's horizontal part. A field that
rides with the body and is not calibrated out (the servos' motor magnets and currents, the battery, a
hard-iron calibration made level, which cannot see the vertical component) adds to the earth's, and the
reported heading turns away from the true one by an angle that depends on the attitude.

With R = Rz(psi) R_t (ZYX yaw psi, tilt R_t), the earth's field H (0, 1, -V/H) in world ENU (north is +y)
and a residual b in body axes (FLU) in units of the earth's horizontal field H, the levelled field in
the heading frame is Rz(psi)^T (0, H, -V) + R_t b H, so the AHRS reports

    psi_m = atan2(sin psi + c_x, cos psi + c_y),   (c_x, c_y) = Rz(-psi) (R b)_xy,

and the reported attitude is Rz(psi_m - psi) R: roll and pitch as true, the heading turned. Level, a
horizontal residual gives the classic one-cycle heading error; tilted, the vertical component enters in
proportion to the sine of the tilt. The vertical field V drops out (the tilt is assumed known), and so
does the filter: the error is taken as the magnetometer's steady answer, without the AHRS's lag.

Near pitch +-90 deg the heading is undefined and so is the error, as on the sensor.

The levelled residual (c_x, c_y) = (R_t b)_xy depends on the tilt only, so for a residual weaker than the
earth's horizontal field (|b| < 1) the heading the AHRS reports is a one-to-one function of the true one
at each tilt, and :func:`true_rotation` inverts it exactly: the true heading's unit vector is r u - c,
u = (sin psi_m, cos psi_m), with r > 0 the root of |r u - c| = 1. A study that starts a trial where Table 1
says the robot started (its IMU's theta_init and psi_init) starts the plant there.
"""
from __future__ import annotations

import numpy as np

from quadruped_common.so3 import atan2_elementwise

__all__ = ["heading_error", "reported_rotation", "true_rotation"]


def _levelled_residual(R: np.ndarray, b: np.ndarray):
    """(psi, cos psi, sin psi, c_x, c_y) of attitude(s) R (..., 3, 3): its heading and the residual b (..., 3)
    levelled into its heading frame, (c_x, c_y) = Rz(-psi) (R b)_xy = (R_t b)_xy (module docstring)."""
    # atan2_elementwise, not np.arctan2: numpy's SIMD arctan2 rounds a third of its results differently from
    # the C library's, and whether it runs depends on the stack's length and alignment, so one attitude
    # and a stack of them would not be reported alike (the batch and the per-trial engine disagreed by an ulp)
    psi = atan2_elementwise(R[..., 1, 0], R[..., 0, 0])
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    # (R b)_x and (R b)_y: the residual's horizontal part in the world frame. Written out element by
    # element so that one attitude and a stack of them round alike (the two engines agree to the bit).
    world_x = R[..., 0, 0] * b[..., 0] + R[..., 0, 1] * b[..., 1] + R[..., 0, 2] * b[..., 2]
    world_y = R[..., 1, 0] * b[..., 0] + R[..., 1, 1] * b[..., 1] + R[..., 1, 2] * b[..., 2]
    return psi, cos_psi, sin_psi, cos_psi * world_x + sin_psi * world_y, -sin_psi * world_x + cos_psi * world_y


def heading_error(R: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """psi_m - psi in (-pi, pi] (rad) of attitude(s) R (..., 3, 3) with the residual field(s) ``residual``
    (..., 3), body axes, in units of the earth's horizontal field (module docstring)."""
    psi, cos_psi, sin_psi, level_x, level_y = _levelled_residual(np.asarray(R, dtype=float),
                                                                 np.asarray(residual, dtype=float))
    reported = atan2_elementwise(sin_psi + level_x, cos_psi + level_y)
    return np.pi - np.mod(np.pi - (reported - psi), 2.0 * np.pi)


def _turned(R: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Rz(delta) R: rows 0 and 1 turned about the world vertical, row 2 (the tilt's) unchanged."""
    cos_d, sin_d = np.cos(delta), np.sin(delta)
    out = np.empty(R.shape)
    out[..., 0, :] = cos_d[..., None] * R[..., 0, :] - sin_d[..., None] * R[..., 1, :]
    out[..., 1, :] = sin_d[..., None] * R[..., 0, :] + cos_d[..., None] * R[..., 1, :]
    out[..., 2, :] = R[..., 2, :]
    return out


def reported_rotation(R: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Rz(psi_m - psi) R: the attitude(s) the AHRS reports for the true R (..., 3, 3) (:func:`heading_error`)."""
    R = np.asarray(R, dtype=float)
    return _turned(R, heading_error(R, residual))


def true_rotation(reported: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """The true attitude(s) whose :func:`reported_rotation` is ``reported`` (..., 3, 3), for residuals weaker
    than the earth's horizontal field (|b| < 1; ValueError otherwise, where a heading can have no true one)."""
    reported = np.asarray(reported, dtype=float)
    b = np.asarray(residual, dtype=float)
    if np.any(np.sum(b * b, axis=-1) >= 1.0):
        raise ValueError("a residual field at least the earth's horizontal field (|b| >= 1) leaves some "
                         "headings without a true one, got %r" % (residual,))
    # the reported attitude's levelled residual is the true one's: the tilt is the same
    psi_m, u_y, u_x, c_x, c_y = _levelled_residual(reported, b)
    along = u_x * c_x + u_y * c_y
    r = along + np.sqrt(along * along - (c_x * c_x + c_y * c_y) + 1.0)
    psi = atan2_elementwise(r * u_x - c_x, r * u_y - c_y)
    return _turned(reported, psi - psi_m)
