"""The variance of a compensated series' mean (issue 34): `analysis.transient.
compensated_mean_se`, and the analysis taking it as the mean's variance (`SeriesSummary.
var_mean_deg2`) instead of S^2/N + s_c^2.

A compensated value is the window mean less the fitted transient, y_k - (row_k - e_j) theta =
R_j + r_k, so the series' mean is the settle point fitted to those same windows plus the mean
residual. S^2/N on top of SE(R_j)^2 counted the observations' scatter twice. Checked by Monte
Carlo on records of the simulated compass's transient (seed 003 eq 2, 5064 s, 0.7) across one
step, as window means of 60 s (settle blocks end to end, then N observations 30 s apart), the
second series compensated after a 20-minute settle, SD of the compensated mean's error over the
RMS reported SE (1 when honest):
- white noise, 1000 records: 0.99 with the new SE, 0.87 with the old sum;
- the reading's exponential correlation (tau_k 20 s, as the simulator's and the shipped plan's),
  exact window-mean covariance, 600 records: 0.99 with the correlation time, 0.88 with one
  inflation factor for the whole record, 0.83 with the old sum.
On the shipped campaign's structure with the simulator's noise (`validation/compensation_noise.py`)
the old sum gave SD/SE 0.72-1.02 (overstated), the trial means 0.91 over 200 whole campaigns.
"""

import math

import numpy as np
import pytest

from gyrostand.analysis.effective import window_means_covariance
from gyrostand.analysis.transient import (
    Segments,
    TransientModel,
    Windows,
    compensated_covariances,
    compensated_mean_se,
    design,
    fit_transient,
    fit_transient_free,
)
from gyrostand.analysis.trials import SeriesSummary, TrialInput, trial_statistics

MODEL = TransientModel(5064.0, 0.7)
WIDTH_S, STEP_S, NOISE_DEG, N = 60.0, 6000.0, 0.01, 5
SEGMENTS = Segments((0.0, STEP_S), (True, False))
OBS = STEP_S + 1200.0 + WIDTH_S / 2 + 90.0 * np.arange(N)  # 20 min of settle blocks, then N
MIDS = np.r_[np.arange(WIDTH_S / 2, STEP_S + 1200.0, WIDTH_S), OBS]
SEGMENT = (MIDS > STEP_S).astype(int)
THETA = np.array([0.0, 0.3, 0.5, -0.2])  # R_0, R_1 (deg), x_0, v_0 of the first series
CLEAN = design(MODEL, SEGMENTS, SEGMENT, MIDS, WIDTH_S) @ THETA


FIRST = MIDS[np.flatnonzero(SEGMENT == 0)[-N:]]  # the first series' "observations": its last N


def _record(rng: np.random.Generator) -> Windows:
    noisy = CLEAN + NOISE_DEG * rng.standard_normal(MIDS.size)
    return Windows(SEGMENT, MIDS, np.full(MIDS.size, WIDTH_S), noisy)


def _ratio(errors: list[float], ses: list[float]) -> float:
    return float(np.std(errors, ddof=1) / math.sqrt(np.mean(np.square(ses))))


def test_the_compensated_mean_se_states_its_spread() -> None:
    rng = np.random.default_rng(34)
    errors, new, old = [], [], []
    for _ in range(1000):
        data = _record(rng)
        fit = fit_transient(MODEL, SEGMENTS, data)
        compensated = data.value_deg[-N:] - fit.transient(1, OBS, WIDTH_S)[0]
        errors.append(float(compensated.mean()) - THETA[1])
        new.append(compensated_mean_se(fit, data, 1, OBS, WIDTH_S))
        old.append(math.sqrt(compensated.var(ddof=1) / N + fit.settle_point(1)[1] ** 2))
    assert 0.94 <= _ratio(errors, new) <= 1.06  # 0.99; the ratio's SD is ~0.023
    assert _ratio(errors, old) < 0.92  # S^2/N + SE(R)^2 counted the scatter twice (0.87)


