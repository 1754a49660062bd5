"""Noise characterisation (seed 004 eqs 8.89-8.94) against simulated processes of known
correlation, closed forms and Monte-Carlo."""

import json
import math

import numpy as np
import pytest
from scipy.signal import lfilter

from gyrostand.analysis.effective import variance_inflation, window_mean_correlation
from gyrostand.analysis.noise import (
    CorrelationModel,
    characterise_noise,
    correlation_estimate_variance,
    correlation_function,
    expected_covariance,
    find_harmonics,
    fit_correlation,
    max_sampling_interval,
    sampling_advice,
)
from tests.analysis.test_excursions import smooth_process


def ou(rng: np.random.Generator, n: int, dt_s: float, mu: float, sigma: float) -> np.ndarray:
    """Stationary exponentially correlated (Ornstein-Uhlenbeck) readings, exact AR(1) form."""
    a = math.exp(-mu * dt_s)
    shocks = rng.normal(0, sigma * math.sqrt(1 - a * a), n)
    return lfilter([1.0], [1.0, -a], shocks, zi=[a * rng.normal(0, sigma)])[0]


def test_correlation_estimate_is_eq_892() -> None:
    x = np.random.default_rng(0).normal(size=200)
    est = correlation_function(x, 0.5, max_lag_s=5.0)
    xc = x - x.mean()
    direct = [sum(xc[j] * xc[j + lag] for j in range(200 - lag)) / (200 - lag) for lag in range(11)]
    assert est.lag_s == pytest.approx(0.5 * np.arange(11))
    assert est.covariance == pytest.approx(direct, rel=1e-10)


def test_exponential_fit_recovers_known_process_and_white_noise() -> None:
    rng = np.random.default_rng(1)
    x = ou(rng, 2**16, 0.1, 0.5, 0.2) + rng.normal(0, 0.1, 2**16)
    model = fit_correlation(correlation_function(x, 0.1))
    assert model.variance == pytest.approx(0.04, rel=0.08)
    assert model.decay_per_s == pytest.approx(0.5, rel=0.1)
    assert model.white_variance == pytest.approx(0.01, rel=0.15)
    assert model.correlation_time_s == pytest.approx(1 / model.decay_per_s)  # 8.89


def test_expected_covariance_is_the_mean_of_the_estimate_by_matrices() -> None:
    """E[K^(l)] = tr(S_l M Sigma M) / (N - l), M the removal of a line, by dense matrices."""
    n, dt = 300, 0.5
    model = CorrelationModel(variance=2.0, decay_per_s=0.1, white_variance=0.3)
    for degree in (0, 1, 2):
        est = correlation_function(np.zeros(n) + np.arange(n) % 7, dt, 20.0, degree)
        q = np.linalg.qr(np.vander(np.linspace(-1, 1, n), degree + 1))[0]
        m = np.eye(n) - q @ q.T
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n))) * dt
        sigma = model(lags) + model.white_variance * np.eye(n)
        msm = m @ sigma @ m
        direct = [np.trace(msm, offset=lag) / (n - lag) for lag in range(est.lag_s.size)]
        assert expected_covariance(model, est) == pytest.approx(direct, rel=1e-9, abs=1e-12)


def test_pooled_records_estimate_and_expectation_by_matrices() -> None:
    """Records of 300, 300, 250 and 15 readings (the last shorter than the longest lags)
    pooled: K^ is the records' sums of products over their pairs, and its expectation the same
    sums of tr(S_l M Sigma M) of each, by dense matrices."""
    dt, degree = 0.5, 1
    model = CorrelationModel(variance=2.0, decay_per_s=0.1, white_variance=0.3)
    rng = np.random.default_rng(3)
    records = [rng.normal(size=n) for n in (300, 300, 250, 15)]
    est = correlation_function(records[0], dt, 20.0, degree, others=records[1:])
    assert est.records == (300, 300, 250, 15) and est.n == 865
    products, pairs, expected = np.zeros(41), np.zeros(41), np.zeros(41)
    for x in records:
        n = x.size
        q = np.linalg.qr(np.vander(np.linspace(-1, 1, n), degree + 1))[0]
        m = np.eye(n) - q @ q.T
        r = m @ x
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n))) * dt
        msm = m @ (model(lags) + model.white_variance * np.eye(n)) @ m
        for lag in range(min(41, n)):
            products[lag] += r[: n - lag] @ r[lag:]
            expected[lag] += np.trace(msm, offset=lag)
            pairs[lag] += n - lag
    assert est.covariance == pytest.approx(products / pairs, rel=1e-9, abs=1e-12)
    assert expected_covariance(model, est) == pytest.approx(expected / pairs, rel=1e-9)


