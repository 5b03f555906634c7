"""The hanging robot's linear model and its maximum-likelihood fit (quadruped_control/analysis/hang.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.linalg import expm, solve_discrete_lyapunov

from quadruped_control.analysis import hang

TRUE = hang.HangModel(stiffness=0.02, damping=0.05, torque_std=0.002, correlation_time=10.0,
                      noise_std=math.radians(0.05), inertia=0.06)


def _simulate(model: hang.HangModel, dt: float, n: int, seed: int) -> np.ndarray:
    """A record of the linear model itself, exactly discretised, from its stationary state."""
    rng = np.random.default_rng(seed)
    phi, q = hang.discretize(model, dt)
    states = phi.shape[0]
    noise = np.linalg.cholesky(q + 1e-30 * np.eye(states))
    x = np.linalg.cholesky(solve_discrete_lyapunov(phi, q) + 1e-30 * np.eye(states)) @ rng.standard_normal(states)
    out = np.empty(n)
    for k in range(n):
        out[k] = x[0] + model.noise_std * rng.standard_normal()
        x = phi @ x + noise @ rng.standard_normal(states)
    return out


def _exact_log_likelihood(model: hang.HangModel, segments, dt: float) -> float:
    """The readable form: the time-varying Kalman filter over every sample, from the stationary state."""
    phi, q = hang.discretize(model, dt)
    r = model.noise_std ** 2
    total = 0.0
    for y in segments:
        x, p = np.zeros(phi.shape[0]), solve_discrete_lyapunov(phi, q)
        for yk in y:
            s = p[0, 0] + r
            innovation = yk - x[0]
            total -= 0.5 * (math.log(2.0 * math.pi * s) + innovation ** 2 / s)
            gain = p[:, 0] / s
            x = phi @ (x + gain * innovation)
            p = phi @ (p - np.outer(gain, p[0, :])) @ phi.T + q
    return total


def test_the_discretisation_is_the_exponential_and_keeps_the_stationary_variance() -> None:
    dt = 0.1
    phi, q = hang.discretize(TRUE, dt)
    a, _ = hang._continuous(TRUE)
    np.testing.assert_allclose(phi, expm(a * dt), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(q, q.T)
    assert np.all(np.linalg.eigvalsh(q) > -1e-20)
    # the discrete chain's stationary variance is the continuous model's, at any step
    for step in (0.01, 0.1, 1.0):
        phi, q = hang.discretize(TRUE, step)
        assert math.sqrt(solve_discrete_lyapunov(phi, q)[0, 0]) == pytest.approx(hang.stationary_std(TRUE), rel=1e-6)


def test_the_spectral_density_integrates_to_the_stationary_variance() -> None:
    total, _ = quad(lambda f: float(hang.spectral_density(TRUE, np.array([f]))[0]), 0.0, np.inf, limit=400)
    assert total == pytest.approx(hang.stationary_std(TRUE) ** 2, rel=1e-4)
    # the static limit: a push held long is sigma / k of tilt, so the low-frequency level is 4 sigma^2 tau / k^2
    level = 4.0 * TRUE.torque_std ** 2 * TRUE.correlation_time / TRUE.stiffness ** 2
    assert float(hang.spectral_density(TRUE, np.array([1e-7]))[0]) == pytest.approx(level, rel=1e-6)


def test_the_fast_likelihood_equals_the_exact_kalman_filter() -> None:
    y = _simulate(TRUE, 0.1, 1500, seed=3)
    segments = [y[:700] - y.mean(), y[720:] - y.mean(), y[700:705] - y.mean()]  # a gap, and a stretch too short
    others = (hang.HangModel(0.5, 0.01, 0.01, 1.0, 1e-3, 0.06), hang.HangModel(1e-3, 2.0, 1e-4, 50.0, 1e-4, 0.2))
    for model in (TRUE,) + others:
        assert hang.log_likelihood(model, segments, 0.1) == pytest.approx(
            _exact_log_likelihood(model, segments, 0.1), rel=1e-8, abs=1e-6)


def test_valid_segments_split_at_invalid_or_missing_samples_and_drop_short_ones() -> None:
    y = np.arange(40, dtype=float)
    y[12] = math.nan
    valid = np.ones(40, dtype=bool)
    valid[30] = False
    segments = hang.valid_segments(y, valid, min_length=10)
    assert [s.tolist() for s in segments] == [list(range(12)), list(range(13, 30))]  # 31-39: nine, dropped


def test_the_records_correlation_time_by_fft_is_the_direct_sums() -> None:
    rng = np.random.default_rng(4)
    y = np.zeros(3000)
    for k in range(1, y.size):  # an AR(1) record with a correlation time of about 2 s at 10 ms
        y[k] = 0.995 * y[k - 1] + rng.standard_normal()
    for segments in ([y], [y[:400], y[500:]], [y[:50]]):
        longest = max(segments, key=len)
        centred = longest - longest.mean()
        direct = np.correlate(centred, centred, mode="full")[centred.size - 1:]
        below = np.flatnonzero(direct < direct[0] / math.e)
        expected = 0.01 * (float(below[0]) if below.size else centred.size / 4.0)
        assert hang._record_time(segments, 0.01) == pytest.approx(expected)


@pytest.mark.slow
def test_the_fit_recovers_a_known_model_inside_its_intervals() -> None:
    y = _simulate(TRUE, 0.1, 6000, seed=1) + math.radians(3.0)  # hung off level: fitted about its mean
    fit = hang.fit_axis(y, 0.1, TRUE.inertia)
    assert fit.samples == 6000 and not fit.on_bound
    for name in hang.HANG_PARAMETERS:
        low, high = fit.intervals[name]
        assert low <= getattr(TRUE, name) <= high, name
        assert low <= getattr(fit.model, name) <= high
    assert fit.model.inertia == TRUE.inertia
    truth = hang.log_likelihood(TRUE, hang.valid_segments(y - y.mean()), 0.1)
    assert fit.log_likelihood >= truth  # the optimum beats the truth on its own record
    assert set(fit.as_dict()["values"]) == set(hang.HANG_PARAMETERS)


def test_a_record_too_short_or_still_or_a_bad_grid_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 100"):
        hang.fit_axis(np.zeros(50), 0.1, 0.06)
    with pytest.raises(ValueError, match="does not move"):
        hang.fit_axis(np.full(500, 0.1), 0.1, 0.06)
    with pytest.raises(ValueError, match="positive grid step"):
        hang.fit_axis(np.ones(500), 0.0, 0.06)
    with pytest.raises(ValueError, match="inertia"):
        hang.fit_axis(np.ones(500), 0.1, math.nan)


TETHERED = hang.HangModel(stiffness=0.003, damping=0.2, torque_std=0.0005, correlation_time=10.0,
                          noise_std=math.radians(0.05), inertia=0.2, relaxing_stiffness=0.05, relaxation_time=25.0)


def test_the_tethers_branch_is_the_plants_standard_linear_solid_and_vanishes_at_zero() -> None:
    a, _ = hang._continuous(TETHERED)
    assert a.shape == (4, 4) and TETHERED.parameters == hang.HANG_PARAMETERS + hang.TETHER_PARAMETERS
    # held at a tilt long enough, the relaxed tilt follows and only the spring k holds it
    theta = 0.1
    relaxed = np.array([theta, 0.0, 0.0, theta])
    assert (a @ relaxed)[1] * TETHERED.inertia == pytest.approx(-TETHERED.stiffness * theta)
    fresh = np.array([theta, 0.0, 0.0, 0.0])  # at once, the bend resists with k + k_r
    assert (a @ fresh)[1] * TETHERED.inertia == pytest.approx(-(TETHERED.stiffness + 0.05) * theta)
    untethered = hang.HangModel(**{**TETHERED.__dict__, "relaxing_stiffness": 0.0})
    assert hang._continuous(untethered)[0].shape == (3, 3) and untethered.parameters == hang.HANG_PARAMETERS
    total, _ = quad(lambda f: float(hang.spectral_density(TETHERED, np.array([f]))[0]), 0.0, np.inf, limit=400)
    assert total == pytest.approx(hang.stationary_std(TETHERED) ** 2, rel=1e-4)
    y = _simulate(TETHERED, 0.2, 600, seed=5)
    # its slow relaxation keeps the filter's covariance moving for longer: the hand-over costs 1e-4 of 3,249
    assert hang.log_likelihood(TETHERED, [y - y.mean()], 0.2) == pytest.approx(
        _exact_log_likelihood(TETHERED, [y - y.mean()], 0.2), abs=1e-3)


@pytest.mark.slow
def test_the_fit_with_the_tether_reaches_the_truths_likelihood_but_one_hang_does_not_pin_the_tether() -> None:
    y = _simulate(TETHERED, 0.2, 3300, seed=7)  # eleven minutes at 5 Hz
    spring = hang.fit_axis(y, 0.2, TETHERED.inertia)
    fit = hang.fit_axis(y, 0.2, TETHERED.inertia, tether=True)
    assert set(fit.model.values()) == set(hang.HANG_PARAMETERS + hang.TETHER_PARAMETERS)
    truth = hang.log_likelihood(TETHERED, hang.valid_segments(y - y.mean()), 0.2)
    assert fit.log_likelihood >= truth and fit.log_likelihood >= spring.log_likelihood - 1e-6
    # ...and the record tells the truth's tether (k_r 50 mN m/rad over 25 s on a 3 mN m/rad spring) from other
    # values by little: at this seed the fit sits 5 above the truth with k ten times the truth's and a tether that
    # relaxes in 1.6 s (docs/identification.md, "What a hang tells"). Likelihoods within a few units are the
    # record's, so neither the fit nor its local intervals pin the tether down.
    assert fit.log_likelihood - truth < 10.0
