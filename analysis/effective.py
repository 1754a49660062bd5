"""Means of correlated observations: the effective number of observations (Sveshnikov §8.3).

The paper's S^2{<delta>} = S^2/N (Potemkin eq 2.3 per series) holds for independent
observations. When successive observations of a series are correlated, rho_k at lag k (from the
reading's fitted correlation function), the variance of their mean is

    D[mean] = sigma^2 / N * f,   f = 1 + 2 sum_{k=1}^{N-1} (1 - k/N) rho_k,

the sampled form of the double integral of K over the record behind eq 8.93; N_eff = N / f is
the number of independent observations that would give the same variance. The sample variance
S^2 of the N observations is then biased low, E[S^2] = sigma^2 (N - f) / (N - 1) (Bayley &
Hammersley 1946), so sigma^2 is estimated by S^2 (N - 1) / (N - f).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gyrostand.analysis.errors import AnalysisError

if TYPE_CHECKING:  # numpy on demand too: `plan check` uses the closed forms, no arrays
    import numpy as np

    from gyrostand.analysis.noise import CorrelationModel

MAX_CORRELATION = 0.1  # successive observations more correlated break the tests' independence


def variance_inflation(rho: np.ndarray, n: int) -> float:
    """f = 1 + 2 sum_{k=1}^{N-1} (1 - k/N) rho_k, rho[k - 1] the correlation at lag k (lags
    beyond the array count as uncorrelated)."""
    import numpy as np

    rho = np.asarray(rho, dtype=float)[: n - 1]
    k = np.arange(1, rho.size + 1)
    return float(1.0 + 2.0 * np.sum((1.0 - k / n) * rho))


@dataclass(frozen=True)
class CorrelatedSeries:
    """One series of N correlated observations: inflation f, N_eff = N/f, the bias-corrected
    single-observation variance sigma^2 and the variance of the mean sigma^2 f / N (deg^2)."""

    n: int
    inflation: float
    n_eff: float
    var_deg2: float
    var_mean_deg2: float


def correlated_series(s2: float, n: int, inflation: float, what: str) -> CorrelatedSeries:
    """The variances of a series with sample variance S^2 (N - 1 divisor) and inflation f."""
    if not n > inflation:
        raise AnalysisError(
            f"{what}: its {n} observations are as good as {n / inflation:.2g} independent ones "
            f"(N_eff <= 1, inflation {inflation:.3g}): their variance cannot be estimated; space "
            "the observations further apart"
        )
    sigma2 = s2 * (n - 1) / (n - inflation)  # E[S^2] = sigma^2 (N - f) / (N - 1)
    return CorrelatedSeries(n, inflation, n / inflation, sigma2, sigma2 * inflation / n)


def window_mean_correlation(
    model: CorrelationModel, window_s: float, step_s: float, dt_s: float
) -> float:
    """Correlation of the means of two windows of length W whose starts are D apart, of a
    reading with correlation ``model`` sampled every ``dt_s``: the double integral of K over the
    two windows (as behind seed 004 eq 8.93),

        cov = (1/W^2) integral_{-W}^{W} (W - |u|) K(D + u) du,

    the variance the same at D = 0 plus the white part s_w^2 dt / W."""
    from scipy.integrate import quad  # on demand: `plan check` imports this module, not scipy

    def averaged(d: float) -> float:
        points = sorted(u for u in {0.0, -d} if -window_s < u < window_s)  # kinks of |u|, K
        integral = quad(
            lambda u: (window_s - abs(u)) * model(d + u),
            -window_s,
            window_s,
            points=points or None,
            limit=200,
        )[0]
        return integral / window_s**2

    variance = averaged(0.0) + model.white_variance * dt_s / window_s
    return float(averaged(step_s) / variance)


def touching_correlation(window_s: float, correlation_time_s: float) -> float:
    """Correlation of the means of two windows of W laid end to end, of a reading with the
    exponential correlation sigma^2 e^(-|tau| / tau_k) (Sveshnikov eq 8.89's model): the double
    integral of `window_mean_correlation` in closed form, x = W / tau_k,

        rho(W) = e^(-x) (cosh x - 1) / (x - 1 + e^(-x)) = (1 - e^(-x))^2 / (2 (x - 1 + e^(-x)))."""
    x = window_s / correlation_time_s
    return math.expm1(-x) ** 2 / (2.0 * (x + math.expm1(-x)))


def independent_spacing_s(
    window_s: float, correlation_time_s: float, max_correlation: float = MAX_CORRELATION
) -> float:
    """The spacing between windows of W from which successive window means of the exponential
    model are correlated at most ``max_correlation`` (0 when end to end already are). Windows
    D >= W apart cover pairs of times at least D - W apart, so the double integral factorises:
    rho(W + s) = rho(W) e^(-s / tau_k) (Sveshnikov §8.3, the correlation of averages behind
    eqs 8.92-8.94), and s = tau_k ln(rho(W) / rho_max). The white part of the reading is left
    out: it only lowers the correlation."""
    ratio = touching_correlation(window_s, correlation_time_s) / max_correlation
    return max(0.0, correlation_time_s * math.log(ratio))


def window_means_covariance(
    start_s: np.ndarray, end_s: np.ndarray, correlation_time_s: float
) -> np.ndarray:
    """Covariance of the means over disjoint windows [start, end) of a reading with the
    exponential correlation e^(-|tau| / tau_k) (unit variance; Sveshnikov eq 8.89's model): the
    double integral behind eq 8.93 in closed form, mu = 1 / tau_k. A window with itself:
    2 (mu W - 1 + e^(-mu W)) / (mu W)^2; windows i before k (end_i <= start_k):
    (e^(-mu (a_k - b_i)) - e^(-mu (a_k - a_i)) - e^(-mu (b_k - b_i)) + e^(-mu (b_k - a_i)))
    / (mu^2 W_i W_k)."""
    import numpy as np

    mu = 1.0 / correlation_time_s
    a, b = np.asarray(start_s, dtype=float), np.asarray(end_s, dtype=float)
    width = b - a
    first = a[:, None] <= a[None, :]  # i before k: the formula with (i, k), else (k, i)
    ai, bi = np.where(first, a[:, None], a[None, :]), np.where(first, b[:, None], b[None, :])
    ak, bk = np.where(first, a[None, :], a[:, None]), np.where(first, b[None, :], b[:, None])
    gap = np.maximum(ak - bi, 0.0)
    between = (
        np.exp(-mu * gap)
        - np.exp(-mu * (ak - ai))
        - np.exp(-mu * (bk - bi))
        + np.exp(-mu * (bk - ai))
    ) / (mu**2 * np.outer(width, width))
    x = mu * width
    np.fill_diagonal(between, 2.0 * (x + np.expm1(-x)) / x**2)
    return between
