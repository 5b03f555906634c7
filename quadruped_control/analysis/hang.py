"""The robot hanging unpowered in its tank: a linear model of one tilt axis pushed by the tank, fitted to a
recorded attitude by maximum likelihood (pure numpy and scipy).

Why (docs/identification.md, "What the model misses, and why" and "What a hang tells"): the fits to the paper's
Table 1 leave the restoring torque on a knife edge (five of the eight shipped members push *away* from level
when held still), and a test tank pushes a body that has so little authority. Ten minutes of the robot
hanging with its legs still, recorded, measure both: how stiffly it is held about the attitude it hangs at,
and how hard and how slowly the tank pushes it.

Model, per tilt axis (roll or pitch about the mean hanging attitude), state x = (theta, omega, d):

    theta' = omega
    I omega' = -k theta - c omega + d                       (I: the body's rotational inertia, rigid + added)
               - k_r (theta - s)                            (with --tether: the tether's relaxing bend,
    s' = (theta - s) / tau_r                                 tank_dynamics' standard linear solid, s its
                                                             relaxed tilt)
    d' = -d / tau_d + sigma sqrt(2 / tau_d) w(t)            (the tank plant's disturbance, an Ornstein-Uhlenbeck
                                                             process of standard deviation sigma:
                                                             tank_dynamics.disturbance_update)
    y = theta + v,   v ~ N(0, r^2)                          (the IMU's attitude noise)

k is the restoring stiffness about the hanging attitude (N m/rad; the slope of the tank plant's restoring
torque, TankModel.restoring_torque), c the damping that holds for small slow motions (N m s/rad), sigma and
tau_d the tank.yaml's ``disturbance.disturbance_torque_std`` and ``.disturbance_correlation_time``. The record gives the spectrum of
theta, whose level and corners fix k / I, c / I, sigma / I and tau_d; I comes from the model
(:func:`fit_axis`'s ``inertia``), so a wrong I scales k, c and sigma alike and leaves tau_d.

Likelihood: the model discretised exactly on the record's grid (Van Loan's method); the Kalman filter's
innovations over each stretch of valid samples, from the model's stationary state, exact (time-varying)
until its covariance has converged and then those of the stationary filter (scipy's discrete algebraic
Riccati solver), run as a linear filter by scipy.signal.lfilter. Fitted in the logarithms of (k, c, sigma,
tau_d, r) by Nelder-Mead from several starts, then, with the tether, of all seven from that fit; 95 %
intervals from the curvature of the log-likelihood there (a parameter on a bound, or where the curvature is
not positive definite, gets none). The intervals are local: where the record leaves parameters trading
against each other (the tether's bend against a stiffer spring), a fit can beat the truth's likelihood
with its interval missing the truth (docs/identification.md, "What a hang tells"). Assumes a body that
hangs stably about its mean (k > 0); the caller refuses a record that tumbled.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["HANG_PARAMETERS", "TETHER_PARAMETERS", "HangFit", "HangModel", "discretize", "fit_axis",
           "log_likelihood", "spectral_density", "stationary_std", "valid_segments"]

#: The fitted parameters, in the order of the optimiser's vector (all fitted in logarithms).
HANG_PARAMETERS = ("stiffness", "damping", "torque_std", "correlation_time", "noise_std")
#: With the tether's relaxing bend (``tether=True``), these two follow.
TETHER_PARAMETERS = ("relaxing_stiffness", "relaxation_time")

#: The bounds of the search (of the parameters, not their logs): wide around a 5 L robot in a test tank, so
#: that a fit on a bound says the record asks for something the model's structure cannot give.
BOUNDS: Dict[str, Tuple[float, float]] = {
    "stiffness": (1e-6, 10.0),          # N m/rad: 1 uN m/rad to a body held by a stiff rod
    "damping": (1e-6, 10.0),            # N m s/rad
    "torque_std": (1e-7, 1.0),          # N m
    "correlation_time": (0.05, 1000.0),  # s
    "noise_std": (1e-6, 0.1),           # rad: 0.06 mdeg to 6 deg
    "relaxing_stiffness": (1e-5, 1.0),  # N m/rad: identify.PARAMETERS' tether bend is 0-0.5
    "relaxation_time": (0.1, 1000.0),   # s: tank.yaml's TIME_CONSTANT_RANGE starts at 0.1
}

#: The standard normal's 97.5 % quantile: a 95 % interval is +-1.96 standard deviations.
_Z95 = 1.959963984540054


@dataclasses.dataclass(frozen=True)
class HangModel:
    """One tilt axis of the hanging robot (module docstring's symbols; SI units, angles in rad)."""

    stiffness: float         # k, N m/rad
    damping: float           # c, N m s/rad
    torque_std: float        # sigma, N m
    correlation_time: float  # tau_d, s
    noise_std: float         # r, rad
    inertia: float           # I, kg m^2 (given, not fitted)
    relaxing_stiffness: float = 0.0  # k_r, N m/rad (0: no tether branch, three states)
    relaxation_time: float = 1.0     # tau_r, s

    @property
    def parameters(self) -> Tuple[str, ...]:
        """The parameters this model carries: :data:`HANG_PARAMETERS`, and the tether's with a tether."""
        return HANG_PARAMETERS + (TETHER_PARAMETERS if self.relaxing_stiffness > 0.0 else ())

    def values(self) -> Dict[str, float]:
        return {name: getattr(self, name) for name in self.parameters}


def _continuous(model: HangModel) -> Tuple[np.ndarray, np.ndarray]:
    """(A, G G^T) of x' = A x + G w for x = (theta, omega, d), and s with a tether."""
    inertia = model.inertia
    tether = model.relaxing_stiffness > 0.0
    n = 4 if tether else 3
    a = np.zeros((n, n))
    a[0, 1] = 1.0
    a[1, :3] = (-(model.stiffness + model.relaxing_stiffness) / inertia, -model.damping / inertia, 1.0 / inertia)
    a[2, 2] = -1.0 / model.correlation_time
    if tether:
        a[1, 3] = model.relaxing_stiffness / inertia
        a[3, 0], a[3, 3] = 1.0 / model.relaxation_time, -1.0 / model.relaxation_time
    noise = np.zeros((n, n))
    noise[2, 2] = 2.0 * model.torque_std ** 2 / model.correlation_time
    return a, noise


def discretize(model: HangModel, dt: float) -> Tuple[np.ndarray, np.ndarray]:
    """(Phi, Q): the state transition over ``dt`` and the covariance of the noise it gathers, exact for the
    linear model (Van Loan, "Computing integrals involving the matrix exponential", 1978)."""
    from scipy.linalg import expm

    a, noise = _continuous(model)
    n = a.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n], block[:n, n:], block[n:, n:] = -a, noise, a.T
    e = expm(block * dt)
    phi = e[n:, n:].T
    q = phi @ e[:n, n:]
    return phi, 0.5 * (q + q.T)


