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

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.errors import AnalysisError


def variance_inflation(rho: np.ndarray, n: int) -> float:
    """f = 1 + 2 sum_{k=1}^{N-1} (1 - k/N) rho_k, rho[k - 1] the correlation at lag k (lags
    beyond the array count as uncorrelated)."""
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
