"""Reachability margins of candidate nominal foot positions (config/robot.yaml ``nominal_foot_leg``).

Run: ``.venv/bin/python benchmarks/bench_nominal_foot_margin.py [z1 z2 ...]`` (default z in -0.110,
-0.105, -0.100 m, x and y from robot.yaml). Prints, for each candidate and leg:

- the servo angles theta1..theta3 from :func:`quadruped_control.model.kinematics.joint_angles` (eq. ik_theta3,
  ik_theta1245) and their distance to the nearest end of ``joint_limits_deg``;
- the passive angles theta4, theta5 (distance from 0 / 180 deg: the five-bar's extended or folded
  singularities);
- the workspace margin along +-x, +-y, +-z of the leg frame: how far the foot can move from the
  nominal point in that direction before the IK fails (bisection on UnreachableError, resolution 0.1 mm,
  searched up to 0.2 m).

All legs share the leg-frame geometry (M_i mirrors the body frame), so the per-leg rows must agree;
they are printed to check that the mirroring introduces no asymmetry.
"""
from __future__ import annotations

import math
import os
import sys
from typing import Dict, List, Sequence, Tuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from quadruped_common.robot import LEGS
from quadruped_control.model.kinematics import UnreachableError, joint_angles_full  # noqa: E402
from quadruped_control.model.params import RobotParams, load_robot_params  # noqa: E402

SEARCH_MAX = 0.2    # m
RESOLUTION = 1e-4   # m


def _reachable(params: RobotParams, leg: int, p_leg: np.ndarray) -> bool:
    r_body = params.leg_origins[leg] + params.mirror[leg] @ p_leg
    try:
        joint_angles_full(r_body, leg, params)
    except UnreachableError:
        return False
    return True


def direction_margin(params: RobotParams, leg: int, p0: np.ndarray, direction: np.ndarray) -> float:
    """Largest step s (m, to RESOLUTION) with p0 + s' direction reachable for every s' in [0, s] sampled
    at 1 mm, refined by bisection at the first failure."""
    step = 1e-3
    s = 0.0
    while s + step <= SEARCH_MAX:
        if not _reachable(params, leg, p0 + (s + step) * direction):
            low, high = s, s + step
            while high - low > RESOLUTION:
                mid = 0.5 * (low + high)
                if _reachable(params, leg, p0 + mid * direction):
                    low = mid
                else:
                    high = mid
            return low
        s += step
    return SEARCH_MAX


def report(params: RobotParams, z: float) -> Dict[str, float]:
    p0 = np.array([params.nominal_foot_leg[0], params.nominal_foot_leg[1], z])
    limits = params.joint_limits
    ranges = [limits.theta1, limits.theta2, limits.theta3]
    print("nominal_foot_leg = [%.3f, %.3f, %.3f] m" % tuple(p0))
    worst: Dict[str, float] = {}
    for leg in LEGS:
        r_body = params.leg_origins[leg] + params.mirror[leg] @ p0
        q = joint_angles_full(r_body, leg, params)
        joint_margin = [min(q[j] - ranges[j][0], ranges[j][1] - q[j]) for j in range(3)]
        passive = [min(abs(q[j]), math.pi - abs(q[j])) for j in (3, 4)]
        margins = {}
        for name, axis, sign in (("+x", 0, 1), ("-x", 0, -1), ("+y", 1, 1), ("-y", 1, -1), ("+z", 2, 1), ("-z", 2, -1)):
            d = np.zeros(3)
            d[axis] = sign
            margins[name] = direction_margin(params, leg, p0, d)
        print("  leg %d: theta1..3 = %7.2f %7.2f %7.2f deg (margin to limits %5.1f %5.1f %5.1f deg), "
              "theta4 %6.1f theta5 %6.1f deg (from 0/180: %5.1f %5.1f deg)"
              % ((leg,) + tuple(math.degrees(v) for v in q[:3]) + tuple(math.degrees(v) for v in joint_margin)
                 + tuple(math.degrees(v) for v in q[3:]) + tuple(math.degrees(v) for v in passive)))
        print("         workspace margin [mm]: " + "  ".join("%s %5.1f" % (k, 1000 * v) for k, v in margins.items()))
        for k, v in margins.items():
            worst[k] = min(worst.get(k, math.inf), v)
        worst["joint"] = min(worst.get("joint", math.inf), math.degrees(min(joint_margin)))
        worst["passive"] = min(worst.get("passive", math.inf), math.degrees(min(passive)))
    return worst


def main(argv: Sequence[str]) -> int:
    params = load_robot_params()
    zs: List[float] = [float(v) for v in argv] if argv else [-0.110, -0.105, -0.100]
    print("joint limits [deg]: theta1 %s theta2 %s theta3 %s" % tuple(
        "[%.0f, %.0f]" % tuple(math.degrees(v) for v in r)
        for r in (params.joint_limits.theta1, params.joint_limits.theta2, params.joint_limits.theta3)))
    summary: List[Tuple[float, Dict[str, float]]] = []
    for z in zs:
        summary.append((z, report(params, z)))
        print()
    print("| z [m] | +x | -x | +y | -y | +z (up) | -z (down) [mm] | min joint margin [deg] | min passive from 0/180 [deg] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for z, w in summary:
        print("| %.3f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f |"
              % (z, 1000 * w["+x"], 1000 * w["-x"], 1000 * w["+y"], 1000 * w["-y"], 1000 * w["+z"],
                 1000 * w["-z"], w["joint"], w["passive"]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
