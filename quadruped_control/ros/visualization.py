"""Message-independent maths behind the rviz view of the robot (no ROS imports).

The URDF ``urdf/underwater_quadruped.urdf.xacro`` draws each five-bar as an open tree: motor 1 -> link a1
-> passive joint ``knee1`` -> link a3, and motor 2 -> link a2 -> passive joint ``knee2`` -> link a4 ->
paw. URDF cannot close the loop, so the passive angles are computed here from the actuated ones with
the paper's five-bar forward kinematics (eq. fk_EFG, fk_phi, fk_planar) and published together with
them; the drawn a3 tip then meets the paw exactly.

Knee angles are relative joint angles (child link direction minus parent link direction, wrapped to
(-pi, pi]): ``knee1`` is the angle of link a3 relative to link a1, the paper's theta4 of
eq. (ik_theta1245); ``knee2`` the angle of link a4 relative to link a2, the paper's theta5.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.robot import JOINT_NAMES, LEGS, joint_index
from quadruped_common.so3 import wrap_angle
from quadruped_control.model.kinematics import five_bar_fk
from quadruped_control.model.params import FiveBar, RobotParams

#: Passive URDF joints, per leg: knee1 (a1 -> a3, theta4) and knee2 (a2 -> a4, theta5).
PASSIVE_JOINT_NAMES: Tuple[str, ...] = tuple(
    "leg%d_%s" % (leg, knee) for leg in LEGS for knee in ("knee1", "knee2"))

#: Joints of the URDF that move: the 12 actuated joints (JOINT_NAMES order) followed by the 8 passive.
VISUAL_JOINT_NAMES: Tuple[str, ...] = JOINT_NAMES + PASSIVE_JOINT_NAMES

#: One colour per leg (RGBA), shared by the foot-target spheres so leg i's target is easy to find.
LEG_COLOURS: Dict[int, Tuple[float, float, float, float]] = {
    1: (0.90, 0.20, 0.20, 0.6),
    2: (0.20, 0.75, 0.25, 0.6),
    3: (0.20, 0.45, 0.95, 0.6),
    4: (0.95, 0.80, 0.15, 0.6),
}


#: Distance (m) from the singular configurations (links fully stretched or folded onto each other, where
#: the passive angles are undefined) inside which a five-bar pose is refused.
_CLOSURE_MARGIN = 1e-9


class VisualizationError(ValueError):
    """Input that cannot be drawn truthfully (missing joints, non-finite values, open five-bar)."""


def knee_angles(theta1: float, theta2: float, five_bar: FiveBar) -> Tuple[float, float]:
    """Passive angles (knee1, knee2) of the five-bar for actuated angles theta1, theta2 (rad).

    These are theta4 (link a3 relative to a1) and theta5 (link a4 relative to a2, phi - theta2) from
    the paper's closed-chain solution, eq. (fk_EFG), (fk_phi), (fk_planar), as computed by
    :func:`quadruped_control.model.kinematics.five_bar_fk`, wrapped to (-pi, pi].

    Raises:
        VisualizationError: the angles are not finite, or the linkage cannot close for them
            (E^2 + F^2 < G^2 in eq. fk_phi) or is singular (link tips B and D coincide).
    """
    if not (math.isfinite(theta1) and math.isfinite(theta2)):
        raise VisualizationError("five-bar angles must be finite, got theta1=%r theta2=%r" % (theta1, theta2))
    # The passive links a3, a4 must span the distance between the actuated link tips B (motor 1 side)
    # and D (motor 2 side), with a margin: near coinciding tips phi is numerically undefined, and a
    # drawing from rounding noise is worse than none.
    tip_distance = math.hypot(five_bar.c + five_bar.a2 * math.cos(theta2) - five_bar.a1 * math.cos(theta1),
                              five_bar.a2 * math.sin(theta2) - five_bar.a1 * math.sin(theta1))
    if not (abs(five_bar.a3 - five_bar.a4) + _CLOSURE_MARGIN < tip_distance
            < five_bar.a3 + five_bar.a4 - _CLOSURE_MARGIN):
        raise VisualizationError("five-bar does not close for theta1=%.4f theta2=%.4f rad (link tips %.4f m "
                                 "apart, passive links %.4f + %.4f m)"
                                 % (theta1, theta2, tip_distance, five_bar.a3, five_bar.a4))
    try:
        theta4, theta5 = five_bar_fk(theta1, theta2, five_bar)[3:5]
    except ValueError as exc:  # kinematics.UnreachableError
        raise VisualizationError("five-bar does not close for theta1=%.4f theta2=%.4f rad: %s"
                                 % (theta1, theta2, exc)) from exc
    if not (math.isfinite(theta4) and math.isfinite(theta5)):
        raise VisualizationError("five-bar does not close for theta1=%.4f theta2=%.4f rad" % (theta1, theta2))
    return wrap_angle(theta4), wrap_angle(theta5)


def visual_joint_state(names: Sequence[str], positions: Sequence[float],
                       params: RobotParams) -> Tuple[List[str], List[float]]:
    """Full joint state for robot_state_publisher: the 12 actuated angles plus the 8 passive knees.

    ``names``/``positions`` are a sensor_msgs/JointState's fields (any order; must contain all of
    :data:`JOINT_NAMES`, extra joints are passed through unchanged after ours). Returns names in
    :data:`VISUAL_JOINT_NAMES` order followed by the extra ones, and their positions.

    Raises:
        VisualizationError: lengths differ, a name repeats, an actuated joint is missing or not finite,
            or a leg's five-bar cannot close. Nothing is returned then: drawing a wrong pose is worse
            than keeping the last good one.
    """
    names = list(names)
    if len(names) != len(positions):
        raise VisualizationError("joint state has %d names but %d positions" % (len(names), len(positions)))
    if len(set(names)) != len(names):
        duplicates = sorted({name for name in names if names.count(name) > 1})
        raise VisualizationError("joint state repeats joints %s" % ", ".join(duplicates))
    by_name = dict(zip(names, (float(p) for p in positions)))
    missing = [name for name in JOINT_NAMES if name not in by_name]
    if missing:
        raise VisualizationError("joint state lacks actuated joints %s" % ", ".join(missing))
    actuated = [by_name[name] for name in JOINT_NAMES]
    bad = [name for name, value in zip(JOINT_NAMES, actuated) if not math.isfinite(value)]
    if bad:
        raise VisualizationError("joint state has non-finite positions for %s" % ", ".join(bad))

    knees: List[float] = []
    for leg in LEGS:
        theta1 = actuated[joint_index(leg, 1)]
        theta2 = actuated[joint_index(leg, 2)]
        try:
            knees.extend(knee_angles(theta1, theta2, params.five_bar))
        except VisualizationError as exc:
            raise VisualizationError("leg %d: %s" % (leg, exc)) from exc
    extra = [name for name in names if name not in VISUAL_JOINT_NAMES]
    return (list(VISUAL_JOINT_NAMES) + extra,
            actuated + knees + [by_name[name] for name in extra])


def unit_quaternion(xyzw: Sequence[float]) -> np.ndarray:
    """(x, y, z, w) normalised, rejecting values that are not a rotation.

    Raises:
        VisualizationError: not four finite numbers, or a norm too small to normalise (an all-zero
            quaternion is what an uninitialised message carries).
    """
    q = np.asarray(xyzw, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise VisualizationError("quaternion must be 4 finite numbers (x, y, z, w), got %r" % (xyzw,))
    norm = float(np.linalg.norm(q))
    if norm < 1e-6:
        raise VisualizationError("quaternion %r has (almost) zero norm: not a rotation" % (tuple(q),))
    return q / norm


def imu_orientation(xyzw: Sequence[float], orientation_covariance: Sequence[float]) -> Optional[np.ndarray]:
    """Body orientation from a sensor_msgs/Imu's fields, or None when the IMU gives none.

    REP-145: ``orientation_covariance[0] == -1`` means "no orientation estimate". Otherwise the
    quaternion (world ENU <- IMU frame, which is base_link here) is validated by :func:`unit_quaternion`.
    """
    if len(orientation_covariance) > 0 and orientation_covariance[0] == -1.0:
        return None
    return unit_quaternion(xyzw)


@dataclass(frozen=True)
class SphereMarker:
    """One foot-target sphere, independent of visualization_msgs: id = leg number."""

    leg: int
    position: Tuple[float, float, float]
    diameter: float
    rgba: Tuple[float, float, float, float]


def foot_target_spheres(points: Sequence[Sequence[float]], diameter: float) -> List[SphereMarker]:
    """Spheres for the controller's foot targets r_e,i^B (body frame, legs 1..4 in order).

    Raises:
        VisualizationError: not exactly one finite 3-D point per leg, or a non-positive diameter.
    """
    if not (math.isfinite(diameter) and diameter > 0.0):
        raise VisualizationError("marker diameter must be positive, got %r" % (diameter,))
    if len(points) != len(LEGS):
        raise VisualizationError("expected %d foot targets (legs 1..4), got %d" % (len(LEGS), len(points)))
    spheres = []
    for leg, point in zip(LEGS, points):
        xyz = tuple(float(v) for v in point)
        if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
            raise VisualizationError("foot target of leg %d must be 3 finite numbers, got %r" % (leg, point))
        spheres.append(SphereMarker(leg=leg, position=(xyz[0], xyz[1], xyz[2]), diameter=diameter,
                                    rgba=LEG_COLOURS[leg]))
    return spheres


class Throttle:
    """Lets an event through at most once per ``min_period`` seconds (rviz needs no 100 Hz markers).

    A clock that jumps backwards (simulated time reset, bag loop) re-arms the throttle instead of
    blocking until the old time comes back.
    """

    def __init__(self, min_period: float) -> None:
        if not (math.isfinite(min_period) and min_period >= 0.0):
            raise ValueError("min_period must be a non-negative number of seconds, got %r" % (min_period,))
        self.min_period = min_period
        self._last: Optional[float] = None

    def ready(self, now: float) -> bool:
        """True (and remember ``now``) when at least ``min_period`` passed since the last True."""
        if self._last is None or now < self._last or now - self._last >= self.min_period:
            self._last = now
            return True
        return False
