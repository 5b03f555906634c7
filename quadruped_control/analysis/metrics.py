"""Regulation metrics of the paper's "Experiments" section, on smoothed signals (pure numpy).

The paper (section "Experiments", Table "Regulation performance") smooths every signal with a centred
3 s moving average, "so the metrics reflect the average orientation that the robot sustains across
stroke cycles", and reports:

- ``theta_init``: initial geodesic error arccos((tr(R_d^T R_B^W) - 1) / 2) at t = 0 (raw, not smoothed);
- per axis (roll, pitch, yaw):
  - rise time ``t_r``: from 10 % to 90 % of the way from the initial value to the setpoint;
  - settling time ``t_s``: the earliest instant after which the error stays within +-6 degrees for at
    least 30 s (``None`` if there is no such instant);
  - steady-state error ``e_ss``: mean error (angle - setpoint) over the last 10 % of the trial;
  - overshoot ``M_p``: largest excursion beyond the setpoint, in percent of the commanded change.

Decisions (the paper does not spell these out):

- Euler angles wrap at +-180 degrees. Each axis is handled as its error to the setpoint, wrapped into
  [-180, 180) and then unwrapped in time, so a yaw trace crossing +-180 degrees is continuous (and
  averages correctly) and the error is the short way round at t = 0. The smoothed error is wrapped
  back into [-180, 180): a robot that turned a full revolution is at its setpoint.
- The initial value of an axis is the raw (unsmoothed) value at t = 0, the initial condition of the
  trial; the centred average at t = 0 would already contain 1.5 s of motion.
- Near the ends of the record the centred window is truncated to the samples that exist (no padding),
  so the smoothed signal is defined (finite) everywhere.
- Signals with non-uniform timestamps (bags) are first resampled by linear interpolation onto a uniform
  grid at the median sample interval; the window then holds the same number of samples everywhere.
- Crossing instants (10 %, 90 %, entering the +-6 degree band) are linearly interpolated between samples.
- An axis whose commanded change is below :data:`MIN_CHANGE_DEG` has no rise time and no overshoot
  (``None``): percentages of a zero change are undefined.

All outputs are plain Python floats, bools or ``None`` (JSON-ready) and never NaN.
"""
from __future__ import annotations

import math
from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np

from quadruped_common.so3 import wrap_angle

ArrayLike = Union[Sequence[float], Sequence[Sequence[float]], np.ndarray]

#: Width of the centred moving average, s (paper, section "Experiments").
SMOOTHING_WINDOW = 3.0
#: Half-width of the settling band, degrees.
SETTLING_BAND_DEG = 6.0
#: How long the error has to stay in the band, s.
SETTLING_HOLD = 30.0
#: Fraction of the trial (at its end) averaged for the steady-state error.
STEADY_STATE_FRACTION = 0.1
#: Rise-time thresholds, fractions of the commanded change.
RISE_LOW, RISE_HIGH = 0.1, 0.9
#: Commanded changes smaller than this (degrees) have no rise time or overshoot.
MIN_CHANGE_DEG = 0.01
#: Relative spread of the sample intervals above which timestamps count as non-uniform.
UNIFORM_TOL = 1e-6

AXES = ("roll", "pitch", "yaw")

__all__ = [
    "AXES",
    "SETTLING_BAND_DEG",
    "SETTLING_HOLD",
    "SMOOTHING_WINDOW",
    "axis_errors",
    "compute_metrics",
    "moving_average_centered",
    "resample_uniform",
    "settling_time",
]


def _time_vector(t: ArrayLike) -> np.ndarray:
    times = np.asarray(t, dtype=float)
    if times.ndim != 1 or times.size < 2:
        raise ValueError("t must be a 1-D array of at least 2 timestamps, got shape %s" % (times.shape,))
    if not np.all(np.isfinite(times)):
        raise ValueError("t has non-finite timestamps")
    if np.any(np.diff(times) <= 0.0):
        raise ValueError("t must be strictly increasing")
    return times


def _is_uniform(t: np.ndarray) -> bool:
    steps = np.diff(t)
    median = float(np.median(steps))
    return bool(np.max(np.abs(steps - median)) <= UNIFORM_TOL * max(median, 1e-300) + 1e-12)


