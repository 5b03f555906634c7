"""Is the IMU mounted as the configuration says? Gravity at the operator's "level" and two guided tilts.

On a stand, the VN-100's specific force is gravity's reaction, +g along the body's up axis when level
(REP-145). The operator holds the robot level (on a spirit level), then nose down, then right side down
(REP-103: positive pitch, positive roll), each by roughly :data:`GUIDED_TILT_DEG`. The rotation that best maps
the expected directions onto the measured ones (Kabsch) is the IMU's mount error as the stack sees it: its
tilt (how far the IMU's up axis is from the body's, measured at level: ``tolerance_deg``) and its heading
about the up axis (from the tilts' directions, as good as the operator's hold: ``heading_tolerance_deg``; a
hold within 3 deg of the named axis at 30 deg gives about 6 deg). A rotated mount or a wrong sign shows in
one or both. A tilt the readings do not show is an inconclusive check, never a pass.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.so3 import log_so3, rot_to_rpy, rpy_to_rot

__all__ = ["GUIDED_POSES", "GUIDED_TILT_DEG", "ImuMountResult", "check_imu_mount", "expected_specific_force",
           "stand_readings"]

GRAVITY = 9.81
#: About how far the operator tilts the robot for each guided pose (deg).
GUIDED_TILT_DEG = 30.0
#: The guided poses: name, what the operator does, (roll, pitch) sign of the tilt.
GUIDED_POSES: Tuple[Tuple[str, str, Tuple[float, float]], ...] = (
    ("level", "hold the robot level", (0.0, 0.0)),
    ("nose down", "tilt the nose down by about %.0f deg" % GUIDED_TILT_DEG, (0.0, 1.0)),
    ("right down", "tilt the right side down by about %.0f deg" % GUIDED_TILT_DEG, (1.0, 0.0)),
)


def expected_specific_force(roll: float, pitch: float) -> np.ndarray:
    """What a correctly mounted IMU reads on a still body at ``roll``, ``pitch`` (rad): R^T (0, 0, g)."""
    return rpy_to_rot(roll, pitch, 0.0).T @ np.array([0.0, 0.0, GRAVITY])


@dataclass
class ImuMountResult:
    """``passed``; the mount error's angle, tilt and heading (deg) and roll/pitch/yaw (deg) when measurable;
    the problems."""

    passed: bool
    error_deg: float = math.nan
    tilt_deg: float = math.nan
    heading_deg: float = math.nan
    error_rpy_deg: Tuple[float, float, float] = (math.nan, math.nan, math.nan)
    problems: List[str] = field(default_factory=list)


def _tilt(level: np.ndarray, tilted: np.ndarray) -> float:
    cos = float(np.dot(level, tilted) / (np.linalg.norm(level) * np.linalg.norm(tilted)))
    return math.acos(max(-1.0, min(1.0, cos)))


def check_imu_mount(readings: Sequence[Sequence[float]], tolerance_deg: float = 5.0,
                    heading_tolerance_deg: float = 12.0, min_tilt_deg: float = 15.0,
                    gravity_tolerance: float = 0.05) -> ImuMountResult:
    """Judge the specific forces (m/s^2, body axes as reported) read in the three :data:`GUIDED_POSES`."""
    f = np.asarray(readings, dtype=float)
    if f.shape != (len(GUIDED_POSES), 3) or not np.all(np.isfinite(f)):
        return ImuMountResult(False, problems=["need one finite specific force per guided pose, got %r"
                                               % (np.asarray(readings).tolist(),)])
    problems = []
    norms = np.linalg.norm(f, axis=1)
    if np.any(np.abs(norms / GRAVITY - 1.0) > gravity_tolerance):
        problems.append("gravity reads %s m/s^2 in the three poses, not %.2f: the robot moved, or the "
                        "accelerometer is off" % (np.round(norms, 2).tolist(), GRAVITY))
    expected = []
    for (name, _, (roll_sign, pitch_sign)), reading in zip(GUIDED_POSES, f):
        tilt = _tilt(f[0], reading)
        if (roll_sign or pitch_sign) and tilt < math.radians(min_tilt_deg):
            problems.append("the '%s' pose is only %.1f deg from level: tilt further and check again"
                            % (name, math.degrees(tilt)))
        expected.append(expected_specific_force(roll_sign * tilt, pitch_sign * tilt))
    if problems:
        return ImuMountResult(False, problems=problems)
    # Kabsch: the rotation Q with measured ~ Q expected, i.e. the mount's R_m^T
    u, _, vt = np.linalg.svd(f.T @ np.array(expected))
    d = np.sign(np.linalg.det(u @ vt))
    q = u @ np.diag([1.0, 1.0, d]) @ vt
    mount = q.T
    angle = math.degrees(float(np.linalg.norm(log_so3(mount))))
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(mount[2, 2])))))
    # heading: the rotation about the up axis left once the tilt is taken out
    heading = math.degrees(math.atan2(mount[1, 0] - mount[0, 1], mount[0, 0] + mount[1, 1]))
    rpy = tuple(round(math.degrees(v), 1) for v in rot_to_rpy(mount))
    result = ImuMountResult(tilt <= tolerance_deg and abs(heading) <= heading_tolerance_deg, angle, tilt, heading,
                            (rpy[0], rpy[1], rpy[2]))
    if not result.passed:
        result.problems.append("the IMU's axes are %.0f deg from the body's (its up axis %.0f deg off, heading %+.0f "
                               "deg; mount roll, pitch, yaw %s deg): remount it as docs/on_the_robot.md shows, or "
                               "set the VN-100's reference frame rotation (register 26) to undo it"
                               % (angle, tilt, heading, list(rpy)))
    return result


def stand_readings(mount_rpy_deg: Sequence[float], tilt_deg: float = GUIDED_TILT_DEG,
                   noise: float = 0.0, rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """The readings of :data:`GUIDED_POSES` from an IMU mounted rotated by ``mount_rpy_deg`` (tests, studies)."""
    mount = rpy_to_rot(*np.radians(mount_rpy_deg))
    rows = []
    for _, _, (roll_sign, pitch_sign) in GUIDED_POSES:
        tilt = math.radians(tilt_deg)
        f = mount.T @ expected_specific_force(roll_sign * tilt, pitch_sign * tilt)
        rows.append(f + (rng.normal(0.0, noise, 3) if rng is not None and noise > 0 else 0.0))
    return np.array(rows)
