"""Acceptance by excursions (Sveshnikov §8.3 item 1, eqs 8.79-8.89): Rice's counts, the exact
Kolmogorov alpha for the exponential correlation, Vanmarcke's clustering correction and the
lower bounds for the smooth one, against closed forms and Monte-Carlo simulation."""

import math
from collections.abc import Iterator

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.linalg import expm
from scipy.stats import norm

from gyrostand.analysis.excursions import (
    POISSON_ESTIMATE_ERROR,
    POISSON_ESTIMATE_MAX_EXCURSIONS,
    VANMARCKE_MAX_EXCURSIONS,
    excursion_acceptance,
    spectral_bandwidth,
    tolerance_for_risk,
)
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


def smooth_survival(model, lower, upper, duration_s, dt_s, reps, seed) -> np.ndarray:
    """Whether each simulated record stays inside (lower, upper) at every sample."""
    steps = smooth_process(model, dt_s, reps, np.random.default_rng(seed))
    inside = np.ones(reps, bool)
    for _ in range(int(round(duration_s / dt_s)) + 1):
        x = next(steps)
        inside &= (x > lower) & (x < upper)
    return inside


def markov_survival(model, lower, upper, duration_s, mu_dt, reps, seed) -> np.ndarray:
    """Per record of the exponential correlation (exact AR(1) steps), the probability that it
    stays inside: 0 once a sample is out, else the product over steps of the Brownian bridge's
    probability of crossing neither bound between the samples, 1 - e^(-2 d d' / v) per bound
    (d, d' the samples' distances to it, v = 1 - rho^2 the step variance)."""
    rng = np.random.default_rng(seed)
    sigma = math.sqrt(model.variance)
    a, b, rho = lower / sigma, upper / sigma, math.exp(-mu_dt)
    v = 1 - rho**2
    z = rng.standard_normal(reps)
    weight = ((z > a) & (z < b)).astype(float)
    for _ in range(int(round(model.decay_per_s * duration_s / mu_dt))):
        nxt = rho * z + math.sqrt(v) * rng.standard_normal(reps)
        up, down = np.clip(b - z, 0, None) * (b - nxt), np.clip(z - a, 0, None) * (nxt - a)
        cross = np.exp(-2 * np.clip(up, 0, None) / v) + np.exp(-2 * np.clip(down, 0, None) / v)
        weight *= np.where((nxt > a) & (nxt < b), np.clip(1 - cross, 0, None), 0.0)
        z = nxt
    return weight


# --- Rice's counts (8.80-8.88) ---------------------------------------------------------------


def test_smooth_model_has_the_simulated_derivative_variance() -> None:
    """sigma_v^2 = -K''(0) (8.86) vs a central second difference of K (error O(h): the third
    derivative jumps at 0)."""
    h = 1e-4
    second = (MODEL(h) - 2 * MODEL(0.0) + MODEL(-h)) / h**2
    assert MODEL.derivative_variance == pytest.approx(-second, rel=1e-3)


@pytest.mark.parametrize("eps_sigma", [2.0, 2.5])
def test_rice_counts_match_monte_carlo(eps_sigma: float) -> None:
    duration = 40.0
    band = excursion_acceptance(MODEL, -eps_sigma, eps_sigma, duration)
    # closed form 8.88: n = T sigma_v / (pi sigma) e^(-eps^2 / 2 sigma^2)
    closed = duration * math.sqrt(5.0) / math.pi * math.exp(-(eps_sigma**2) / 2)
    assert band.rice.mean_excursions == pytest.approx(closed, rel=1e-12)
    assert band.rice.p_poisson == pytest.approx(math.exp(-closed), rel=1e-12)  # 8.84
    counts = excursion_counts(MODEL, -eps_sigma, eps_sigma, duration, 0.01, 3000, 1)
    se = counts.std() / math.sqrt(counts.size)
    assert abs(counts.mean() - band.rice.mean_excursions) < 4 * se + 0.02 * closed


def test_offset_mean_counts_each_bound_separately() -> None:
    """8.80-8.81 with the mean off-centre: the near bound dominates, as simulation shows."""
    band = excursion_acceptance(MODEL, -2.5, 2.5, 40.0, mean=1.0)
    assert band.rice.upcrossings_upper > 10 * band.rice.downcrossings_lower
    counts = excursion_counts(MODEL, -3.5, 1.5, 40.0, 0.01, 2000, 2)  # the same band around 0
    se = counts.std() / math.sqrt(counts.size)
    assert abs(counts.mean() - band.rice.mean_excursions) < 4 * se + 0.02 * counts.mean()


