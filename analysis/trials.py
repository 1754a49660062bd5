"""Trial inputs and their statistics, seed 000 eqs 2.1-2.4.

Each trial i has a series j=1 of readings before rocking and j=2 under rocking (degrees). A trial
is given in exactly one of three forms:

- raw observations: ``before_deg`` and ``under_deg`` (N1 and N2 readings, N1 may differ from N2);
- per-series summaries: ``before`` and ``under`` (`SeriesSummary`: mean, variance, N);
- the per-trial figures the paper prints: ``delta_mean_deg`` = <delta_i>, ``delta_var_deg2`` =
  S^2{<delta_i>} of eq 2.3 and ``n_obs`` = N per series (variance optional for control trials).

Variance basis: ``var_deg2`` is the paper's eq 2.3, the sum of the two single-observation
variances (what Cochran's test and S_e use); ``var_mean_deg2`` = S1^2/N1 + S2^2/N2 is the variance
of the mean difference <delta_i> itself. Both are kept so a report can show both.

Correlated observations: given each series' variance inflation f (`analysis.effective`, from the
reading's fitted correlation function), S^2 is corrected for its bias, var_mean_deg2 =
sigma1^2 f1/N1 + sigma2^2 f2/N2 (N_eff = N/f in place of N) and dof = N_eff1 + N_eff2 - 2
(rounded down); ``paper_var_mean_deg2`` keeps S1^2/N1 + S2^2/N2 beside it.
"""

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gyrostand.analysis.angles import about, wrap180
from gyrostand.analysis.effective import correlated_series
from gyrostand.analysis.errors import (
    AnalysisError,
    MissingDataError,
    NonFiniteError,
    TooFewObservationsError,
)

ROLES = ("fit", "control")


@dataclass(frozen=True)
class SeriesSummary:
    """A pre-averaged series: mean (2.1) in deg, sample variance (2.2, N-1) in deg^2, and N;
    ``var_mean_deg2`` the variance of the mean when it is known otherwise than as S^2/N (a
    compensated series: its mean is the settle point fitted to the same observations,
    `analysis.transient.compensated_mean_se`; None: S^2/N, or S^2/N_eff when correlated)."""

    mean_deg: float
    var_deg2: float
    n: int
    var_mean_deg2: float | None = None


@dataclass(frozen=True)
class TrialInput:
    """One stand trial: rocking conditions, role, and its observations in one of three forms."""

    index: int
    role: str
    direction_deg: float
    amplitude_cm: float
    period_s: float
    before_deg: tuple[float, ...] | None = None
    under_deg: tuple[float, ...] | None = None
    before: SeriesSummary | None = None
    under: SeriesSummary | None = None
    delta_mean_deg: float | None = None
    delta_var_deg2: float | None = None
    n_obs: int | None = None

    def __post_init__(self) -> None:
        name = f"trial {self.index}"
        if self.role not in ROLES:
            raise AnalysisError(f"{name}: role {self.role!r} must be one of {ROLES}")
        for field in ("direction_deg", "amplitude_cm", "period_s"):
            if not np.isfinite(getattr(self, field)):
                raise NonFiniteError(f"{name}: {field} = {getattr(self, field)} is not finite")
        if self.amplitude_cm < 0 or self.period_s <= 0:
            raise AnalysisError(f"{name}: amplitude must be >= 0 and period > 0")
        forms = [
            self.before_deg is not None or self.under_deg is not None,
            self.before is not None or self.under is not None,
            self.delta_mean_deg is not None or self.delta_var_deg2 is not None,
        ]
        if sum(forms) != 1:
            raise MissingDataError(
                f"{name}: give exactly one of raw series (before_deg, under_deg), series "
                "summaries (before, under), or the trial mean (delta_mean_deg)"
            )
        if forms[0]:
            self._check_raw(name)
        elif forms[1]:
            self._check_summaries(name)
        else:
            self._check_trial(name)

    def _check_raw(self, name: str) -> None:
        for field in ("before_deg", "under_deg"):
            series = getattr(self, field)
            if series is None:
                raise MissingDataError(f"{name}: {field} is missing")
            values = tuple(float(v) for v in series)
            object.__setattr__(self, field, values)
            _check_count(f"{name}, {field}", len(values))
            bad = [k for k, v in enumerate(values) if not np.isfinite(v)]
            if bad:
                raise NonFiniteError(f"{name}: {field}[{bad[0]}] is not finite")

    def _check_summaries(self, name: str) -> None:
        for field in ("before", "under"):
            summary = getattr(self, field)
            if summary is None:
                raise MissingDataError(f"{name}: series summary {field} is missing")
            _check_count(f"{name}, {field}", summary.n)
            _check_value(f"{name}: {field} mean", summary.mean_deg)
            _check_variance(f"{name}: {field} variance", summary.var_deg2)

    def _check_trial(self, name: str) -> None:
        if self.delta_mean_deg is None:
            raise MissingDataError(f"{name}: delta_mean_deg is missing")
        _check_value(f"{name}: delta_mean_deg", self.delta_mean_deg)
        if self.delta_var_deg2 is not None:
            _check_variance(f"{name}: delta_var_deg2", self.delta_var_deg2)
            if self.n_obs is None:
                raise MissingDataError(f"{name}: n_obs is needed with delta_var_deg2")
        if self.n_obs is not None:
            _check_count(f"{name}, n_obs", self.n_obs)