def test_fit_allows_for_the_removed_line_on_a_short_record() -> None:
    """420 s of exponential (1/mu = 20 s) plus white readings less their line, as the report's
    still series: K^ is biased low by what the line took (a tenth of the variance and more), and
    K fitted to it straight decayed too fast: median mu 0.091 for 0.05 over these records, and
    the inflation f of a still series' five 60 s windows 90 s apart 1.011 for 1.079."""
    rng = np.random.default_rng(7)
    truth = CorrelationModel(1e-4, 0.05, white_variance=2.5e-5)
    mu, f = [], []
    for _ in range(60):
        x = ou(rng, 4200, 0.1, 0.05, 0.01) + rng.normal(0, 0.005, 4200)
        model = fit_correlation(correlation_function(x, 0.1, trend_degree=1))
        mu.append(model.decay_per_s)
        f.append(still_inflation(model))
    assert np.median(mu) == pytest.approx(0.05, rel=0.2)  # 0.057
    assert np.median(f) - 1 == pytest.approx(still_inflation(truth) - 1, rel=0.35)  # 1.055


def still_inflation(model: CorrelationModel) -> float:
    """f of five 60 s window means 90 s apart (`analysis.effective`)."""
    rho = [window_mean_correlation(model, 60.0, 90.0 * k, 0.1) for k in range(1, 5)]
    return variance_inflation(np.array(rho), 5)


def test_smooth_fit_recovers_oscillator_process() -> None:
    truth = CorrelationModel(variance=0.25, decay_per_s=0.2, frequency_rad_s=0.8)
    steps = smooth_process(truth, 0.1, 1, np.random.default_rng(2))
    x = np.array([next(steps)[0] for _ in range(2**16)])
    model = fit_correlation(correlation_function(x, 0.1), smooth=True)
    assert model.decay_per_s == pytest.approx(0.2, rel=0.15)
    assert model.frequency_rad_s == pytest.approx(0.8, rel=0.05)
    assert model.variance == pytest.approx(0.25, rel=0.15)


@pytest.mark.parametrize(
    ("mu", "beta"), [(0.5, 0.0), (0.3, 2.0), (1.0, 0.4), (0.0646, 2.2e-7), (0.01, 3.0)]
)
def test_correlation_time_is_integral_of_abs_k(mu: float, beta: float) -> None:
    """8.89 vs a trapezoid of |K| on a fine grid (and 2/mu exactly when beta = 0); beta near 0
    as the paper campaign's smooth fit has it, and many zeros of K within the record."""
    model = CorrelationModel(variance=2.0, decay_per_s=mu, frequency_rad_s=beta)
    tau = np.linspace(0, 60 / mu, 600_001)
    assert model.correlation_time_s == pytest.approx(
        np.trapezoid(np.abs(model(tau)), tau) / 2.0, rel=1e-6
    )
    if beta == 0.0:
        assert model.correlation_time_s == pytest.approx(2 / mu)


def test_hidden_harmonic_amplitude_from_spectrum_and_correlation() -> None:
    """a cos(nu t + phi) in correlated noise (8.90): found, with a from the peak and from the
    cosine a^2/2 cos(nu tau) of K^ at large lags (8.91)."""
    rng = np.random.default_rng(3)
    n, dt = 2**15, 0.1
    t = np.arange(n) * dt
    x = ou(rng, n, dt, 0.5, 0.2) + 0.08 * np.cos(2 * np.pi * 0.37 * t + 0.3)
    search = find_harmonics(x, dt, false_alarm=0.01)
    assert len(search.harmonics) == 1
    h = search.harmonics[0]
    assert h.frequency_hz == pytest.approx(0.37, abs=1e-3)
    assert h.amplitude == pytest.approx(0.08, rel=0.1)
    assert h.amplitude_from_correlation == pytest.approx(0.08, rel=0.1)
    assert h.false_alarm_probability < 1e-6
    # Welch's dof for 15 Hann segments at 50 % overlap (overlap correlation exactly 1/6)
    assert search.dof == pytest.approx(30 / (1 + 2 * (14 / 15) / 36), rel=1e-6)


