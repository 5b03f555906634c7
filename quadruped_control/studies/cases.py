"""Trial cases of the stroke-scheme study, as plain records (no ROS, pure).

- :func:`paper_sim_cases`: section "Simulation Validation": 15, 45 and 75 degrees on roll, pitch and yaw at
  once, from level.
- :func:`table1_cases`: the 15 experiments of Table 1 (section "Experiments") exactly as the
  paper-experiments study defines them (:mod:`quadruped_control.studies.paper_experiments`: setpoints,
  initial attitudes reconstructed from theta_init and psi_init, t_rec, 180 s).
- :func:`random_cases`: seeded random setpoint / initial-attitude pairs (documented in the docstring).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

__all__ = ["Case", "paper_sim_cases", "random_cases", "table1_cases"]


@dataclass(frozen=True)
class Case:
    """One trial case: setpoint and initial attitude (roll, pitch, yaw in degrees), length, optional t_rec."""

    name: str
    setpoint_rpy_deg: Tuple[float, float, float]
    initial_rpy_deg: Tuple[float, float, float]
    duration: float
    t_rec: Optional[float] = None
    group: str = ""


def paper_sim_cases(duration: float = 120.0) -> List[Case]:
    return [Case("sim %g" % a, (a, a, a), (0.0, 0.0, 0.0), duration, group="paper-sim") for a in (15.0, 45.0, 75.0)]


def table1_cases() -> List[Case]:
    """The 15 experiments of Table 1 as defined by :mod:`quadruped_control.studies.paper_experiments`
    (its table, setpoints, reconstructed initial attitudes, t_rec and trial length)."""
    from quadruped_control.studies.paper_experiments import DURATION, PAPER_TABLE, case_label, initial_attitude, \
        setpoint_rpy_deg

    cases = []
    for row in PAPER_TABLE:
        setpoint = setpoint_rpy_deg(row)
        initial, _ = initial_attitude(setpoint, row["theta_init"], row["psi_init"])
        cases.append(Case("T1 " + case_label(row), setpoint, tuple(float(v) for v in initial), DURATION,
                          float(row["t_rec"]), group="table1"))
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
