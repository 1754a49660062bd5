"""Checks of the assumptions seed 000 section 2 requires before regression: readings within a
series are normal and independent, and the trial variances are homogeneous (Cochran, eq 2.5).

Normality: Shapiro-Wilk per series (N >= 3), combined over series by Fisher's method.
Independence: lag-1 Ljung-Box statistic Q = N (N + 2) r1^2 / (N - 1) per series, ~chi2(1) under
independence; their sum over series is ~chi2(number of series). Both need raw observations; with
pre-averaged input they are reported as not checked.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from analysis.cochran import CochranResult
from analysis.trials import TrialInput


@dataclass(frozen=True)
class SeriesCheck:
    """One series' statistic and p-value (series: "before" or "under" rocking)."""

    trial: int
    series: str
    n: int
    statistic: float
    p_value: float


@dataclass(frozen=True)
class AssumptionCheck:
    """One assumption: its method, overall statistic and p-value, and whether it holds at q
    (``holds`` is None when it could not be checked; ``detail`` says why)."""

    name: str
    method: str
    statistic: float | None
    p_value: float | None
    holds: bool | None
    detail: str
    series: tuple[SeriesCheck, ...] = ()

    @property
    def verdict(self) -> str:
        return {True: "holds", False: "violated", None: "not checked"}[self.holds]


def _raw_series(trials: Sequence[TrialInput], min_n: int) -> list[tuple[int, str, np.ndarray]]:
    """Raw series with at least min_n readings and non-zero spread."""
    found = []
    for trial in trials:
        if trial.before_deg is None:
            continue
        for label, values in (("before", trial.before_deg), ("under", trial.under_deg)):
            x = np.asarray(values)
            if x.size >= min_n and np.ptp(x) > 0:
                found.append((trial.index, label, x))
    return found


def _not_checked(
    name: str, method: str, trials: Sequence[TrialInput], need: str
) -> AssumptionCheck:
    if all(t.before_deg is None for t in trials):
        need = "raw observations not available (pre-averaged input)"
    return AssumptionCheck(name, method, None, None, None, need)


def normality_check(trials: Sequence[TrialInput], q: float) -> AssumptionCheck:
    """Shapiro-Wilk per series, Fisher-combined."""
    method = "Shapiro-Wilk per series, Fisher-combined"
    series = _raw_series(trials, 3)
    if not series:
        return _not_checked("normality", method, trials, "no series with N >= 3 and spread")
    checks = tuple(
        SeriesCheck(i, label, x.size, *map(float, stats.shapiro(x))) for i, label, x in series
    )
    combined = stats.combine_pvalues([c.p_value for c in checks], method="fisher")
    rejected = sum(c.p_value < q for c in checks)
    return AssumptionCheck(
        "normality",
        method,
        float(combined.statistic),
        float(combined.pvalue),
        bool(combined.pvalue >= q),
        f"{rejected} of {len(checks)} series reject normality at q = {q}",
        checks,
    )


def ljung_box_lag1(x: np.ndarray) -> float:
    """Ljung-Box Q at lag 1: N (N + 2) r1^2 / (N - 1), r1 the lag-1 autocorrelation."""
    d = x - x.mean()
    r1 = float(d[:-1] @ d[1:] / (d @ d))
    return x.size * (x.size + 2) * r1**2 / (x.size - 1)


def independence_check(trials: Sequence[TrialInput], q: float) -> AssumptionCheck:
    """Lag-1 Ljung-Box per series, summed over series."""
    method = "lag-1 autocorrelation (Ljung-Box Q) per series, summed"
    series = _raw_series(trials, 3)
    if not series:
        return _not_checked("independence", method, trials, "no series with N >= 3 and spread")
    checks = []
    for i, label, x in series:
        q_stat = ljung_box_lag1(x)
        checks.append(SeriesCheck(i, label, x.size, q_stat, float(stats.chi2.sf(q_stat, 1))))
    total = sum(c.statistic for c in checks)
    p = float(stats.chi2.sf(total, len(checks)))
    rejected = sum(c.p_value < q for c in checks)
    return AssumptionCheck(
        "independence",
        method,
        total,
        p,
        p >= q,
        f"{rejected} of {len(checks)} series show lag-1 correlation at q = {q}",
        tuple(checks),
    )


def homogeneity_check(cochran: CochranResult) -> AssumptionCheck:
    """Cochran's test (2.5) restated as an assumption check."""
    relation = "<" if cochran.homogeneous else ">="
    detail = f"G_ex = {cochran.g_ex:.4f} {relation} G* = {cochran.g_critical:.4f}"
    if not cochran.homogeneous:
        detail += f"; trial {cochran.largest} has the outlying variance"
    return AssumptionCheck(
        "homogeneity",
        f"Cochran (q = {cochran.q}, nu = {cochran.nu}, k = {cochran.k})",
        cochran.g_ex,
        None,
        cochran.homogeneous,
        detail,
    )
