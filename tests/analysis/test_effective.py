"""Means of correlated observations: N_eff from the correlation function, against AR(1) closed
forms and simulation (fixed seeds), and through a whole campaign's analysis."""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from gyrostand.analysis import paper_example as paper
from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.effective import (
    correlated_series,
    independent_spacing_s,
    touching_correlation,
    variance_inflation,
    window_mean_correlation,
)
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.gyro_model import RollingErrorModel
from gyrostand.analysis.noise import CorrelationModel
from gyrostand.analysis.synthetic import Design, ar1, synthetic_trials
from gyrostand.analysis.trials import TrialInput

RHO, N = 0.5, 12
TRUE = {"C_gcm2s2": 6e7, "T_s": 1.15}
DESIGN = Design(  # six fit trials
    direction_deg=np.array([30.0, 60, 120, 150, 45, 135]),
    amplitude_cm=np.array([20.0, 24, 22, 18, 21, 23]),
    period_s=np.array([3.5, 4.5, 5.5, 6.5, 6.0, 7.0]),
)


def ar1_inflation(rho: float, n: int) -> float:
    """The AR(1) sum 1 + 2 sum (1 - k/N) rho^k in closed form (geometric series)."""
    return (1 + rho) / (1 - rho) - 2 * rho * (1 - rho**n) / (n * (1 - rho) ** 2)


def test_inflation_is_the_ar1_closed_form() -> None:
    for rho, n in ((0.5, 12), (0.9, 5), (-0.3, 20), (0.0, 7)):
        assert variance_inflation(rho ** np.arange(1, n), n) == pytest.approx(
            ar1_inflation(rho, n), rel=1e-12
        )
    assert variance_inflation(np.zeros(3), 12) == 1.0  # lags beyond the array: uncorrelated


def test_variance_of_the_mean_with_n_eff_matches_simulation() -> None:
    """20000 AR(1) series (rho = 0.5, N = 12): the spread of their means is sigma^2 f / N, and
    the bias-corrected estimate from each series' S^2 averages to it; the paper's S^2/N is
    about half of it."""
    x = ar1(RHO, (20000, N), np.random.default_rng(34))
    f = variance_inflation(RHO ** np.arange(1, N), N)
    closed = f / N  # sigma^2 = 1
    assert x.mean(axis=1).var(ddof=1) == pytest.approx(closed, rel=0.03)
    s2 = x.var(axis=1, ddof=1)
    estimated = [correlated_series(v, N, f, "series").var_mean_deg2 for v in s2[:4000]]
    assert np.mean(estimated) == pytest.approx(closed, rel=0.04)
    assert np.mean(s2 / N) < 0.6 * closed  # what S^2{<delta>} = S^2/N (eq 2.3) reports
    series = correlated_series(1.0, N, f, "series")
    assert series.n_eff == pytest.approx(N / f) and series.inflation == f


def test_too_correlated_series_is_refused_in_one_line() -> None:
    with pytest.raises(AnalysisError, match=r"trial 3, series 2: .* \(N_eff <= 1"):
        correlated_series(1.0, 5, 5.0, "trial 3, series 2")


def correlated_campaign(seed: int) -> list[TrialInput]:
    """The design with AR(1) reading noise (rho = 0.5, sigma 0.05 deg) in every series of N."""
    rng = np.random.default_rng(seed)
    roles = ["fit"] * 6
    return synthetic_trials(
        paper.CONSTANTS, DESIGN, roles, **TRUE, sigma_deg=0.05, n_obs=N, rng=rng, rho=RHO
    )


def test_campaign_reports_the_standard_error_the_trial_means_have() -> None:
    """40 campaigns of 6 trials: the spread of each trial mean about the truth over its reported
    sqrt(var_mean) is ~1 with N_eff, sqrt(f (N - 1) / (N - f)) ~ 1.5 too small with the
    paper's S^2/N; S_e and each trial's dof follow."""
    f = variance_inflation(RHO ** np.arange(1, N), N)
    inflation = {i: (f, f) for i in range(1, 7)}
    alpha = RollingErrorModel(paper.CONSTANTS)(DESIGN.conditions, **TRUE)
    z_new, z_old = [], []
    for seed in range(40):
        trials = correlated_campaign(seed)
        new = analyze_campaign(trials, paper.CONSTANTS, start=paper.START, inflation=inflation)
        old = analyze_campaign(trials, paper.CONSTANTS, start=paper.START)
        for s_new, s_old, t, a in zip(new.trials, old.trials, trials, alpha, strict=True):
            z_new.append((s_new.delta_deg - a) / np.sqrt(s_new.var_mean_deg2))
            z_old.append((s_old.delta_deg - a) / np.sqrt(s_old.var_mean_deg2))
            # independent: each series' S^2 corrected by (N - 1)/(N - f), times f/N
            s2 = np.var(t.before_deg, ddof=1) + np.var(t.under_deg, ddof=1)
            assert s_new.var_mean_deg2 == pytest.approx(s2 * (N - 1) / (N - f) * f / N)
            assert s_new.paper_var_mean_deg2 == pytest.approx(s_old.var_mean_deg2)
            assert s_new.n_eff_before == pytest.approx(N / f)
            assert s_new.dof == int(2 * N / f - 2) and s_old.dof == 2 * N - 2
        assert new.cochran.nu == int(2 * N / f - 2)
        assert new.cochran.pooled_variance > old.cochran.pooled_variance
    assert np.std(z_new) == pytest.approx(1.0, abs=0.12)
    assert np.std(z_old) > 1.35


@pytest.mark.parametrize(("tau", "window"), [(20.0, 28.0), (20.0, 60.0), (100.0, 30.0)])
def test_independent_spacing_meets_the_correlation_bound(tau: float, window: float) -> None:
    """The closed form of rho(W) against the double integral by quadrature; rho(W + s) = 0.1 at
    the spacing returned."""
    model = CorrelationModel(2e-4, 1 / tau)
    touching = touching_correlation(window, tau)
    assert touching == pytest.approx(window_mean_correlation(model, window, window, 0.1), rel=1e-8)
    spacing = independent_spacing_s(window, tau)
    assert window_mean_correlation(model, window, window + spacing, 0.1) == pytest.approx(0.1)


def test_spaced_window_means_of_a_simulated_reading_are_independent() -> None:
    """Exponentially correlated readings (AR(1) at 1 s, tau_k = 20 s, fixed seed): the lag-1
    correlation of 28 s window means is ~0.44 end to end and ~0.10 at the spacing returned."""
    tau, window = 20.0, 28
    phi = math.exp(-1 / tau)
    x = lfilter(
        [math.sqrt(1 - phi**2)], [1, -phi], np.random.default_rng(7).standard_normal(400_000)
    )
    spacing = independent_spacing_s(window, tau)
    for step, expected in (
        (window, touching_correlation(window, tau)),
        (window + round(spacing), 0.1),
    ):
        starts = np.arange(0, x.size - window, step)
        csum = np.concatenate([[0.0], np.cumsum(x)])
        means = (csum[starts + window] - csum[starts]) / window  # windows [start, start + W)
        r = np.corrcoef(means[:-1], means[1:])[0, 1]
        assert r == pytest.approx(expected, abs=4 / math.sqrt(means.size))
