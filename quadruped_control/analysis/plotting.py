"""Figures of attitude trials in the style of the paper's Fig. "sim" and "experiments".

Each figure has four stacked panels: roll, pitch and yaw against their setpoints (degrees), and the
geodesic error (angle of R_d^T R_B^W) raw and after the centred 3 s moving average of section
"Experiments". Euler angles are drawn as setpoint + wrapped error, so a yaw trace near +-180 degrees
does not jump. Uses matplotlib's non-interactive Agg backend (works headless); no pyplot state leaks.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Union

import numpy as np

from quadruped_control.analysis.metrics import SMOOTHING_WINDOW, axis_errors, moving_average_centered

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

AXIS_LABELS = ("roll", "pitch", "yaw")
_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")

__all__ = ["Trace", "plot_attitude", "plot_trials"]


class Trace:
    """One trial to draw: times ``t`` (N,) s, ``rpy`` (N, 3) rad, ``setpoint_rpy`` (3,) rad,
    ``geodesic`` (N,) rad and a legend ``label``."""

    def __init__(self, t: ArrayLike, rpy: ArrayLike, setpoint_rpy: ArrayLike, geodesic: ArrayLike,
                 label: str = "") -> None:
        self.t = np.asarray(t, dtype=float).reshape(-1)
        self.rpy = np.asarray(rpy, dtype=float)
        self.setpoint = np.asarray(setpoint_rpy, dtype=float).reshape(-1)
        self.geodesic = np.asarray(geodesic, dtype=float).reshape(-1)
        self.label = label
        if self.rpy.shape != (self.t.size, 3) or self.geodesic.shape != self.t.shape or self.setpoint.shape != (3,):
            raise ValueError("trace shapes do not match: t %s, rpy %s, setpoint %s, geodesic %s"
                             % (self.t.shape, self.rpy.shape, self.setpoint.shape, self.geodesic.shape))

    def continuous_rpy_deg(self) -> np.ndarray:
        """Euler angles as setpoint + continuous error, degrees (N, 3)."""
        return np.degrees(self.setpoint + axis_errors(self.rpy, self.setpoint))


def _figure(rows: int):
    from matplotlib.figure import Figure  # no pyplot: no global state, no display needed
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figure = Figure(figsize=(8.0, 9.0), dpi=110)
    FigureCanvasAgg(figure)
    axes = figure.subplots(rows, 1, sharex=True)
    return figure, axes


def plot_trials(traces: Sequence[Trace], path: str, title: Optional[str] = None,
                window: float = SMOOTHING_WINDOW) -> str:
    """Draw one or more trials into one figure (one colour per trial) and save it to ``path`` (PNG).

    Panels: roll, pitch, yaw (solid) with their setpoints (dashed, same colour); geodesic error raw
    (thin, faint) and smoothed with the centred ``window`` s moving average (thick). Returns ``path``.
    """
    if not traces:
        raise ValueError("nothing to plot: no traces")
    figure, axes = _figure(4)
    for index, trace in enumerate(traces):
        colour = _COLOURS[index % len(_COLOURS)]
        angles = trace.continuous_rpy_deg()
        for column in range(3):
            ax = axes[column]
            ax.plot(trace.t, angles[:, column], color=colour, linewidth=1.0, label=trace.label or None)
            ax.axhline(math.degrees(trace.setpoint[column]), color=colour, linestyle="--", linewidth=0.9)
        geodesic_deg = np.degrees(trace.geodesic)
        smooth = moving_average_centered(geodesic_deg, trace.t, window) if trace.t.size > 1 else geodesic_deg
        axes[3].plot(trace.t, geodesic_deg, color=colour, linewidth=0.6, alpha=0.35)
        axes[3].plot(trace.t, smooth, color=colour, linewidth=1.6,
                     label=("%s (%.0f s avg)" % (trace.label, window)) if trace.label else None)
    for column, name in enumerate(AXIS_LABELS):
        axes[column].set_ylabel("%s [deg]" % name)
        axes[column].grid(True, alpha=0.3)
    axes[3].axhline(6.0, color="grey", linestyle=":", linewidth=0.9)
    axes[3].set_ylabel("geodesic error [deg]")
    axes[3].set_xlabel("time [s]")
    axes[3].grid(True, alpha=0.3)
    axes[3].set_ylim(bottom=0.0)
    if any(trace.label for trace in traces):
        axes[0].legend(loc="lower right", fontsize=8)
        axes[3].legend(loc="upper right", fontsize=8)
    if title:
        axes[0].set_title(title)
    figure.tight_layout()
    figure.savefig(path)
    return path


def plot_attitude(t: ArrayLike, rpy: ArrayLike, setpoint_rpy: ArrayLike, geodesic: ArrayLike, path: str,
                  title: Optional[str] = None, window: float = SMOOTHING_WINDOW) -> str:
    """Figure of one trial (like the paper's experiment figures), saved to ``path``; returns ``path``."""
    return plot_trials([Trace(t, rpy, setpoint_rpy, geodesic)], path, title=title, window=window)