def test_with_the_correlation_time_the_se_holds_for_correlated_readings() -> None:
    tau_k = 20.0
    half = WIDTH_S / 2
    root = np.linalg.cholesky(window_means_covariance(MIDS - half, MIDS + half, tau_k))
    rng = np.random.default_rng(34)
    errors, sandwich, one_factor, old = [], [], [], []
    for _ in range(600):
        noisy = CLEAN + NOISE_DEG * root @ rng.standard_normal(MIDS.size)
        data = Windows(SEGMENT, MIDS, np.full(MIDS.size, WIDTH_S), noisy)
        fit = fit_transient(MODEL, SEGMENTS, data)
        compensated = noisy[-N:] - fit.transient(1, OBS, WIDTH_S)[0]
        errors.append(float(compensated.mean()) - THETA[1])
        sandwich.append(compensated_mean_se(fit, data, 1, OBS, WIDTH_S, tau_k))
        one_factor.append(compensated_mean_se(fit, data, 1, OBS, WIDTH_S))
        old.append(math.sqrt(compensated.var(ddof=1) / N + fit.settle_point(1)[1] ** 2))
    assert 0.92 <= _ratio(errors, sandwich) <= 1.08  # 0.99; the ratio's SD is ~0.03
    assert _ratio(errors, one_factor) < _ratio(errors, sandwich) - 0.05  # 0.88: overstated
    assert _ratio(errors, old) < 0.9  # 0.83


def test_the_window_means_covariance_is_the_double_integral() -> None:
    """Closed form against scipy's double integral: touching windows, and windows of unequal
    length apart (Sveshnikov eq 8.89's correlation; `effective.touching_correlation`)."""
    from scipy.integrate import dblquad

    from gyrostand.analysis.effective import touching_correlation

    k = window_means_covariance(np.array([0.0, 60.0, 150.0]), np.array([60.0, 120.0, 190.0]), 20.0)
    assert k[0, 1] / k[0, 0] == pytest.approx(touching_correlation(60.0, 20.0), rel=1e-12)

    def integrand(s: float, t: float) -> float:
        return math.exp(-abs(t - s) / 20.0)

    apart = dblquad(integrand, 60.0, 120.0, 150.0, 190.0)[0] / (60.0 * 40.0)
    assert k[1, 2] == pytest.approx(apart, rel=1e-9)
    assert k[2, 1] == k[1, 2]
    alone = dblquad(integrand, 150.0, 190.0, 150.0, 190.0)[0] / 40.0**2
    assert k[2, 2] == pytest.approx(alone, rel=1e-7)  # quad across the kink at t = s


def test_the_free_fit_includes_the_residual_part_and_needs_the_windows() -> None:
    data = _record(np.random.default_rng(3))
    fit = fit_transient_free(TransientModel(0.95 * MODEL.undamped_period_s, 0.7), SEGMENTS, data)
    se = compensated_mean_se(fit, data, 1, OBS, WIDTH_S)
    assert fit.settle_point(1)[1] < se < 1.2 * fit.settle_point(1)[1]
    with pytest.raises(ValueError, match="not all in the record"):
        compensated_mean_se(fit, data, 1, OBS + 1.0, WIDTH_S)


def test_a_series_with_its_own_variance_of_the_mean_keeps_it() -> None:
    """A compensated series' var_mean is its own (not S^2/N, nor S^2/N_eff); the other series
    of the trial keeps eq 2.3 / N_eff; eq 2.3 itself (Cochran's, S_e's basis) is unchanged."""
    before = SeriesSummary(0.0, 4e-4, 5, var_mean_deg2=3e-5)
    under = SeriesSummary(0.2, 2e-4, 5)
    common = {"index": 1, "role": "fit", "direction_deg": 0.0, "amplitude_cm": 20.0}
    trial = TrialInput(**common, period_s=6.0, before=before, under=under)
    plain = trial_statistics(trial)
    assert plain.var_mean_deg2 == pytest.approx(3e-5 + 2e-4 / 5, rel=1e-15)
    assert plain.var_deg2 == pytest.approx(6e-4, rel=1e-15)
    f = 1.5
    correlated = trial_statistics(trial, inflation=(f, f))
    sigma2 = 2e-4 * 4 / (5 - f)  # analysis.effective: E[S^2] = sigma^2 (N - f) / (N - 1)
    assert correlated.var_mean_deg2 == pytest.approx(3e-5 + sigma2 * f / 5, rel=1e-14)
    assert correlated.paper_var_mean_deg2 == pytest.approx(4e-4 / 5 + 2e-4 / 5, rel=1e-15)