def resample_uniform(t: ArrayLike, x: ArrayLike, dt: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of ``x`` (N,) or (N, k) at times ``t`` onto a uniform grid from t[0].

    ``dt`` defaults to the median sample interval. The grid ends at the last grid point <= t[-1].
    Continuous signals only: unwrap angles first. Returns (t_uniform, x_uniform).
    """
    times = _time_vector(t)
    values = np.asarray(x, dtype=float)
    if values.shape[0] != times.size:
        raise ValueError("x has %d samples but t has %d" % (values.shape[0], times.size))
    step = float(np.median(np.diff(times))) if dt is None else float(dt)
    if not (math.isfinite(step) and step > 0.0):
        raise ValueError("dt must be a positive finite number, got %r" % (dt,))
    count = int(math.floor((times[-1] - times[0]) / step * (1.0 + 1e-12))) + 1
    grid = times[0] + step * np.arange(count)
    if values.ndim == 1:
        return grid, np.interp(grid, times, values)
    out = np.empty((count,) + values.shape[1:])
    flat = values.reshape(values.shape[0], -1)
    out_flat = out.reshape(count, -1)
    for column in range(flat.shape[1]):
        out_flat[:, column] = np.interp(grid, times, flat[:, column])
    return grid, out


def moving_average_centered(x: ArrayLike, t: ArrayLike, window: float = SMOOTHING_WINDOW) -> np.ndarray:
    """Centred moving average over ``window`` seconds: mean of the samples with |t_j - t_i| <= window/2.

    ``x``: (N,) or (N, k) samples at the strictly increasing times ``t`` (N,). At the edges of the
    record the window is truncated to the samples that exist. For uniform sampling this is the usual
    centred boxcar of round(window / dt) + 1 samples (odd). Non-uniformly sampled signals should be
    resampled first (:func:`resample_uniform`; :func:`compute_metrics` does); here every sample has
    equal weight. Returns an array of the shape of ``x``; NaN-free for finite input.
    """
    times = _time_vector(t)
    values = np.asarray(x, dtype=float)
    if values.shape[0] != times.size:
        raise ValueError("x has %d samples but t has %d" % (values.shape[0], times.size))
    if not np.all(np.isfinite(values)):
        raise ValueError("x has non-finite samples")
    if not (math.isfinite(window) and window >= 0.0):
        raise ValueError("window must be a non-negative number of seconds, got %r" % (window,))
    half = 0.5 * window
    # Slack for timestamps that are multiples of dt in floating point (t_i +- half hits a sample).
    slack = 1e-9 * max(1.0, float(np.max(np.abs(times))))
    lo = np.searchsorted(times, times - half - slack, side="left")
    hi = np.searchsorted(times, times + half + slack, side="right")
    cumulative = np.concatenate((np.zeros((1,) + values.shape[1:]), np.cumsum(values, axis=0)), axis=0)
    counts = (hi - lo).astype(float)
    if values.ndim > 1:
        counts = counts.reshape((-1,) + (1,) * (values.ndim - 1))
    return (cumulative[hi] - cumulative[lo]) / counts


def axis_errors(rpy: ArrayLike, setpoint_rpy: ArrayLike) -> np.ndarray:
    """Per-axis errors angle - setpoint (rad), (N, 3): wrapped into [-pi, pi) at t = 0, then continuous.

    Each column is the wrapped difference unwrapped along time, so a yaw trace crossing +-180 degrees
    gives a continuous error.
    """
    angles = np.asarray(rpy, dtype=float)
    setpoint = np.asarray(setpoint_rpy, dtype=float).reshape(-1)
    if angles.ndim != 2 or angles.shape[1] != 3:
        raise ValueError("rpy must have shape (N, 3), got %s" % (angles.shape,))
    if setpoint.shape != (3,):
        raise ValueError("setpoint_rpy must have 3 elements, got shape %s" % (setpoint.shape,))
    return np.unwrap(wrap_angle(angles - setpoint), axis=0)


def _crossing_time(t: np.ndarray, y: np.ndarray, level: float) -> Optional[float]:
    """First time at which ``y`` reaches ``level`` from below (linear interpolation); None if never."""
    above = np.nonzero(y >= level)[0]
    if above.size == 0:
        return None
    k = int(above[0])
    if k == 0:
        return float(t[0])
    y0, y1 = float(y[k - 1]), float(y[k])
    fraction = (level - y0) / (y1 - y0) if y1 != y0 else 1.0
    return float(t[k - 1] + fraction * (t[k] - t[k - 1]))


def settling_time(t: ArrayLike, error: ArrayLike, band: float, hold: float = SETTLING_HOLD) -> Optional[float]:
    """Earliest instant after which |error| <= band for at least ``hold`` seconds, or None.

    Runs of in-band samples are measured from the interpolated entry into the band (or t[0]) to the
    interpolated exit (or the last sample). Units of ``error`` and ``band`` must match.
    """
    times = _time_vector(t)
    e = np.abs(np.asarray(error, dtype=float))
    inside = e <= band
    if not np.any(inside):
        return None
    # Start and end indices of runs of True.
    edges = np.diff(np.concatenate(([0], inside.astype(np.int8), [0])))
    starts = np.nonzero(edges == 1)[0]
    ends = np.nonzero(edges == -1)[0] - 1  # inclusive
    tol = 1e-9 * max(1.0, hold)
    for start, end in zip(starts.tolist(), ends.tolist()):
        if start == 0:
            entry = float(times[0])
        else:
            e0, e1 = float(e[start - 1]), float(e[start])
            entry = float(times[start - 1] + (e0 - band) / (e0 - e1) * (times[start] - times[start - 1]))
        if end == times.size - 1:
            leave = float(times[-1])
        else:
            e0, e1 = float(e[end]), float(e[end + 1])
            leave = float(times[end] + (band - e0) / (e1 - e0) * (times[end + 1] - times[end]))
        if leave - entry >= hold - tol:
            return entry - float(times[0])
    return None


def _axis_metrics(t: np.ndarray, error_raw: np.ndarray, error_smooth: np.ndarray) -> Dict[str, Optional[float]]:
    """t_r, t_s (s), e_ss (deg), M_p (%) of one axis from its raw and smoothed errors (rad)."""
    t0 = float(t[0])
    e_init = float(error_raw[0])            # initial value - setpoint
    change = -e_init                        # setpoint - initial value: the commanded change
    # Steady state: mean over the last 10 % of the trial (by time).
    tail = t >= t[-1] - STEADY_STATE_FRACTION * (t[-1] - t0) - 1e-12
    e_ss = math.degrees(float(np.mean(error_smooth[tail])))
    t_s = settling_time(t, error_smooth, math.radians(SETTLING_BAND_DEG), SETTLING_HOLD)
    t_r: Optional[float] = None
    m_p: Optional[float] = None
    if abs(math.degrees(change)) >= MIN_CHANGE_DEG:
        progress = 1.0 + error_smooth / change   # (y - y0) / (y_d - y0), 1 at the setpoint
        low = _crossing_time(t, progress, RISE_LOW)
        high = _crossing_time(t, progress, RISE_HIGH)
        if low is not None and high is not None and high >= low:
            t_r = high - low
        m_p = max(0.0, 100.0 * (float(np.max(progress)) - 1.0))
    return {"t_r": t_r, "t_s": t_s, "e_ss": e_ss, "M_p": m_p,
            "initial_deg": None, "setpoint_deg": None, "change_deg": math.degrees(change)}


def compute_metrics(t: ArrayLike, rpy: ArrayLike, setpoint_rpy: ArrayLike, geodesic: ArrayLike,
                    window: float = SMOOTHING_WINDOW) -> Dict[str, Any]:
    """The paper's regulation metrics (section "Experiments") of one trial.

    ``t`` (N,) s, strictly increasing, uniform or not; ``rpy`` (N, 3) roll, pitch, yaw in rad;
    ``setpoint_rpy`` (3,) rad; ``geodesic`` (N,) geodesic error in rad. Rows with a non-finite value
    are dropped (counted in ``samples_dropped``). Returns a JSON-ready dict::

        {"roll": {"t_r", "t_s", "e_ss", "M_p", "initial_deg", "setpoint_deg", "change_deg"},
         "pitch": {...}, "yaw": {...},
         "theta_init_deg", "settled", "geodesic": {"final_smoothed_deg", "max_smoothed_last_30s_deg",
         "t_s"}, "duration", "samples", "samples_dropped", "resampled", "window"}

    Times in s, angles in degrees, M_p in percent, ``None`` where undefined. ``settled`` is true when
    the smoothed geodesic error stays within 6 degrees over the last 30 s (false for shorter trials).
    """
    times = np.asarray(t, dtype=float).reshape(-1)
    angles = np.asarray(rpy, dtype=float)
    theta = np.asarray(geodesic, dtype=float).reshape(-1)
    setpoint = np.asarray(setpoint_rpy, dtype=float).reshape(-1)
    if angles.ndim != 2 or angles.shape[1] != 3:
        raise ValueError("rpy must have shape (N, 3), got %s" % (angles.shape,))
    if not (times.size == angles.shape[0] == theta.size):
        raise ValueError("t, rpy and geodesic must have the same number of samples, got %d, %d, %d"
                         % (times.size, angles.shape[0], theta.size))
    if setpoint.shape != (3,) or not np.all(np.isfinite(setpoint)):
        raise ValueError("setpoint_rpy must be 3 finite angles, got %r" % (setpoint_rpy,))
    keep = np.isfinite(times) & np.all(np.isfinite(angles), axis=1) & np.isfinite(theta)
    dropped = int(times.size - np.count_nonzero(keep))
    times, angles, theta = times[keep], angles[keep], theta[keep]
    if times.size < 2:
        raise ValueError("need at least 2 finite samples to compute metrics, got %d" % times.size)
    order = np.argsort(times, kind="stable")
    times, angles, theta = times[order], angles[order], theta[order]
    unique = np.concatenate(([True], np.diff(times) > 0.0))  # drop duplicate timestamps
    dropped += int(np.count_nonzero(~unique))
    times, angles, theta = times[unique], angles[unique], theta[unique]
    if times.size < 2:
        raise ValueError("need at least 2 distinct timestamps to compute metrics")

    errors = axis_errors(angles, setpoint)   # continuous, so interpolation across +-pi is safe
    resampled = not _is_uniform(times)
    if resampled:
        grid, stacked = resample_uniform(times, np.column_stack((errors, theta)))
        times, errors, theta = grid, stacked[:, :3], stacked[:, 3]
    # Smooth the continuous errors, then wrap back: after a full turn the robot is at its setpoint.
    smooth_errors = np.asarray(wrap_angle(moving_average_centered(errors, times, window)))
    smooth_theta = moving_average_centered(theta, times, window)

    out: Dict[str, Any] = {}
    for column, axis in enumerate(AXES):
        metrics = _axis_metrics(times, errors[:, column], smooth_errors[:, column])
        metrics["setpoint_deg"] = math.degrees(float(setpoint[column]))
        metrics["initial_deg"] = math.degrees(float(setpoint[column] + errors[0, column]))
        out[axis] = metrics
    duration = float(times[-1] - times[0])
    last = times >= times[-1] - SETTLING_HOLD - 1e-9
    max_last = math.degrees(float(np.max(smooth_theta[last])))
    out["theta_init_deg"] = math.degrees(float(theta[0]))
    out["settled"] = bool(duration >= SETTLING_HOLD - 1e-9 and max_last <= SETTLING_BAND_DEG)
    out["geodesic"] = {
        "final_smoothed_deg": math.degrees(float(smooth_theta[-1])),
        "max_smoothed_last_30s_deg": max_last,
        "mean_smoothed_last_10pct_deg": math.degrees(float(np.mean(
            smooth_theta[times >= times[-1] - STEADY_STATE_FRACTION * duration - 1e-12]))),
        "t_s": settling_time(times, smooth_theta, math.radians(SETTLING_BAND_DEG), SETTLING_HOLD),
    }
    out["duration"] = duration
    out["samples"] = int(times.size)
    out["samples_dropped"] = dropped
    out["resampled"] = resampled
    out["window"] = float(window)
    return out