def test_false_alarm_level_holds_on_noise_alone() -> None:
    """Records without a harmonic: detections in at most ~ the nominal fraction of them."""
    rng = np.random.default_rng(4)
    flagged = sum(
        bool(find_harmonics(ou(rng, 4096, 0.1, 0.5, 0.2), 0.1, false_alarm=0.1).harmonics)
        for _ in range(150)
    )
    assert flagged <= 25  # nominal 15 of 150; binomial(150, 0.1) exceeds 25 with p < 0.005


def test_continuous_estimate_variance_closed_form() -> None:
    """8.93, exponential K: D = (4 sigma^4 / T^2) (T / 2mu - (1 - e^(-2 mu T)) / 4 mu^2)."""
    model = CorrelationModel(variance=0.3, decay_per_s=0.2)
    t = 50.0
    closed = 4 * 0.3**2 / t**2 * (t / 0.4 - (1 - math.exp(-0.4 * t)) / 0.16)
    assert correlation_estimate_variance(model, t) == pytest.approx(closed, rel=1e-8)


@pytest.mark.parametrize("mu_delta", [0.1, 0.5, 2.0])
def test_sampled_to_continuous_variance_ratio(mu_delta: float) -> None:
    """8.92 vs 8.93 for an exponential K and T >> 1/mu: ratio -> mu Delta coth(mu Delta)."""
    model = CorrelationModel(variance=1.0, decay_per_s=1.0)
    ratio = correlation_estimate_variance(
        model, 4000.0, interval_s=mu_delta
    ) / correlation_estimate_variance(model, 4000.0)
    assert ratio == pytest.approx(mu_delta / math.tanh(mu_delta), rel=2e-3)


def test_max_sampling_interval_round_trips_the_closed_form() -> None:
    model = CorrelationModel(variance=1.0, decay_per_s=0.5)
    delta = max_sampling_interval(model, 8000.0, factor=1.2)
    # mu Delta coth(mu Delta) = 1.2, solved here by bisection on the closed form
    lo, hi = 1e-6, 10.0
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if mid / math.tanh(mid) < 1.2 else (lo, mid)
    assert delta * 0.5 == pytest.approx(lo, rel=5e-3)


def test_sampled_variance_formula_matches_monte_carlo() -> None:
    """Scatter of the sampled variance estimate over simulated records vs 8.92's variance."""
    rng = np.random.default_rng(5)
    model = CorrelationModel(variance=1.0, decay_per_s=1.0)
    a = math.exp(-0.5)  # readings every 0.5 s of an exponential process, 100 s records
    shocks = rng.normal(0, math.sqrt(1 - a * a), (4000, 201))
    x = lfilter([1.0], [1.0, -a], shocks, axis=1, zi=a * rng.normal(size=(4000, 1)))[0]
    k0 = np.mean((x - x.mean(axis=1, keepdims=True)) ** 2, axis=1)
    predicted = correlation_estimate_variance(model, 100.0, interval_s=0.5)
    assert np.var(k0) == pytest.approx(predicted, rel=0.1)


def test_sampling_advice_flags_correlated_observations() -> None:
    model = CorrelationModel(variance=1.0, decay_per_s=0.05)
    advice = sampling_advice(model, 3600.0, observation_interval_s=30.0)
    assert advice.observation_correlation == pytest.approx(math.exp(-1.5))
    assert advice.correlated
    assert not sampling_advice(model, 3600.0, observation_interval_s=60.0).correlated


def test_characterise_noise_end_to_end() -> None:
    rng = np.random.default_rng(6)
    n, dt = 2**15, 0.1
    t = np.arange(n) * dt
    x = ou(rng, n, dt, 0.05, 0.01) + rng.normal(0, 0.005, n)
    x += 0.01 * np.sin(2 * np.pi * t / 60.0)  # the simulator's spurious harmonic, 60 s period
    result = characterise_noise(x, dt, observation_interval_s=10.0)
    (harmonic,) = result.harmonics.harmonics
    assert harmonic.frequency_hz == pytest.approx(1 / 60, rel=1e-3)
    assert harmonic.amplitude == pytest.approx(0.01, rel=0.15)
    assert harmonic.amplitude_from_correlation == pytest.approx(0.01, rel=0.15)
    # the harmonic's a^2/2 cos(nu tau) is removed before the model is fitted
    assert result.exponential.decay_per_s == pytest.approx(0.05, rel=0.3)
    assert result.exponential.variance == pytest.approx(1e-4, rel=0.3)
    assert result.sampling.correlated  # e^(-0.05 * 10) = 0.61
    json.dumps(result.to_dict())
