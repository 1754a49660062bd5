"""Fleet statistics: do some tested units of one instrument model have a parameter (C, T) that
the type's random scatter cannot explain? Sveshnikov, section 8.2 (the closing paragraph, before
section 8.3): units made at different factories (or lots, or tested on different stands) may
differ systematically; since measurement errors and true values are normal, Fisher's analysis of
variance applies (his formulas (29)-(33)), and in some cases Smirnov's two-sample test.

Entry point::

    analyze_fleet(units, *, factor, q=0.05) -> FleetAnalysis

Each unit brings its estimates of C and T and their standard errors (from its campaign's fit).
For each parameter:

- one-way analysis of variance between the groups of the factor (factory, lot, stand): the
  between-group mean square against the within-group mean square, F test at level q.
  **The within-group variance is the units' scatter about their group means** (Fisher's S²
  within, N - k degrees of freedom), not the units' standard errors: units of one type differ
  really (the type's scatter, Sveshnikov's "random scatter according to the parameter's
  distribution law"), and their estimates add measurement error on top; both are in the scatter,
  while the SEs hold only the second, so an F built on the SEs would call the type's own scatter
  a group difference. The SEs give the split (Fisher's random-effects reading of the analysis of
  variance): E[Q2] = (N - k) σ²_type + Σ_j Σ_i (1 - 1/n_j) σ²_ji, so the measurement share is
  the units' SE² weighted by 1 - 1/n_j over N - k (the plain mean when the groups are equal),
  the rest (S²_within minus it, floored at 0) the type's scatter, both reported. The type's
  variance is unbiased only as far as the units' SE² are unbiased for their measurement error:
  SEs that understate it (a fit with few residual degrees of freedom, correlated readings, an
  inadequate model) move their shortfall into the type's share; its square root is biased low
  and floored at 0; its 1 - q confidence interval is S²_within's chi-square interval
  (Satterthwaite's degrees of freedom) less the measurement share (`fleet simulate` checks the
  split against the known truth);
- which groups differ, step down: while the F test of the groups still in (their means against
  the fleet's within-group mean square, N - k degrees of freedom) rejects at q, the group whose
  mean lies farthest from the others' (Student t of the contrast) is set apart; when the last
  two differ, both are (two groups that differ from each other do not tell which one is odd);
  each group's t against the rest of the fleet is reported too;
- Smirnov's two-sample test (Kolmogorov-Smirnov, its exact p-value: analysis.smirnov) of each
  group against the rest of the fleet, at level q / k (Bonferroni over the k groups);
- each unit against the type's prediction interval formed from the other units (leave-one-out:
  mean ± t · s · sqrt(1 + 1/(N-1)), Student with N - 2 degrees of freedom), at the fleet-wide
  level q: each unit at q / N (Bonferroni), so that a fleet without an odd unit shows none with
  probability at least 1 - q.

This module is pure computation (numpy, scipy).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from gyrostand.analysis.quantiles import chi2_quantile, f_quantile, f_sf, t_quantile
from gyrostand.analysis.smirnov import smirnov_test

PARAMETERS = (("C_gcm2s2", "C", "g·cm²·s⁻²"), ("T_s", "T", "s"))


class FleetError(ValueError):
    """The fleet cannot be analysed as given (one line naming why)."""


@dataclass(frozen=True)
class FleetUnit:
    """One tested unit: its campaign, serial, group (the factor's value) and fitted C, T with
    their standard errors; `when` the campaign's start (ISO 8601), for the control chart."""

    campaign_id: int
    serial: str
    group: str
    c_gcm2s2: float
    c_se: float
    t_s: float
    t_se: float
    when: str | None = None

    def value(self, parameter: str) -> tuple[float, float]:
        """(estimate, standard error) of `parameter` ("C_gcm2s2" or "T_s")."""
        if parameter == "C_gcm2s2":
            return self.c_gcm2s2, self.c_se
        return self.t_s, self.t_se


@dataclass(frozen=True)
class GroupStats:
    group: str
    n: int
    mean: float
    sd: float | None
    """Units' scatter about the group mean (None for a single unit)."""
    rms_se: float
    """Root mean square of the units' standard errors (their measurement share)."""
    t_vs_rest: float
    """(group mean - mean of the other units) / sqrt(S²_within (1/n + 1/n_rest))."""
    differs: bool
    """Set apart by the step-down F tests (see the module doc)."""


@dataclass(frozen=True)
class Anova:
    """One-way analysis of variance (Fisher) between and within the groups."""

    k: int
    n: int
    grand_mean: float
    q_between: float
    q_within: float
    dof_between: int
    dof_within: int
    s2_between: float
    s2_within: float
    f: float
    f_critical: float
    p_value: float
    q: float
    groups_differ: bool
    s2_measurement: float
    """The units' SE² weighted by 1 - 1/n_j over N - k (the measurement share of the
    within-group variance; their mean when the groups are equal)."""
    s2_type: float
    """S²_within - s2_measurement, floored at 0: the type's own unit-to-unit scatter."""
    s2_type_dof: float
    """Satterthwaite's degrees of freedom of S²_within (N - k when the units are measured
    equally precisely; fewer when some are far less precise)."""
    s2_type_interval: tuple[float, float]
    """Its 1 - q confidence interval: S²_within's chi-square interval (`s2_type_dof`) less
    the measurement share taken as known, floored at 0."""

    @property
    def verdict(self) -> str:
        relation = ">" if self.groups_differ else "<="
        outcome = "the groups differ" if self.groups_differ else "no difference between groups"
        return f"F = {self.f:.3g} {relation} F* = {self.f_critical:.3g}: {outcome}"


@dataclass(frozen=True)
class SmirnovTest:
    """Smirnov's two-sample test of one group against the rest of the fleet."""

    group: str
    n: int
    n_rest: int
    statistic: float
    p_value: float
    q_each: float
    differs: bool


@dataclass(frozen=True)
class UnitCheck:
    """One unit against the prediction interval of the type formed from the other units."""

    campaign_id: int
    serial: str
    group: str
    when: str | None
    value: float
    se: float
    center: float
    half_width: float
    t_statistic: float
    outside: bool


@dataclass(frozen=True)
class ParameterAnalysis:
    parameter: str
    symbol: str
    unit: str
    groups: tuple[GroupStats, ...]
    anova: Anova
    smirnov: tuple[SmirnovTest, ...]
    units: tuple[UnitCheck, ...]

    @property
    def outliers(self) -> tuple[UnitCheck, ...]:
        return tuple(u for u in self.units if u.outside)

    def smirnov_verdict(self, test: SmirnovTest) -> str:
        """A group's Smirnov test read beside the analysis of variance: not rejecting for a
        group the analysis of variance sets apart is inconclusive (with few units D has
        little power), not evidence of no difference."""
        if test.differs:
            return "differs from the rest"
        if any(g.differs for g in self.groups if g.group == test.group):
            return "inconclusive: the analysis of variance sets it apart"
        return "no difference found"


@dataclass(frozen=True)
class FleetAnalysis:
    factor: str
    q: float
    n_units: int
    parameters: tuple[ParameterAnalysis, ...]

    def to_dict(self) -> dict[str, object]:
        """Plain JSON types: factor, q, n_units, and per parameter its groups, anova (with
        verdict), smirnov and units (with outside)."""
        return {
            "factor": self.factor,
            "q": self.q,
            "n_units": self.n_units,
            "parameters": [
                {
                    **{k: v for k, v in asdict(p).items() if k != "anova"},
                    "anova": {**asdict(p.anova), "verdict": p.anova.verdict},
                }
                for p in self.parameters
            ],
        }


def _sd(values: np.ndarray) -> float | None:
    return float(np.std(values, ddof=1)) if values.size > 1 else None


def one_way_anova(groups: Sequence[np.ndarray], ses: Sequence[np.ndarray], q: float) -> Anova:
    """Fisher's one-way analysis of variance of `groups` (each an array of unit estimates, with
    the units' standard errors `ses`) at level q."""
    k = len(groups)
    n = sum(g.size for g in groups)
    grand = float(np.concatenate(groups).mean())
    means = [float(g.mean()) for g in groups]
    q_between = sum(g.size * (m - grand) ** 2 for g, m in zip(groups, means, strict=True))  # Q1
    q_within = sum(float(((g - m) ** 2).sum()) for g, m in zip(groups, means, strict=True))  # Q2
    dof_between, dof_within = k - 1, n - k
    s2_between = float(q_between) / dof_between  # S1² = Q1 / (k - 1)
    s2_within = q_within / dof_within  # S2² = Q2 / (N - k)
    f = s2_between / s2_within if s2_within > 0 else math.inf  # F = S1² / S2²
    f_critical = f_quantile(1 - q, dof_between, dof_within)  # F*(1 - q; k-1, N-k)
    p_value = f_sf(f, dof_between, dof_within)
    # E[Q2] = (N - k) σ²_type + Σ_j Σ_i (1 - 1/n_j) σ²_ji (Q2 about the group means)
    s2_measurement = float(sum(((1 - 1 / e.size) * e**2).sum() for e in ses) / dof_within)
    # Satterthwaite's degrees of freedom of S²_within, each group's variance s2_type + its
    # mean SE²: ν' = (Σ (n_j - 1) v_j)² / Σ (n_j - 1) v_j² (ν' = N - k for equal precision)
    s2_type = max(0.0, s2_within - s2_measurement)
    v = [s2_type + float(np.mean(e**2)) for e in ses]
    weights = [g.size - 1 for g in groups]
    dof_type = (
        sum(w * x for w, x in zip(weights, v, strict=True)) ** 2
        / sum(w * x**2 for w, x in zip(weights, v, strict=True))
        if any(v)
        else float(dof_within)
    )
    # ν' S²/χ²(1 - q/2; ν') .. ν' S²/χ²(q/2; ν'), less the measurement share (taken as known)
    low, high = (
        max(0.0, dof_type * s2_within / chi2_quantile(p, dof_type) - s2_measurement)
        for p in (1 - q / 2, q / 2)
    )
    return Anova(
        k=k,
        n=n,
        grand_mean=grand,
        q_between=float(q_between),
        q_within=q_within,
        dof_between=dof_between,
        dof_within=dof_within,
        s2_between=s2_between,
        s2_within=s2_within,
        f=float(f),
        f_critical=f_critical,
        p_value=p_value,
        q=q,
        groups_differ=bool(f > f_critical),
        s2_measurement=s2_measurement,
        s2_type=s2_type,
        s2_type_dof=dof_type,
        s2_type_interval=(low, high),
    )


def _contrast(
    values: dict[str, np.ndarray], group: str, among: Sequence[str], s2_within: float
) -> float:
    """Student t of `group`'s mean against the mean of the other units of the groups `among`."""
    rest = np.concatenate([values[h] for h in among if h != group])
    scale = math.sqrt(s2_within * (1 / values[group].size + 1 / rest.size))
    return float((values[group].mean() - rest.mean()) / scale) if scale > 0 else math.inf


def set_apart(
    values: dict[str, np.ndarray], s2_within: float, dof_within: int, q: float
) -> tuple[str, ...]:
    """The groups that differ, step down: while the groups still in differ by the F test (their
    between-group mean square against the fleet's S²_within), the one with the largest |t|
    against the others is set apart; two that differ are both set apart (their |t| are equal)."""
    remaining, apart = list(values), []
    while len(remaining) >= 2:
        data = [values[g] for g in remaining]
        grand = float(np.concatenate(data).mean())
        s2_between = sum(d.size * (d.mean() - grand) ** 2 for d in data) / (len(data) - 1)  # S1²
        f_critical = f_quantile(1 - q, len(data) - 1, dof_within)
        if s2_within > 0 and s2_between / s2_within <= f_critical:
            break
        if len(remaining) == 2:
            apart.extend(remaining)
            break
        farthest = max(remaining, key=lambda g: abs(_contrast(values, g, remaining, s2_within)))
        apart.append(farthest)
        remaining.remove(farthest)
    return tuple(apart)


def prediction_checks(units: Sequence[FleetUnit], parameter: str, q: float) -> list[UnitCheck]:
    """Each unit against the leave-one-out prediction interval of the type, at q / N each."""
    values = np.array([u.value(parameter)[0] for u in units])
    n = values.size
    level = q / n  # Bonferroni over the N units: fleet-wide level q
    t_critical = t_quantile(1 - level / 2, n - 2)
    checks = []
    for i, unit in enumerate(units):
        others = np.delete(values, i)
        center, sd = float(others.mean()), float(others.std(ddof=1))
        scale = sd * math.sqrt(1 + 1 / (n - 1))  # SD of a new unit about the others' mean
        t_stat = (values[i] - center) / scale if scale > 0 else math.inf
        checks.append(
            UnitCheck(
                campaign_id=unit.campaign_id,
                serial=unit.serial,
                group=unit.group,
                when=unit.when,
                value=float(values[i]),
                se=unit.value(parameter)[1],
                center=center,
                half_width=t_critical * scale,  # Student prediction interval, N - 2 dof
                t_statistic=float(t_stat),
                outside=bool(abs(t_stat) > t_critical),
            )
        )
    return checks


def analyze_fleet(units: Sequence[FleetUnit], *, factor: str, q: float = 0.05) -> FleetAnalysis:
    """Fisher's analysis of variance, Smirnov's tests and the prediction-interval checks of C
    and T over the fleet's units, grouped by their `group` (the value of `factor`)."""
    if not 0 < q < 1:
        raise FleetError(f"q = {q} is not a level between 0 and 1")
    names = sorted({u.group for u in units})
    if len(names) < 2:
        raise FleetError(
            f"the fleet has {len(names)} group{'' if len(names) == 1 else 's'} by {factor}: "
            "at least 2 are needed to compare them"
        )
    if len(units) - len(names) < 2:
        raise FleetError(
            f"{len(units)} units in {len(names)} groups by {factor}: the scatter within the "
            "groups needs at least 2 more units than groups"
        )
    for u in units:
        for parameter, symbol, _ in PARAMETERS:
            value, se = u.value(parameter)
            if not (math.isfinite(value) and math.isfinite(se) and se >= 0):
                raise FleetError(
                    f"campaign {u.campaign_id} (serial {u.serial}): {symbol} = {value} ± {se} "
                    "is not a finite estimate with a standard error"
                )
    results = []
    for parameter, symbol, unit_name in PARAMETERS:
        values = {
            g: np.array([u.value(parameter)[0] for u in units if u.group == g]) for g in names
        }
        ses = {g: np.array([u.value(parameter)[1] for u in units if u.group == g]) for g in names}
        anova = one_way_anova([values[g] for g in names], [ses[g] for g in names], q)
        apart = set_apart(values, anova.s2_within, anova.dof_within, q)
        groups = [
            GroupStats(
                group=g,
                n=int(values[g].size),
                mean=float(values[g].mean()),
                sd=_sd(values[g]),
                rms_se=float(np.sqrt(np.mean(ses[g] ** 2))),
                t_vs_rest=_contrast(values, g, names, anova.s2_within),
                differs=g in apart,
            )
            for g in names
        ]
        smirnov = []
        for g in names:
            rest = np.concatenate([values[h] for h in names if h != g])
            test = smirnov_test(values[g], rest)  # Smirnov's two-sample statistic D
            smirnov.append(
                SmirnovTest(
                    group=g,
                    n=int(values[g].size),
                    n_rest=int(rest.size),
                    statistic=test.statistic,
                    p_value=test.p_value,
                    q_each=q / len(names),
                    differs=test.p_value < q / len(names),
                )
            )
        results.append(
            ParameterAnalysis(
                parameter=parameter,
                symbol=symbol,
                unit=unit_name,
                groups=tuple(groups),
                anova=anova,
                smirnov=tuple(smirnov),
                units=tuple(prediction_checks(units, parameter, q)),
            )
        )
    return FleetAnalysis(factor=factor, q=q, n_units=len(units), parameters=tuple(results))