@pytest.mark.parametrize(("mu", "beta"), [(0.1, 1.0), (1.0, 2.0), (0.5, 0.0), (0.02, 3.0)])
def test_bandwidth_matches_the_time_domain_moment(mu: float, beta: float) -> None:
    """lambda_1 = (2 / pi) integral_0^inf (K(0) - K(tau)) / tau^2 d tau (as integral_0^inf
    (1 - cos w tau) / tau^2 d tau = pi w / 2), against the closed form behind q."""
    model = CorrelationModel(2.0, mu, beta)
    end = 60.0 / mu  # K ~ e^(-60) beyond: the rest is K(0) / end
    edges = np.linspace(0.0, end, 200)  # pieces short enough for the oscillation
    pieces = [
        quad(lambda t: (model(0.0) - model(t)) / t**2, lo, hi)[0]
        for lo, hi in zip(edges[:-1], edges[1:], strict=True)
    ]
    lambda_1 = 2 / np.pi * (sum(pieces) + model.variance / end)
    q = spectral_bandwidth(model)
    expected = math.sqrt((1 - q**2) * model.variance * model.variance * (mu**2 + beta**2))
    assert lambda_1 == pytest.approx(expected, rel=1e-6)


# --- exponential correlation: the Kolmogorov equation ----------------------------------------


@pytest.mark.parametrize("s", [0.1, 1.0, 5.0])
def test_kolmogorov_matches_the_reflection_principle_on_a_half_line(s: float) -> None:
    """The band (0, inf) about a zero mean: by symmetry and the reflection principle,
    P(Z stays positive over s = mu T) = arcsin(e^(-s)) / pi for the stationary OU process."""
    band = excursion_acceptance(CorrelationModel(4.0, 0.2), 0.0, 100.0, s / 0.2, mean=0.0)
    assert band.method == "kolmogorov" and not band.is_bound and band.rice is None
    assert band.p_no_excursion == pytest.approx(math.asin(math.exp(-s)) / math.pi, rel=1e-3)


def test_kolmogorov_short_control_time_loses_a_boundary_layer() -> None:
    """Over s << 1 the process moves like Brownian motion with variance 2 s: starting at a
    distance d from a bound it crosses with probability 2 Phi(-d / sqrt(2 s)); integrated over
    the start, alpha = P(start inside) - 2 sqrt(s / pi) (phi(a) + phi(b)) + O(s)."""
    s, a, b = 1e-4, -2.0, 1.5
    band = excursion_acceptance(CorrelationModel(1.0, 0.5), a, b, s / 0.5, mean=0.0)
    expected = norm.cdf(b) - norm.cdf(a) - 2 * math.sqrt(s / math.pi) * (norm.pdf(a) + norm.pdf(b))
    assert band.p_no_excursion == pytest.approx(expected, abs=3e-4)
    assert band.p_no_excursion < band.p_start_inside


def test_markov_in_test_simulation() -> None:
    """Case d below, re-simulated here with 4000 records (bridge-corrected AR(1), mu dt = 0.01:
    the drift left out of the bridge biases alpha by O(mu dt) ~ 1 %)."""
    model = CorrelationModel(1.0, 0.5)
    band = excursion_acceptance(model, -1.5, 2.5, 10.0, mean=0.0)
    weight = markov_survival(model, -1.5, 2.5, 10.0, 0.01, 4000, 7)
    se = weight.std() / math.sqrt(weight.size)
    assert abs(weight.mean() - band.p_no_excursion) < 4 * se + 0.01 * band.p_no_excursion


# --- smooth correlation: Vanmarcke's correction and the lower bounds --------------------------

NARROW = CorrelationModel(1.0, 0.1, 1.0)  # q = 0.34: crossings cluster