def test_the_compensation_covaries_with_the_series_before_it_as_predicted() -> None:
    """Issue 34: the series before a compensated one is not compensated, but its windows are in
    the record that fixes the compensation's period, damping and carried state: the two means
    covary (today's V has 0 there). `compensated_covariances` takes the compensated mean as
    c^T y; checked against the compensation itself, refitted with each window mean moved by
    1e-6 deg: Cov / Var of the compensated mean is then (d^T K b) / (d^T K d), d that gradient,
    b the earlier series' mean, for white and correlated readings. With the plan's period and
    damping held the compensation is linear in the record (exact); with them fitted c is the
    Gauss-Newton form (the residuals' curvature term left out: 4 % here). Monte Carlo on the
    same record: Cov / (SD SD) predicted +0.16, simulated +0.12 +- 0.02 over 2500 records with
    the free fit; -0.042 vs -0.048 +- 0.010 over 10000 with the period and damping held."""
    data = _record(np.random.default_rng(34))
    start = TransientModel(1.05 * MODEL.undamped_period_s, 0.7)
    b = np.zeros(MIDS.size)
    b[np.flatnonzero(SEGMENT == 0)[-N:]] = 1.0 / N  # the mean of the first series' last N
    half = WIDTH_S / 2
    correlated = window_means_covariance(MIDS - half, MIDS + half, 20.0)
    for fitter, rel in (
        (lambda w: fit_transient(MODEL, SEGMENTS, w), 1e-6),
        (lambda w: fit_transient_free(start, SEGMENTS, w), 0.1),
    ):

        def compensated(values: np.ndarray, fitter=fitter) -> float:
            fit = fitter(Windows(data.segment, data.mid_s, data.width_s, values))
            return float(np.mean(values[-N:] - fit.transient(1, OBS, WIDTH_S)[0]))

        d = np.array(
            [
                (compensated(data.value_deg + 1e-6 * e) - compensated(data.value_deg - 1e-6 * e))
                / 2e-6
                for e in np.eye(MIDS.size)
            ]
        )
        fit = fitter(data)
        for tau_k, k in ((None, np.eye(MIDS.size)), (20.0, correlated)):
            (cov,) = compensated_covariances(fit, data, 1, OBS, WIDTH_S, [FIRST], N, tau_k)
            var = compensated_mean_se(fit, data, 1, OBS, WIDTH_S, tau_k) ** 2
            expected = float(d @ k @ b) / float(d @ k @ d)
            assert cov / var == pytest.approx(expected, rel=rel)
    (cov,) = compensated_covariances(fit, data, 1, OBS, WIDTH_S, [FIRST], N)  # free fit, white
    se = compensated_mean_se(fit, data, 1, OBS, WIDTH_S)
    assert cov / (se * NOISE_DEG / math.sqrt(N)) > 0.1  # correlation 0.14: not negligible


def test_a_series_partly_in_the_record_covaries_through_its_windows_there() -> None:
    """A series resumed after a restart has only its last observations in the record that
    compensates a later one: its mean over all N covaries with the compensation through those
    alone, 1/N each (the others are in another run's record: independent). The named windows,
    not the segment's last N, whatever else the segment holds; a window not in the record is
    refused rather than silently dropped."""
    data = _record(np.random.default_rng(7))
    fit = fit_transient_free(MODEL, SEGMENTS, data)
    one = compensated_covariances(fit, data, 1, OBS, WIDTH_S, [[m] for m in FIRST], 1, 20.0)
    both = compensated_covariances(fit, data, 1, OBS, WIDTH_S, [FIRST, FIRST[2:]], N, 20.0)
    assert both == pytest.approx((sum(one) / N, sum(one[2:]) / N), rel=1e-12)
    early = MIDS[:N]  # the segment's first windows: another covariance (the transient's start)
    (other,) = compensated_covariances(fit, data, 1, OBS, WIDTH_S, [early], N, 20.0)
    assert abs(other - both[0]) > 0.1 * abs(both[0])
    with pytest.raises(ValueError, match="not all in the record"):
        compensated_covariances(fit, data, 1, OBS, WIDTH_S, [FIRST + 1.0], N, 20.0)