def _check_count(what: str, n: int) -> None:
    if int(n) != n or n < 2:
        raise TooFewObservationsError(f"{what}: N = {n} < 2 observations, variance undefined")


def _check_value(what: str, value: float) -> None:
    if not np.isfinite(value):
        raise NonFiniteError(f"{what} = {value} is not finite")


def _check_variance(what: str, value: float) -> None:
    _check_value(what, value)
    if value < 0:
        raise AnalysisError(f"{what} = {value} is negative")


@dataclass(frozen=True)
class DifferenceStats:
    """Vectorised eqs 2.1-2.4 over k trials: arrays of shape (k,)."""

    delta_deg: np.ndarray
    var_deg2: np.ndarray
    var_mean_deg2: np.ndarray
    dof: np.ndarray


def series_moments(observations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (2.1) and sample variance with N-1 (2.2) along the last axis, of headings taken on
    the branch of each series' first reading (a series across north, 359.9 and 0.1 deg, has the
    mean and variance of its readings)."""
    headings = about(observations[..., :1], observations)
    return headings.mean(axis=-1), headings.var(axis=-1, ddof=1)


def combine_series(m1: Any, v1: Any, n1: Any, m2: Any, v2: Any, n2: Any) -> tuple[Any, ...]:
    """From the series' means, variances and counts (scalars or arrays): <delta_i> = <delta_2i> -
    <delta_1i> wrapped to [-180, 180) (headings), its variance by eq 2.3, the variance of the
    mean difference, and dof by eq 2.4."""
    return wrap180(m2 - m1), v1 + v2, v1 / n1 + v2 / n2, n1 + n2 - 2


def difference_statistics(before: np.ndarray, under: np.ndarray) -> DifferenceStats:
    """Eqs 2.1-2.4 vectorised over (k, N1) and (k, N2) arrays of readings before and under
    rocking."""
    n1, n2 = before.shape[-1], under.shape[-1]
    delta, var, var_mean, dof = combine_series(
        *series_moments(before), n1, *series_moments(under), n2
    )
    return DifferenceStats(delta, var, var_mean, np.full(np.shape(delta), dof))


@dataclass(frozen=True)
class TrialStats:
    """Statistics of one trial. ``var_deg2`` is eq 2.3 (single-observation basis), ``dof`` eq 2.4;
    ``var_mean_deg2`` is the variance of <delta_i>. Variances are None when the input gives none
    (control trials as printed in the paper). ``source`` names the input form."""

    index: int
    role: str
    direction_deg: float
    amplitude_cm: float
    period_s: float
    delta_deg: float
    var_deg2: float | None
    var_mean_deg2: float | None
    dof: int | None
    n_before: int | None
    n_under: int | None
    before: SeriesSummary | None
    under: SeriesSummary | None
    source: str
    n_eff_before: float | None = None  # N/f when the observations are correlated, else None
    n_eff_under: float | None = None
    paper_var_mean_deg2: float | None = None  # S1^2/N1 + S2^2/N2 (eq 2.3 / N) when corrected

    @property
    def own_variance(self) -> tuple[float, float]:
        """The part of ``var_mean_deg2`` estimated from the trial's own few observations (S^2 /
        N_eff of each series whose mean has no variance of its own: not compensated) and its
        degrees of freedom: eq 2.4 with N_eff for two series, N_eff - 1 for one; (0, inf) when
        both series are compensated (their variances come from fits of the whole record)."""
        series = [
            (x, n)
            for x, n in ((self.before, self.n_eff_before), (self.under, self.n_eff_under))
            if x
        ]
        var_mean = float(self.var_mean_deg2)  # type: ignore[arg-type]
        if not series:  # a trial as printed: its variance is its own, nu by eq 2.4
            return var_mean, float(self.dof)  # type: ignore[arg-type]
        known = sum(x.var_mean_deg2 for x, _ in series if x.var_mean_deg2 is not None)
        own = [x.n if n is None else n for x, n in series if x.var_mean_deg2 is None]
        if len(own) == 2:
            return var_mean - known, float(self.dof)  # type: ignore[arg-type]
        return (var_mean - known, max(own[0] - 1.0, 1.0)) if own else (0.0, math.inf)

    @property
    def mean_dof(self) -> float:
        """Degrees of freedom of ``var_mean_deg2`` (what an interval of <delta_i> takes):
        Welch-Satterthwaite with the compensated series' parts known, nu (V / P)^2 for the
        estimated part P with nu dof (`own_variance`); eq 2.4's when no series is compensated,
        inf when both are."""
        part, dof = self.own_variance
        if part <= 0:
            return math.inf
        return dof * (float(self.var_mean_deg2) / part) ** 2  # type: ignore[arg-type]


def _from_summaries(
    common: dict,
    s1: SeriesSummary,
    s2: SeriesSummary,
    inflation: tuple[float, float] | None = None,
) -> TrialStats:
    """Trial statistics from the two series' summaries (and their variance inflations)."""
    delta, var, var_mean, dof = combine_series(
        s1.mean_deg, s1.var_deg2, s1.n, s2.mean_deg, s2.var_deg2, s2.n
    )
    paper_var_mean = var_mean
    if s1.var_mean_deg2 is not None or s2.var_mean_deg2 is not None:
        var_mean = _var_mean(s1, s1.var_deg2 / s1.n) + _var_mean(s2, s2.var_deg2 / s2.n)
    stats = TrialStats(
        **common,
        delta_deg=delta,
        var_deg2=var,
        var_mean_deg2=var_mean,
        dof=dof,
        n_before=s1.n,
        n_under=s2.n,
        before=s1,
        under=s2,
        source="series",
    )
    if inflation is None:
        return stats
    name = f"trial {common['index']}"
    c1, c2 = (
        correlated_series(s.var_deg2, s.n, f, f"{name}, series {j}")
        for j, s, f in ((1, s1, inflation[0]), (2, s2, inflation[1]))
    )
    return replace(
        stats,
        var_deg2=c1.var_deg2 + c2.var_deg2,  # eq 2.3 with sigma^2 for S^2
        # eq 2.3 / N with N_eff for N (a compensated series: its own, `SeriesSummary`)
        var_mean_deg2=_var_mean(s1, c1.var_mean_deg2) + _var_mean(s2, c2.var_mean_deg2),
        dof=max(int(np.floor(c1.n_eff + c2.n_eff - 2)), 1),  # eq 2.4 with N_eff for N
        n_eff_before=c1.n_eff,
        n_eff_under=c2.n_eff,
        paper_var_mean_deg2=paper_var_mean,
    )


