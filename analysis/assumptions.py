"""Checks of the assumptions seed 000 section 2 requires before regression: readings within a
series are normal and independent, and the trial variances are homogeneous (Cochran, eq 2.5).

Normality: Shapiro-Wilk per series (N >= 3), combined over series by Fisher's method.
Independence: lag-1 Ljung-Box statistic Q = N (N + 2) r1^2 / (N - 1) per series, ~chi2(1) under
independence; their sum over series is ~chi2(number of series). Both need raw observations; with
pre-averaged input they are reported as not checked.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyrostand.analysis.cochran import CochranResult
from gyrostand.analysis.trials import TrialInput


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


def _raw_series(
    trials: Sequence[TrialInput],
) -> dict[int, tuple[list[tuple[int, str]], np.ndarray]]:
    """Raw series with N >= 3 readings and non-zero spread, grouped by N: labels and (m, N)."""
    groups: dict[int, tuple[list[tuple[int, str]], list[tuple[float, ...]]]] = {}
    for trial in trials:
        if trial.before_deg is None:
            continue
        for label, values in (("before", trial.before_deg), ("under", trial.under_deg)):
            if len(values) >= 3 and max(values) > min(values):
                labels, rows = groups.setdefault(len(values), ([], []))
                labels.append((trial.index, label))
                rows.append(values)
    return {n: (labels, np.array(rows)) for n, (labels, rows) in groups.items()}


def _not_checked(
    name: str, method: str, trials: Sequence[TrialInput], need: str
) -> AssumptionCheck:
    if all(t.before_deg is None for t in trials):
        need = "raw observations not available (pre-averaged input)"
    return AssumptionCheck(name, method, None, None, None, need)


def _series_checks(
    groups: dict[int, tuple[list[tuple[int, str]], np.ndarray]], test: Any
) -> tuple[SeriesCheck, ...]:
    """Apply a vectorised test(rows) -> (statistics, p-values) to each group of equal N."""
    checks = []
    for n, (labels, rows) in groups.items():
        statistic, p = test(rows)
        checks += [
            SeriesCheck(i, label, n, float(s), float(pv))
            for (i, label), s, pv in zip(labels, statistic, p, strict=True)
        ]
    return tuple(checks)


def normality_check(trials: Sequence[TrialInput], q: float) -> AssumptionCheck:
    """Shapiro-Wilk per series, Fisher-combined."""
    from scipy import stats

    method = "Shapiro-Wilk per series, Fisher-combined"
    groups = _raw_series(trials)
    if not groups:
        return _not_checked("normality", method, trials, "no series with N >= 3 and spread")
    checks = _series_checks(groups, lambda rows: stats.shapiro(rows, axis=-1))
    # Shapiro-Wilk's p at N = 3 is 0 at W = 3/4 (two equal readings) and Fisher's -2 sum log p
    # would be infinite: such a series counts as p = the smallest positive double.
    p_values = np.maximum([c.p_value for c in checks], np.finfo(float).tiny)
    combined = stats.combine_pvalues(p_values, method="fisher")
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


def ljung_box_lag1(x: np.ndarray) -> np.ndarray:
    """Ljung-Box Q at lag 1 along the last axis: N (N + 2) r1^2 / (N - 1), r1 the lag-1
    autocorrelation."""
    d = x - x.mean(axis=-1, keepdims=True)
    r1 = np.sum(d[..., :-1] * d[..., 1:], axis=-1) / np.sum(d * d, axis=-1)
    n = x.shape[-1]
    return n * (n + 2) * r1**2 / (n - 1)


def independence_check(trials: Sequence[TrialInput], q: float) -> AssumptionCheck:
    """Lag-1 Ljung-Box per series, summed over series."""
    from scipy import stats

    method = "lag-1 autocorrelation (Ljung-Box Q) per series, summed"
    groups = _raw_series(trials)
    if not groups:
        return _not_checked("independence", method, trials, "no series with N >= 3 and spread")

    def test(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q_stat = ljung_box_lag1(rows)
        return q_stat, stats.chi2.sf(q_stat, 1)

    checks = _series_checks(groups, test)
    total = float(sum(c.statistic for c in checks))
    p = float(stats.chi2.sf(total, len(checks)))
    rejected = sum(c.p_value < q for c in checks)
    return AssumptionCheck(
        "independence",
        method,
        total,
        p,
        p >= q,
        f"{rejected} of {len(checks)} series show lag-1 correlation at q = {q}",
        checks,
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
