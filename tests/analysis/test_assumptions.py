"""Assumption checks of section 2 against data built to satisfy or violate them."""

import warnings

import numpy as np
import pytest
from scipy import stats

from gyrostand.analysis.assumptions import independence_check, ljung_box_lag1, normality_check
from gyrostand.analysis.trials import TrialInput


def trials_from(series: np.ndarray) -> list[TrialInput]:
    """Pairs of rows as the before/under series of successive trials."""
    return [
        TrialInput(i + 1, "fit", 30, 20, 6, before_deg=series[2 * i], under_deg=series[2 * i + 1])
        for i in range(series.shape[0] // 2)
    ]


def ar1(rng: np.random.Generator, phi: float, shape: tuple[int, int]) -> np.ndarray:
    e = rng.normal(size=shape)
    x = np.empty(shape)
    x[:, 0] = e[:, 0] / np.sqrt(1 - phi**2)
    for t in range(1, shape[1]):
        x[:, t] = phi * x[:, t - 1] + e[:, t]
    return x


def test_ljung_box_by_hand() -> None:
    x = np.array([1.0, 3.0, 2.0, 5.0, 4.0])
    d = x - 3.0
    r1 = (d[:-1] @ d[1:]) / (d @ d)
    assert ljung_box_lag1(x) == pytest.approx(5 * 7 * r1**2 / 4)


def test_normal_independent_readings_pass() -> None:
    rng = np.random.default_rng(5)
    trials = trials_from(rng.normal(0, 0.01, (20, 30)))
    normality, independence = normality_check(trials, 0.05), independence_check(trials, 0.05)
    assert normality.holds and independence.holds
    assert len(normality.series) == 20
    # the per-series figures are scipy's Shapiro-Wilk
    assert normality.series[0].p_value == pytest.approx(stats.shapiro(trials[0].before_deg)[1])


def test_skewed_readings_fail_normality() -> None:
    rng = np.random.default_rng(6)
    check = normality_check(trials_from(rng.exponential(0.01, (20, 30))), 0.05)
    assert check.holds is False and check.p_value < 1e-6


def test_a_series_with_p_zero_rejects_with_a_finite_statistic() -> None:
    # N = 3 with two equal readings: Shapiro-Wilk's W = 3/4 and p = 0 (here, in floating point)
    series = np.tile([[1.5, -1.3, 1.5], [0.1, 0.2, 0.3]], (2, 1))
    assert stats.shapiro(series[0]).pvalue == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        check = normality_check(trials_from(series), 0.05)
    assert np.isfinite(check.statistic) and check.holds is False
    tiny = np.finfo(float).tiny
    p = [max(c.p_value, tiny) for c in check.series]
    assert check.statistic == pytest.approx(-2 * np.log(p).sum())


def test_correlated_readings_fail_independence() -> None:
    rng = np.random.default_rng(7)
    check = independence_check(trials_from(ar1(rng, 0.6, (20, 30))), 0.05)
    assert check.holds is False and check.verdict == "violated"


def test_pre_averaged_input_is_not_checked() -> None:
    trials = [TrialInput(1, "fit", 30, 20, 6, delta_mean_deg=0.1, delta_var_deg2=1e-4, n_obs=5)]
    check = normality_check(trials, 0.05)
    assert check.holds is None and check.verdict == "not checked"
    assert "pre-averaged" in check.detail