def _var_mean(series: SeriesSummary, otherwise: float) -> float:
    """The variance of a series' mean: its own when given (`SeriesSummary`), else ``otherwise``."""
    return otherwise if series.var_mean_deg2 is None else series.var_mean_deg2


def trial_statistics(trial: TrialInput, inflation: tuple[float, float] | None = None) -> TrialStats:
    """Eqs 2.1-2.4 for one trial, whatever its input form; ``inflation`` (f of the series before
    and under rocking) makes a series' N its N_eff = N/f (raw or summarised series only)."""
    common = {
        "index": trial.index,
        "role": trial.role,
        "direction_deg": float(trial.direction_deg),
        "amplitude_cm": float(trial.amplitude_cm),
        "period_s": float(trial.period_s),
    }
    if trial.before_deg is not None:
        before, under = np.array(trial.before_deg), np.array(trial.under_deg)
        s1 = SeriesSummary(*map(float, series_moments(before)), before.size)
        s2 = SeriesSummary(*map(float, series_moments(under)), under.size)
        return replace(_from_summaries(common, s1, s2, inflation), source="observations")
    if trial.before is not None:
        return _from_summaries(common, trial.before, trial.under, inflation)
    n = trial.n_obs
    has_var = trial.delta_var_deg2 is not None
    return TrialStats(
        **common,
        delta_deg=float(trial.delta_mean_deg),
        var_deg2=float(trial.delta_var_deg2) if has_var else None,
        var_mean_deg2=float(trial.delta_var_deg2) / n if has_var else None,
        dof=2 * (n - 1) if n is not None else None,  # eq 2.4, N1 = N2 = N
        n_before=n,
        n_under=n,
        before=None,
        under=None,
        source="trial",
    )