def test_vanmarcke_is_the_published_double_barrier_formula_on_a_symmetric_band() -> None:
    """Vanmarcke (1975) as Der Kiureghian (1980) writes it for |X| < r:
    alpha = (1 - e^(-r^2/2)) exp(-N e^(-r^2/2) (1 - e^(-sqrt(pi/2) q^1.2 r)) / (1 - e^(-r^2/2))),
    N = T sqrt(lambda_2 / lambda_0) / pi zero crossings, here with P(start inside) in front."""
    r, duration = 2.5, 15.0
    band = excursion_acceptance(NARROW, -r, r, duration)
    assert band.rice.mean_excursions < VANMARCKE_MAX_EXCURSIONS
    assert band.method == "vanmarcke" and not band.is_bound
    q = band.rice.bandwidth
    zeros = duration * math.sqrt(0.1**2 + 1.0) / math.pi
    tail = math.exp(-(r**2) / 2)
    clusters = zeros * tail * (1 - math.exp(-math.sqrt(math.pi / 2) * q**1.2 * r)) / (1 - tail)
    expected = (norm.cdf(r) - norm.cdf(-r)) * math.exp(-clusters)
    assert band.p_no_excursion == pytest.approx(expected, rel=1e-12)
    assert band.rice.p_vanmarcke == band.p_no_excursion


def test_a_broad_band_takes_the_poisson_law_up_to_one_excursion() -> None:
    band = excursion_acceptance(MODEL, -2.0, 3.0, 10.0, mean=0.0)  # q = 0.62, n = 0.52
    assert (band.method, band.is_bound) == ("poisson", False)
    assert band.p_no_excursion == pytest.approx(band.p_start_inside * band.rice.p_poisson)
    assert band.p_no_excursion != band.rice.p_vanmarcke


def test_outside_the_checked_regions_alpha_is_a_lower_bound() -> None:
    narrow = excursion_acceptance(NARROW, -2.0, 3.0, 60.0, mean=0.0)  # q = 0.34, n = 1.4
    assert narrow.rice.mean_excursions > VANMARCKE_MAX_EXCURSIONS
    assert (narrow.method, narrow.is_bound) == ("poisson", True)
    assert narrow.p_no_excursion == pytest.approx(narrow.p_start_inside * narrow.rice.p_poisson)
    broad = excursion_acceptance(MODEL, -2.0, 3.0, 80.0, mean=0.0)  # q = 0.62, n = 4.2
    assert broad.rice.mean_excursions > POISSON_ESTIMATE_MAX_EXCURSIONS
    assert (broad.method, broad.is_bound) == ("rice", True)
    rice_bound = broad.p_start_inside - broad.rice.mean_excursions
    assert broad.p_no_excursion == pytest.approx(max(rice_bound, 0.0))
    low = excursion_acceptance(NARROW, -1.5, 2.5, 2.0, mean=0.0)  # a bound 1.5 sigma away
    assert low.rice.mean_excursions < VANMARCKE_MAX_EXCURSIONS and low.method == "rice"
    outside = excursion_acceptance(MODEL, 0.5, 3.0, 10.0, mean=0.0)  # mean below the band
    assert outside.method == "rice" and outside.p_no_excursion == 0.0


def test_a_broad_band_with_many_excursions_gets_the_poisson_estimate() -> None:
    """n = 2.4: the guaranteed bound P(start inside) - n is 0, which says nothing; the Poisson
    law is the best estimate, stated as such, and agrees with simulation within its 17 % (it
    was once reported as the bound 0)."""
    band = excursion_acceptance(MODEL, -2.0, 3.0, 46.0, mean=0.0)  # q = 0.62
    assert 2.3 < band.rice.mean_excursions < 2.5
    assert (band.method, band.is_bound) == ("poisson-estimate", False)
    assert band.p_no_excursion == pytest.approx(band.p_start_inside * band.rice.p_poisson)
    assert "best estimate" in band.method_note and "17 %" in band.method_note
    inside = smooth_survival(MODEL, -2.0, 3.0, 46.0, 0.02, 4000, 11)
    p, se = inside.mean(), inside.std() / math.sqrt(inside.size)
    assert abs(band.p_no_excursion - p) < POISSON_ESTIMATE_ERROR * p + 3 * se


@pytest.mark.parametrize(
    "model", [MODEL, NARROW, CorrelationModel(1.0, 0.3), CorrelationModel(1.0, 0.02, 2.0)]
)
@pytest.mark.parametrize("offset", [0.0, 0.7])
def test_alpha_rises_with_the_band_and_never_exceeds_a_start_inside(
    model: CorrelationModel, offset: float
) -> None:
    """Monotone in eps, as the inverse problem needs (the method may change with eps, but only
    from a lower bound up to an estimate)."""
    alphas, inside = [], []
    for eps in np.linspace(0.8, 5.0, 43):
        band = excursion_acceptance(model, -eps, eps, 30.0, mean=offset)
        alphas.append(band.p_no_excursion)
        inside.append(band.p_start_inside)
    assert np.all(np.diff(alphas) >= -1e-12)
    assert np.all(np.array(alphas) <= np.array(inside) + 1e-12)