def stationary_std(model: HangModel) -> float:
    """The standard deviation of theta (rad) when the model hangs in its stationary state, without the
    measurement noise: from the continuous Lyapunov equation A P + P A^T + G G^T = 0."""
    from scipy.linalg import solve_continuous_lyapunov

    a, noise = _continuous(model)
    return math.sqrt(max(float(solve_continuous_lyapunov(a, -noise)[0, 0]), 0.0))


def spectral_density(model: HangModel, frequency_hz: np.ndarray) -> np.ndarray:
    """The one-sided power spectral density of theta (rad^2/Hz) at ``frequency_hz``: |H(i w)|^2 times the
    disturbance's 4 sigma^2 tau_d / (1 + (w tau_d)^2) (the transform of sigma^2 exp(-|t| / tau_d), one-sided),
    H(s) = 1 / (I s^2 + c s + k + k_r s tau_r / (1 + s tau_r)). Without the measurement noise, whose floor
    depends on the sampling (2 r^2 dt)."""
    w = 2.0 * math.pi * np.asarray(frequency_hz, dtype=float)
    tau = model.correlation_time
    torque = 4.0 * model.torque_std ** 2 * tau / (1.0 + (w * tau) ** 2)
    # the tether's Maxwell branch: k_r times the part of theta its relaxed tilt has not followed,
    # i w tau_r / (1 + i w tau_r)
    tether = model.relaxing_stiffness * (1j * w * model.relaxation_time) / (1.0 + 1j * w * model.relaxation_time)
    return torque / np.abs(model.stiffness + tether - model.inertia * w ** 2 + 1j * model.damping * w) ** 2


