"""Cochran's test of the homogeneity of trial variances (seed 000 eqs 2.5-2.6)."""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.errors import (
    AnalysisError,
    NonFiniteError,
    TooFewTrialsError,
    UnequalDegreesOfFreedomError,
    ZeroVarianceError,
)


def cochran_critical(q: float, nu: int, k: int) -> float:
    """Critical value G* of Cochran's statistic for k variances with nu degrees of freedom each.

    G* = 1 / (1 + (k - 1) / F), F the upper q/k quantile of F(nu, (k - 1) nu). Exact whenever
    G* >= 1/2 (then at most one variance can exceed G* of the sum, so P(G > g) = k P(one ratio
    > g), and each ratio is a Beta(nu/2, (k-1)nu/2) variable); below 1/2 it is the Bonferroni
    bound used by the classical tables, conservative by far less than their rounding at q <= 0.1.
    """
    from scipy import stats

    if not 0 < q < 1:
        raise AnalysisError(f"significance level q = {q} must lie in (0, 1)")
    if int(nu) != nu or nu < 1:
        raise AnalysisError(f"degrees of freedom nu = {nu} must be a positive integer")
    if int(k) != k or k < 2:
        raise AnalysisError(f"number of variances k = {k} must be an integer >= 2")
    f = stats.f.isf(q / k, nu, (k - 1) * nu)
    return float(1.0 / (1.0 + (k - 1) / f))


@dataclass(frozen=True)
class CochranResult:
    """Cochran's test (2.5) and the pooled experimental error (2.6).

    ``largest`` is the label of the trial with the largest variance: the one that breaks
    homogeneity when ``homogeneous`` is False. ``pooled_variance`` (2.6) is the mean of the
    variances; it is a valid estimate of the experimental error only when ``homogeneous``."""

    g_ex: float
    g_critical: float
    q: float
    nu: int
    k: int
    homogeneous: bool
    largest: int
    pooled_variance: float
    s_e: float


def cochran_test(
    variances: Sequence[float] | np.ndarray,
    dof: Sequence[int] | np.ndarray,
    *,
    q: float = 0.05,
    labels: Sequence[int] | None = None,
) -> CochranResult:
    """Test the k trial variances (each with its dof) for homogeneity at level q (eq 2.5)."""
    s2 = np.asarray(variances, dtype=float)
    nu = np.asarray(dof)
    labels = list(range(1, s2.size + 1)) if labels is None else list(labels)
    if s2.size < 2:
        raise TooFewTrialsError(f"Cochran's test needs at least 2 variances, got {s2.size}")
    bad = np.flatnonzero(~np.isfinite(s2))
    if bad.size:
        raise NonFiniteError(f"trial {labels[bad[0]]}: variance is not finite")
    if np.any(s2 < 0):
        raise AnalysisError(f"trial {labels[int(np.flatnonzero(s2 < 0)[0])]}: negative variance")
    if np.any(nu != nu[0]):
        i = int(np.flatnonzero(nu != nu[0])[0])
        raise UnequalDegreesOfFreedomError(
            f"Cochran's test needs equal degrees of freedom: trial {labels[0]} has {nu[0]}, "
            f"trial {labels[i]} has {nu[i]}"
        )
    total = float(s2.sum())
    if total == 0:
        raise ZeroVarianceError("every trial variance is zero: Cochran's statistic is undefined")
    i_max = int(np.argmax(s2))
    g_ex = float(s2[i_max] / total)  # eq 2.5
    g_crit = cochran_critical(q, int(nu[0]), s2.size)
    pooled = total / s2.size  # eq 2.6
    return CochranResult(
        g_ex=g_ex,
        g_critical=g_crit,
        q=q,
        nu=int(nu[0]),
        k=s2.size,
        homogeneous=g_ex < g_crit,
        largest=labels[i_max],
        pooled_variance=pooled,
        s_e=float(np.sqrt(pooled)),
    )