@pytest.mark.parametrize("model", [MODEL, CorrelationModel(1.0, 0.05)])
@pytest.mark.parametrize("offset", [0.0, 0.7])
@pytest.mark.parametrize("alpha", [0.03, 0.05, 0.3, 0.55, 0.9])
def test_inverse_problem_round_trips(model: CorrelationModel, alpha: float, offset: float) -> None:
    """alpha(eps) is reached at eps, or jumps across it there (the edge of a checked region: for
    MODEL at 600 s the Rice bound is 0 beyond n = 3 and the Poisson estimate starts at e^(-3))."""
    eps = tolerance_for_risk(model, alpha, 600.0, mean_offset=offset)
    below = excursion_acceptance(model, -eps * (1 - 1e-9), eps * (1 - 1e-9), 600.0, mean=offset)
    above = excursion_acceptance(model, -eps * (1 + 1e-9), eps * (1 + 1e-9), 600.0, mean=offset)
    assert below.p_no_excursion <= alpha + 1e-7 and above.p_no_excursion >= alpha - 1e-7
    jump = above.method != below.method
    assert jump == (model is MODEL and alpha < math.exp(-POISSON_ESTIMATE_MAX_EXCURSIONS))
    if not jump:
        assert above.p_no_excursion == pytest.approx(alpha, rel=1e-6)


# --- the reference cases, against simulation -----------------------------------------------

# alpha simulated by `validation/excursions_mc.py --paths 200000 --seed 2024` (the smooth model
# discretised exactly at dt = 0.02 / w0; the exponential one by AR(1) steps at mu dt = 0.002 with
# the Brownian-bridge correction, residual bias O(mu dt) ~ 0.2 %): model, band about a zero
# mean, control time, simulated alpha and its standard error.
REFERENCE = {
    "a narrow band, clusters": (NARROW, -2.0, 3.0, 200.0, 0.0232, 0.0003),
    "b broad band, rare": (MODEL, -3.0, 3.0, 50.0, 0.6770, 0.0010),
    "c Markov, slow": (CorrelationModel(1.0, 0.05), -2.0, 2.0, 40.0, 0.5619, 0.0011),
    "d Markov, fast": (CorrelationModel(1.0, 0.5), -1.5, 2.5, 10.0, 0.2028, 0.0009),
}


@pytest.mark.parametrize("case", REFERENCE)
def test_reference_cases_against_simulation(case: str) -> None:
    """Within 10 % of simulation, or declared a lower bound that the simulation respects."""
    model, lower, upper, duration, simulated, se = REFERENCE[case]
    band = excursion_acceptance(model, lower, upper, duration, mean=0.0)
    alpha = band.p_no_excursion
    if case.startswith("a"):  # the issue: Poisson 2.5x too low while it claimed to be valid
        assert simulated / band.rice.p_poisson > 2.4
        assert (band.method, band.is_bound) == ("poisson", True)
        assert alpha <= simulated - 3 * se
        # Vanmarcke alone misses by 13 % here: that is why n = 4.7 is outside the region
        assert abs(band.rice.p_vanmarcke / simulated - 1) > 0.10
    elif case.startswith("b"):  # rare excursions: Poisson fine, Vanmarcke too
        assert (band.method, band.is_bound) == ("poisson", False)
        assert abs(alpha / simulated - 1) < 0.10
        assert abs(band.rice.p_vanmarcke / simulated - 1) < 0.10
    else:  # exact: only the simulation's noise and its bias of ~0.2 %
        assert (band.method, band.is_bound) == ("kolmogorov", False)
        assert abs(alpha - simulated) < 3 * se + 0.003 * simulated


def test_smooth_in_test_simulation() -> None:
    """Case b re-simulated here with 3000 records (dt = 0.01 s: 45 samples a period)."""
    model, lower, upper, duration, _, _ = REFERENCE["b broad band, rare"]
    band = excursion_acceptance(model, lower, upper, duration, mean=0.0)
    inside = smooth_survival(model, lower, upper, duration, 0.01, 3000, 5)
    se = inside.std() / math.sqrt(inside.size)
    assert abs(band.p_no_excursion - inside.mean()) < 0.10 * inside.mean() + 3 * se