def valid_segments(y: np.ndarray, valid: Optional[np.ndarray] = None, min_length: int = 10) -> List[np.ndarray]:
    """The stretches of consecutive valid, finite samples of ``y`` at least ``min_length`` long."""
    y = np.asarray(y, dtype=float)
    good = np.isfinite(y) if valid is None else (np.asarray(valid, dtype=bool) & np.isfinite(y))
    edges = np.flatnonzero(np.diff(np.concatenate(([0], good.astype(int), [0]))))
    return [y[first:end] for first, end in zip(edges[::2], edges[1::2]) if end - first >= min_length]


#: The exact (time-varying) Kalman filter runs at most this many steps of a segment before the stationary
#: one takes over; it hands over as soon as its prediction covariance is within 1e-7 of the stationary one
#: (after 35-50 steps of 0.1 s over the range of hanging bodies tried).
_EXACT_STEPS = 400


def log_likelihood(model: HangModel, segments: Sequence[np.ndarray], dt: float) -> float:
    """The Gaussian log-likelihood of the zero-mean ``segments`` (rad, one sample per ``dt``) under
    ``model``, each segment starting from the model's stationary state: the Kalman filter's innovations,
    exact (time-varying) until its covariance has converged and then those of the stationary filter, run
    as a linear filter (scipy.signal.lfilter) from the state the exact one handed over. -inf where the
    model has no stationary state."""
    from scipy.linalg import LinAlgError, solve_discrete_are, solve_discrete_lyapunov
    from scipy.signal import lfilter, ss2tf

    phi, q = discretize(model, dt)
    n = phi.shape[0]
    h = np.eye(1, n)
    r = model.noise_std ** 2
    try:
        stationary = solve_discrete_lyapunov(phi, q)
        converged = solve_discrete_are(phi.T, h.T, q + 1e-30 * np.eye(n), np.array([[r]]))
    except (LinAlgError, ValueError):
        return -math.inf
    s_converged = float(converged[0, 0] + r)
    if not (np.all(np.isfinite(stationary)) and stationary[0, 0] > 0.0 and math.isfinite(s_converged)
            and s_converged > 0.0):
        return -math.inf
    gain = phi @ converged @ h.T / s_converged  # the stationary predictor's gain
    closed = phi - gain @ h
    num, den = ss2tf(closed, gain, -h, np.array([[1.0]]))  # y_k -> y_k - h x_k|k-1 from a zero state
    tolerance = 1e-7 * float(np.max(np.abs(converged)))
    total = 0.0
    for y in segments:
        x, p = np.zeros(n), stationary.copy()
        k = 0
        while k < min(y.size, _EXACT_STEPS):
            s = p[0, 0] + r
            innovation = y[k] - x[0]
            total -= 0.5 * (math.log(2.0 * math.pi * s) + innovation * innovation / s)
            gain_k = p[:, 0] / s
            x = phi @ (x + gain_k * innovation)
            p = phi @ (p - np.outer(gain_k, p[0, :])) @ phi.T + q
            k += 1
            if float(np.max(np.abs(p - converged))) <= tolerance:
                break
        rest = y[k:]
        if rest.size == 0:
            continue
        innovations = lfilter(num[0], den, rest)
        if np.any(x != 0.0):  # the handed-over state's own decay, h closed^j x: the impulse response of (closed, x)
            free_num, free_den = ss2tf(closed, x[:, None], h, np.array([[0.0]]))
            impulse = np.zeros(rest.size + 1)
            impulse[0] = 1.0
            innovations -= lfilter(free_num[0], free_den, impulse)[1:]
        total -= 0.5 * (rest.size * math.log(2.0 * math.pi * s_converged)
                        + float(np.dot(innovations, innovations)) / s_converged)
    return total


