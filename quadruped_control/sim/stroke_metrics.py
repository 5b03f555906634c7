"""How much of the commanded torque the strokes deliver, accumulated sample by sample for N trials.

The stroke-scheme comparison judges a scheme by the torque its paws deliver, eq. (torque_leg) from the
simulated joints (:func:`~quadruped_control.control.allocation.estimate_body_torque`), against the
commanded tau_sat, and by how often some pair is in its power stroke. :class:`StrokeTorqueMetrics` takes
the samples in time order, so the batched engine needs no joint history, and the per-trial engine feeds
it its recorded arrays (:func:`quadruped_control.studies.trial.stroke_metrics`): one computation for both.

Per trial, over every ``every``-th interior sample k = 1, 1 + every, ... (the first and last samples have
no centred difference):

- joint rates by the centred difference of np.gradient on a non-uniform grid (second order),
- ``torque_commanded_mean``: mean |tau_sat|,
- ``torque_ratio``: mean delivered component along tau_sat over mean |tau_sat|,
- ``torque_sideways``: mean delivered component across tau_sat over mean |tau_sat|,
- ``power_fraction``: fraction of all samples with some pair in power.

A sample whose joints or state are not finite (a failed trial) makes that trial's figures NaN.
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional

import numpy as np

from quadruped_control.control.allocation import estimate_body_torque
from quadruped_control.model.params import RobotParams

__all__ = ["StrokeTorqueMetrics"]


class StrokeTorqueMetrics:
    """Accumulates the stroke metrics of ``n`` trials (module docstring); :meth:`add` every sample in
    time order, then :meth:`result`."""

    def __init__(self, robot: RobotParams, n: int, every: int = 5) -> None:
        if n < 1 or every < 1:
            raise ValueError("need n >= 1 trials and every >= 1, got %r, %r" % (n, every))
        self.robot = robot
        self.n = int(n)
        self.every = int(every)
        self.samples = 0
        self.power_samples = np.zeros(self.n)
        self._along = np.zeros(self.n)
        self._across = np.zeros(self.n)
        self._commanded = np.zeros(self.n)
        self._terms = 0
        self._invalid = np.zeros(self.n, dtype=bool)
        # the two samples before the newest: (t, q) of k - 2; (t, q, R, omega, tau_sat) of k - 1
        self._older: Optional[tuple] = None
        self._previous: Optional[tuple] = None

    def add(self, t: float, q: np.ndarray, R: np.ndarray, omega: np.ndarray, tau_sat: np.ndarray,
            power: np.ndarray) -> None:
        """Sample k at time ``t``: joint angles ``q`` (N, 12), R (N, 3, 3), omega (N, 3), the controller's
        tau_sat (N, 3) and whether some pair is in power (N,) at that sample. The arrays are copied."""
        k = self.samples
        current = (float(t), np.array(q, dtype=float).reshape(self.n, 12), np.array(R, dtype=float).reshape(self.n, 3, 3),
                   np.array(omega, dtype=float).reshape(self.n, 3), np.array(tau_sat, dtype=float).reshape(self.n, 3))
        self.power_samples += np.asarray(power, dtype=bool).reshape(self.n)
        middle = k - 1
        if middle >= 1 and (middle - 1) % self.every == 0:
            assert self._older is not None and self._previous is not None
            self._term(self._older, self._previous, current)
        self._older, self._previous = self._previous, current
        self.samples += 1

    def _term(self, before: tuple, here: tuple, after: tuple) -> None:
        """One sample's contribution: q_dot as np.gradient computes it at an interior point."""
        t0, q0 = before[0], before[1]
        t1, q1, R, omega, tau_sat = here
        t2, q2 = after[0], after[1]
        dx1, dx2 = t1 - t0, t2 - t1
        a = -dx2 / (dx1 * (dx1 + dx2))
        b = (dx2 - dx1) / (dx1 * dx2)
        c = dx1 / (dx2 * (dx1 + dx2))
        q_dot = a * q0 + b * q1 + c * q2
        self._terms += 1
        for i in range(self.n):
            norm = math.sqrt(float(tau_sat[i] @ tau_sat[i]))
            self._commanded[i] += norm
            try:
                delivered = estimate_body_torque(q1[i], q_dot[i], R[i], omega[i], self.robot)
            except ValueError:  # non-finite joints or state: a failed trial
                self._invalid[i] = True
                continue
            if norm > 1e-9:
                unit = tau_sat[i] / norm
                along = float(delivered @ unit)
                self._along[i] += along
                self._across[i] += float(np.linalg.norm(delivered - along * unit))

    def result(self, i: int) -> Dict[str, float]:
        """The figures of trial ``i`` (module docstring)."""
        terms = self._terms
        mean_cmd = float(self._commanded[i] / terms) if terms else 0.0
        out = {"torque_commanded_mean": mean_cmd,
               "torque_ratio": float(self._along[i] / terms / mean_cmd) if mean_cmd > 0 else 0.0,
               "torque_sideways": float(self._across[i] / terms / mean_cmd) if mean_cmd > 0 else 0.0,
               "power_fraction": float(self.power_samples[i] / self.samples) if self.samples else 0.0}
        if self._invalid[i]:
            out = {key: math.nan for key in out}
        return out

    def results(self) -> List[Dict[str, float]]:
        return [self.result(i) for i in range(self.n)]
