"""Acceptance by excursions (seed 004 eqs 8.79-8.89): Rice's formula and the Poisson law against
Monte-Carlo simulation of a Gaussian process with the smooth correlation function."""

import math
from collections.abc import Iterator

import numpy as np
import pytest
from scipy.linalg import expm

from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.excursions import excursion_acceptance, tolerance_for_risk
from gyrostand.analysis.noise import CorrelationModel

MODEL = CorrelationModel(variance=1.0, decay_per_s=1.0, frequency_rad_s=2.0)


def smooth_process(
    model: CorrelationModel, dt_s: float, reps: int, rng: np.random.Generator
) -> Iterator[np.ndarray]:
    """Readings x(k dt) of `reps` independent stationary processes with the smooth correlation
    sigma^2 e^(-mu|tau|)(cos(beta tau) + mu/beta sin(beta|tau|)): the damped oscillator
    x'' + 2 mu x' + (mu^2 + beta^2) x = white noise, discretised exactly (transition expm(A dt),
    noise covariance Sigma - Phi Sigma Phi^T with the stationary Sigma)."""
    mu, w2 = model.decay_per_s, model.decay_per_s**2 + model.frequency_rad_s**2
    phi = expm(np.array([[0.0, 1.0], [-w2, -2 * mu]]) * dt_s)
    sigma = np.diag([model.variance, model.variance * w2])
    chol = np.linalg.cholesky(sigma - phi @ sigma @ phi.T)
    state = np.linalg.cholesky(sigma) @ rng.standard_normal((2, reps))
    while True:
        yield state[0]
        state = phi @ state + chol @ rng.standard_normal((2, reps))


def excursion_counts(model, lower, upper, duration_s, dt_s, reps, seed) -> np.ndarray:
    """Up-crossings of `upper` plus down-crossings of `lower` per simulated record."""
    steps = smooth_process(model, dt_s, reps, np.random.default_rng(seed))
    counts = np.zeros(reps)
    prev = next(steps)
    for _ in range(int(round(duration_s / dt_s))):
        x = next(steps)
        counts += ((prev < upper) & (x >= upper)) | ((prev > lower) & (x <= lower))
        prev = x
    return counts


def test_smooth_model_has_the_simulated_derivative_variance() -> None:
    """sigma_v^2 = -K''(0) (8.86) vs a central second difference of K (error O(h): the third
    derivative jumps at 0)."""
    h = 1e-4
    second = (MODEL(h) - 2 * MODEL(0.0) + MODEL(-h)) / h**2
    assert MODEL.derivative_variance == pytest.approx(-second, rel=1e-3)


@pytest.mark.parametrize("eps_sigma", [2.0, 2.5])
def test_rice_and_poisson_match_monte_carlo(eps_sigma: float) -> None:
    duration = 40.0
    band = excursion_acceptance(MODEL, -eps_sigma, eps_sigma, duration)
    # closed form 8.88: n = T sigma_v / (pi sigma) e^(-eps^2 / 2 sigma^2)
    closed = duration * math.sqrt(5.0) / math.pi * math.exp(-(eps_sigma**2) / 2)
    assert band.mean_excursions == pytest.approx(closed, rel=1e-12)
    counts = excursion_counts(MODEL, -eps_sigma, eps_sigma, duration, 0.01, 3000, 1)
    se = counts.std() / math.sqrt(counts.size)
    assert abs(counts.mean() - band.mean_excursions) < 4 * se + 0.02 * band.mean_excursions
    assert band.poisson_valid
    p0_mc = np.mean(counts == 0)
    assert band.p_no_excursion == pytest.approx(p0_mc, abs=0.03)  # MC s.e. <= 0.009


def test_offset_mean_counts_each_bound_separately() -> None:
    """8.80-8.81 with the mean off-centre: the near bound dominates, as simulation shows."""
    band = excursion_acceptance(MODEL, -2.5, 2.5, 40.0, mean=1.0)
    assert band.upcrossings_upper > 10 * band.downcrossings_lower
    counts = excursion_counts(MODEL, -3.5, 1.5, 40.0, 0.01, 2000, 2)  # the same band around 0
    se = counts.std() / math.sqrt(counts.size)
    assert abs(counts.mean() - band.mean_excursions) < 4 * se + 0.02 * band.mean_excursions


def test_poisson_condition_fails_for_frequent_excursions() -> None:
    """A narrow-band reading (beta >> mu) stays correlated longer than it takes to cross."""
    narrow = CorrelationModel(variance=1.0, decay_per_s=0.1, frequency_rad_s=2.0)
    band = excursion_acceptance(narrow, -0.2, 0.2, 40.0)
    assert band.mean_time_between_s < band.correlation_time_s
    assert not band.poisson_valid


@pytest.mark.parametrize("offset", [0.0, 0.7])
@pytest.mark.parametrize("alpha", [0.05, 0.5, 0.9])
def test_inverse_problem_round_trips(alpha: float, offset: float) -> None:
    eps = tolerance_for_risk(MODEL, alpha, 600.0, mean_offset=offset)
    band = excursion_acceptance(MODEL, -eps, eps, 600.0, mean=offset)
    assert band.p_no_excursion == pytest.approx(alpha, rel=1e-9)
    if offset == 0.0:  # closed-form inverse of 8.88 with 8.84
        rate = 600.0 * math.sqrt(5.0) / math.pi
        assert eps == pytest.approx(math.sqrt(2 * math.log(rate / -math.log(alpha))), rel=1e-9)


def test_exponential_correlation_is_refused() -> None:
    with pytest.raises(AnalysisError, match="differentiable"):
        excursion_acceptance(CorrelationModel(1.0, 1.0), -2.0, 2.0, 10.0)
