"""Trial cases taken from the paper, in one place for every study (no ROS, pure).

- :func:`paper_sim_cases`: section "Simulation Validation": 15, 45 and 75 degrees on roll, pitch and yaw at
  once, from level.
- :func:`table1_cases`: the 15 experiments of Table 1 (section "Experiments"): roll 15..90 and pitch 15..90
  in 15 degree steps, coupled roll + pitch 30/45/60; yaw reference 0; t_rec = 1.0 s for pitch 75, 90 and the
  coupled 60 (sections "Pitch Regulation", "Coupled Roll and Pitch Regulation"). The table gives only the
  initial geodesic error theta_init and the initial yaw psi_init; the initial attitude is reconstructed as
  R0 = Rz(psi_init) R_axis(a) with the commanded axis (roll: Rx(a); pitch: Ry(a); coupled: Ry(a) Rx(a))
  and the angle a in [-180, 180] degrees (0.05 degree grid) whose geodesic distance to the setpoint is
  closest to theta_init (the smallest |a| among equals). Each case records the reconstructed theta_init.
- :func:`random_cases`: seeded random setpoint / initial-attitude pairs (documented in the docstring).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from quadruped_control.so3 import geodesic_angle, rot_to_rpy, rpy_to_rot

__all__ = ["Case", "TABLE1", "paper_sim_cases", "random_cases", "table1_cases"]


@dataclass(frozen=True)
class Case:
    """One trial case: setpoint and initial attitude (roll, pitch, yaw in degrees), length, optional t_rec."""

    name: str
    setpoint_rpy_deg: Tuple[float, float, float]
    initial_rpy_deg: Tuple[float, float, float]
    duration: float
    t_rec: Optional[float] = None
    group: str = ""


#: Table 1: (set, commanded angle deg, theta_init deg, psi_init deg, t_rec s or None).
TABLE1: Tuple[Tuple[str, float, float, float, Optional[float]], ...] = (
    ("roll", 15.0, 80.89, -78.02, None), ("roll", 30.0, 50.86, -35.49, None),
    ("roll", 45.0, 132.86, 121.83, None), ("roll", 60.0, 84.54, 71.15, None),
    ("roll", 75.0, 115.21, 82.91, None), ("roll", 90.0, 158.31, 123.32, None),
    ("pitch", 15.0, 9.35, 1.54, None), ("pitch", 30.0, 64.58, 61.38, None),
    ("pitch", 45.0, 64.68, 56.76, None), ("pitch", 60.0, 79.15, -54.06, None),
    ("pitch", 75.0, 77.72, -43.40, 1.0), ("pitch", 90.0, 76.97, 58.46, 1.0),
    ("roll+pitch", 30.0, 19.59, -0.54, None), ("roll+pitch", 45.0, 51.01, -57.54, None),
    ("roll+pitch", 60.0, 45.96, -38.35, 1.0),
)


def paper_sim_cases(duration: float = 120.0) -> List[Case]:
    return [Case("sim %g" % a, (a, a, a), (0.0, 0.0, 0.0), duration, group="paper-sim") for a in (15.0, 45.0, 75.0)]


def _axis_rotation(kind: str, angle: float) -> np.ndarray:
    if kind == "roll":
        return rpy_to_rot(angle, 0.0, 0.0)
    if kind == "pitch":
        return rpy_to_rot(0.0, angle, 0.0)
    return rpy_to_rot(0.0, angle, 0.0) @ rpy_to_rot(angle, 0.0, 0.0)


def _setpoint(kind: str, command: float) -> Tuple[float, float, float]:
    return {"roll": (command, 0.0, 0.0), "pitch": (0.0, command, 0.0)}.get(kind, (command, command, 0.0))


def table1_cases(duration: float = 180.0) -> List[Case]:
    """The 15 experiments of Table 1 with reconstructed initial attitudes (module docstring)."""
    cases = []
    grid = np.radians(np.arange(-180.0, 180.0 + 1e-9, 0.05))
    for kind, command, theta_init, psi_init, t_rec in TABLE1:
        setpoint = _setpoint(kind, command)
        R_d = rpy_to_rot(*np.radians(setpoint))
        yaw = rpy_to_rot(0.0, 0.0, math.radians(psi_init))
        errors = np.array([abs(math.degrees(geodesic_angle(R_d, yaw @ _axis_rotation(kind, a))) - theta_init)
                           for a in grid])
        best = float(np.min(errors))
        candidates = grid[errors <= best + 1e-9]
        angle = float(candidates[np.argmin(np.abs(candidates))])
        initial = tuple(float(v) for v in np.degrees(rot_to_rpy(yaw @ _axis_rotation(kind, angle))))
        cases.append(Case("T1 %s %g" % (kind, command), setpoint, initial, duration, t_rec, group="table1"))
    return cases


def random_cases(count: int = 20, seed: int = 2026, duration: float = 120.0) -> List[Case]:
    """``count`` random cases from numpy's default_rng(seed): setpoint roll, pitch uniform in [-60, 60] deg,
    yaw in [-180, 180]; initial roll, pitch in [-45, 45], yaw in [-180, 180] (drawn in that order per case)."""
    rng = np.random.default_rng(seed)
    cases = []
    for index in range(count):
        setpoint = (float(rng.uniform(-60, 60)), float(rng.uniform(-60, 60)), float(rng.uniform(-180, 180)))
        initial = (float(rng.uniform(-45, 45)), float(rng.uniform(-45, 45)), float(rng.uniform(-180, 180)))
        cases.append(Case("rand %02d" % index, setpoint, initial, duration, group="random"))
    return cases