@dataclasses.dataclass
class HangFit:
    """A fitted axis: the model, its log-likelihood, the 95 % interval of each parameter (None where the
    record does not pin it down), which parameters ended on a bound, and the record's own figures."""

    model: HangModel
    log_likelihood: float
    intervals: Dict[str, Optional[Tuple[float, float]]]
    on_bound: List[str]
    samples: int
    record_std: float

    def as_dict(self) -> Dict[str, object]:
        return {"values": self.model.values(), "inertia": self.model.inertia, "log_likelihood": self.log_likelihood,
                "intervals": {k: (list(v) if v else None) for k, v in self.intervals.items()},
                "on_bound": list(self.on_bound), "samples": self.samples, "record_std": self.record_std}


def _model(names: Sequence[str], log_values: np.ndarray, inertia: float) -> HangModel:
    values = dict(zip(names, (float(v) for v in np.exp(log_values))))
    return HangModel(inertia=inertia, **values)


def _record_time(segments: Sequence[np.ndarray], dt: float) -> float:
    """The record's correlation time (s): where the longest stretch's autocorrelation falls below 1/e
    (by FFT: a ten-minute record at the IMU's rate is too long for the direct sum's O(n^2))."""
    from scipy.signal import correlate

    longest = max(segments, key=len)
    centred = longest - longest.mean()
    correlation = correlate(centred, centred, mode="full", method="fft")[centred.size - 1:]
    below = np.flatnonzero(correlation < correlation[0] / math.e)
    return dt * (float(below[0]) if below.size else centred.size / 4.0)


def _starts(segments: Sequence[np.ndarray], dt: float, inertia: float) -> List[np.ndarray]:
    """Starts of :data:`HANG_PARAMETERS` spread over the time scales the record could hold: the correlation
    time of the record, and body time scales from a tenth of it to the record's own, each with the sigma that
    gives the record's variance."""
    y = np.concatenate(segments)
    variance = float(np.var(y))
    record_time = _record_time(segments, dt)
    noise = max(float(np.std(np.diff(y))) / math.sqrt(2.0) / 4.0, 1e-5)
    starts = []
    for tau_d in (record_time, record_time / 4.0):
        for body_time in (record_time / 10.0, record_time):
            for ratio in (0.5, 5.0):  # under- to over-damped
                omega = 1.0 / max(body_time, dt)
                k = inertia * omega ** 2
                trial = HangModel(k, 2.0 * ratio * inertia * omega, 1.0, max(tau_d, 2.0 * dt), noise, inertia)
                sigma = math.sqrt(max(variance - noise ** 2, 1e-12)) / max(stationary_std(trial), 1e-12)
                values = dataclasses.replace(trial, torque_std=sigma).values()
                starts.append(np.log([_clip(name, values[name]) for name in HANG_PARAMETERS]))
    return starts


def _search(cost, starts: Sequence[np.ndarray], max_evaluations: int):
    """Nelder-Mead from each start, then once more from the best (its simplex can stall in a long valley)."""
    from scipy.optimize import minimize

    best = None
    for start in starts:
        result = minimize(cost, start, method="Nelder-Mead",
                          options={"maxfev": max_evaluations, "xatol": 1e-4, "fatol": 1e-4})
        if best is None or result.fun < best.fun:
            best = result
    assert best is not None
    again = minimize(cost, best.x, method="Nelder-Mead",
                     options={"maxfev": max_evaluations, "xatol": 1e-5, "fatol": 1e-5})
    return again if again.fun < best.fun else best


def _clip(name: str, value: float) -> float:
    low, high = BOUNDS[name]
    return min(max(value, low * 1.01), high / 1.01)


def fit_axis(y: np.ndarray, dt: float, inertia: float, valid: Optional[np.ndarray] = None,
             max_evaluations: int = 4000, tether: bool = False) -> HangFit:
    """Fit :class:`HangModel` to one axis's record ``y`` (rad, on a grid of ``dt`` s; ``valid`` marks the
    usable samples) about its mean, with the body's rotational ``inertia`` (kg m^2) given; ``tether`` adds
    the tether's relaxing bend (:data:`TETHER_PARAMETERS`). ValueError for a record too short to fit (under
    100 valid samples) or one that does not move."""
    if not (math.isfinite(dt) and dt > 0.0 and math.isfinite(inertia) and inertia > 0.0):
        raise ValueError("the hang fit needs a positive grid step and inertia, got dt %r, inertia %r" % (dt, inertia))
    segments = valid_segments(y, valid)
    count = sum(s.size for s in segments)
    if count < 100:
        raise ValueError("the hang record has %d usable samples; at least 100 are needed" % count)
    mean = float(np.mean(np.concatenate(segments)))
    segments = [s - mean for s in segments]
    if float(np.std(np.concatenate(segments))) <= 0.0:
        raise ValueError("the hang record does not move: nothing to fit")

    def cost_of(names: Sequence[str]):
        low = np.log([BOUNDS[name][0] for name in names])
        high = np.log([BOUNDS[name][1] for name in names])

        def cost(log_values: np.ndarray) -> float:
            if np.any(log_values < low) or np.any(log_values > high):
                return math.inf
            value = log_likelihood(_model(names, log_values, inertia), segments, dt)
            return -value if math.isfinite(value) else math.inf
        return cost, low, high

    names = HANG_PARAMETERS
    cost, low, high = cost_of(names)
    best = _search(cost, _starts(segments, dt, inertia), max_evaluations)
    if tether:  # from the spring's fit, the tether as stiff as the spring or a tenth, relaxing slowly or fast
        names = HANG_PARAMETERS + TETHER_PARAMETERS
        cost, low, high = cost_of(names)
        stiffness, record_time = math.exp(best.x[0]), _record_time(segments, dt)
        starts = [np.concatenate((best.x, np.log([_clip("relaxing_stiffness", k_r), _clip("relaxation_time", tau_r)])))
                  for k_r in (stiffness, 0.1 * stiffness) for tau_r in (record_time, 0.1 * record_time)]
        best = _search(cost, starts, max_evaluations)
    on_bound = [name for name, v, lo, hi in zip(names, best.x, low, high) if v - lo < 0.05 or hi - v < 0.05]
    intervals = _intervals(cost, best.x, names, on_bound)
    return HangFit(model=_model(names, best.x, inertia), log_likelihood=-float(best.fun), intervals=intervals,
                   on_bound=on_bound, samples=count, record_std=float(np.std(np.concatenate(segments))))


def _intervals(cost, x: np.ndarray, names: Sequence[str], on_bound: Sequence[str], step: float = 1e-2
               ) -> Dict[str, Optional[Tuple[float, float]]]:
    """95 % intervals from the Hessian of the negative log-likelihood in the logarithms (central differences);
    None for a parameter on a bound or where the curvature is not positive definite."""
    n = x.size
    f0 = cost(x)
    hessian = np.zeros((n, n))
    with np.errstate(invalid="ignore"):  # a step beyond a bound costs inf, and inf - inf is nan: no interval
        for i in range(n):
            for j in range(i, n):
                ei, ej = np.eye(n)[i] * step, np.eye(n)[j] * step
                if i == j:
                    value = (cost(x + ei) - 2.0 * f0 + cost(x - ei)) / step ** 2
                else:
                    value = (cost(x + ei + ej) - cost(x + ei - ej) - cost(x - ei + ej) + cost(x - ei - ej)) \
                        / (4.0 * step ** 2)
                hessian[i, j] = hessian[j, i] = value
    out: Dict[str, Optional[Tuple[float, float]]] = {name: None for name in names}
    if not np.all(np.isfinite(hessian)):
        return out
    try:
        covariance = np.linalg.inv(hessian)
    except np.linalg.LinAlgError:
        return out
    for k, name in enumerate(names):
        if name in on_bound or not covariance[k, k] > 0.0:
            continue
        half = _Z95 * math.sqrt(covariance[k, k])
        out[name] = (float(math.exp(x[k] - half)), float(math.exp(x[k] + half)))
    return out
