"""A whole campaign through the seed-000 method: trial statistics (2.1-2.4), Cochran (2.5-2.6),
Gauss-Newton fit of model 1.1 (1.2-1.10), adequacy (2.7-2.8), control trials and forecasts
(2.10-2.11), and the assumption checks of section 2.

Entry point::

    analyze_campaign(trials, constants, *, q=0.05, start=(7e7, 0.55), admissible=None,
                     forecast=None, eps=None, eps_se=1e-3, n_repeat=None) -> CampaignAnalysis

The admissible region (the plan's prior range of C and T) is not imposed on the fit: an estimate
outside it is reported unconstrained, with a warning. (The paper's own example states
T = 0.1..1 s, yet its data put T near 1.15 s; clipping would bias the fit and its adequacy test.)
The fit's hard bounds are the physical domain C > 0, T >= 0; Gauss-Newton leaving them, diverging
or stalling hands the fit to the bounded trust-region path, and the result says so.

``CampaignAnalysis.to_dict()`` returns plain JSON types (no NaN: missing values are null):

- ``schema``: "gyrostand.analysis/1"; ``q``; ``variance_basis``; ``sign_convention``;
- ``constants``: lP_gcm2s2, H1_gcm2s, earth_rate_rad_s, gravity_cm_s2, latitude_deg;
- ``trials``: per trial index, role, direction_deg, amplitude_cm, period_s, delta_deg,
  var_deg2 (eq 2.3), var_mean_deg2 (variance of the mean difference), dof (2.4), n_before,
  n_under, before / under ({mean_deg, var_deg2, n} or null), source, n_eff_before, n_eff_under
  and paper_var_mean_deg2 (S1^2/N1 + S2^2/N2; all three null unless the observations are
  correlated, when var_deg2, var_mean_deg2 and dof use N_eff: `analysis.effective`);
- ``cochran``: g_ex, g_critical, q, nu, k, homogeneous, largest (trial index), pooled_variance
  (S^2_e of 2.6, deg^2), s_e (deg);
- ``fit``: parameters, start, estimates, std_errors, covariance, correlation, xtx_inv,
  trial_indices, fitted_deg, residuals_deg (observed - fitted), rss, s2, n, dof, iterations,
  converged, reason, path, fallback_reason, condition_number, log (per Gauss-Newton iteration:
  iteration, theta, step, rss, s2, f_p = s2 / S^2_e), trial_covariance_deg2 (null: the paper's
  independent trial means, eq 1.6; else the fit trials' covariance V with the compensations'
  shared period and damping error, and the fit, rss, s2 and covariance are generalised least
  squares on it: `analysis.gls`);
- ``adequacy``: s2_r, dof_r, s2_e, dof_e, f_p, f_critical, p_value, adequate, s2_e_mean, f_p_mean,
  p_value_mean, adequate_mean_basis, q, dof_e_mean (of s2_e_mean: dof_e, or under a generalised
  fit its Welch-Satterthwaite dof, null when infinite: V known), f_critical_mean (the decision's
  F_T) (see `analysis.adequacy`);
- ``error_agreement``: f_p (S^2_r over S^2_e/N), dof_r, dof_e, p_low (its lower tail), q,
  too_small (the residual variance implausibly small: a warning says so);
- ``controls``: per control trial index, direction_deg, amplitude_cm, period_s, observed_deg,
  predicted_deg, residual_deg, residual_over_s_e, s_e_bound_deg, within_s_e_bound,
  half_width_deg, within_interval;
- ``assumptions``: per check name, method, statistic, p_value, holds, verdict, detail, series;
- ``predictor``: constants, C_gcm2s2, T_s, xtx_inv, s2_r, dof, q, n_repeat (rebuild it with
  `Predictor.from_dict` to call `forecast_grid`);
- ``forecasts``: per forecast conditions {roll_deg, arm_cm, period_s, course_deg, latitude_deg,
  motion, amplitude_cm}, direction_deg (K), amplitude_cm (used), alpha_deg, se_deg, se_mean_deg,
  t, half_width_deg, half_width_mean_deg, lower_deg, upper_deg;
- ``admissible``: {C_gcm2s2: [lo, hi], T_s: [lo, hi]} or null; ``warnings``: list of strings;
- ``left_out``: the source's trials not in ``trials``, each index, attempt, role, status,
  reason, superseded_by (a stored campaign's failed trials, attempts superseded by a retry with
  the attempt that replaced them, trials not acquired; empty for a table of trials);
- ``transient``: null, or the compass's transient fitted to a stored campaign's whole record
  (`analysis.transient.TransientCheck`): undamped_period_s, damping_ratio (the plan's),
  plan_contradicted, record_period_s, record_period_se_s, record_damping_ratio,
  record_damping_ratio_se, residual_sd_deg, and per series trial, j,
  compensation_se_deg, left_deg, standard_error_deg, bound_deg.
"""

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields, is_dataclass
from typing import Any

import numpy as np

from gyrostand.analysis.adequacy import (
    ADEQUACY_BASIS,
    Adequacy,
    ControlResult,
    ErrorAgreement,
    adequacy_test,
    error_agreement,
    generalised_dof,
    judge_controls,
)
from gyrostand.analysis.assumptions import (
    AssumptionCheck,
    homogeneity_check,
    independence_check,
    normality_check,
)
from gyrostand.analysis.cochran import CochranResult, cochran_test
from gyrostand.analysis.errors import (
    AnalysisError,
    ConvergenceError,
    MissingDataError,
    SingularDesignError,
    TooFewTrialsError,
    ZeroVarianceError,
)
from gyrostand.analysis.forecast import (
    SIGN_CONVENTION,
    Forecast,
    Predictor,
    ShipConditions,
    TestedRange,
    forecast_ship,
    tested_range,
)
from gyrostand.analysis.gls import (
    Series,
    SharedError,
    control_variances,
    fit_generalised,
    shared_covariance,
    trial_covariance,
)
from gyrostand.analysis.gyro_model import PARAMETERS, Conditions, KnownConstants, RollingErrorModel
from gyrostand.analysis.nlsq import COND_LIMIT, FitResult, fit_nonlinear
from gyrostand.analysis.quantiles import dof_text, t_quantile
from gyrostand.analysis.transient import TransientCheck
from gyrostand.analysis.trials import TrialInput, TrialStats, trial_statistics

VARIANCE_BASIS = (
    "S^2{<delta_i>} = S1^2 + S2^2 (eq 2.3, single-observation variances) for Cochran, S_e and "
    "F_p; var_mean = S1^2/N1 + S2^2/N2 (variance of <delta_i>) for the trial-mean basis; with "
    "correlated observations N_eff = N/f for N and S^2 corrected for its bias (Sveshnikov "
    "section 8.3), the paper's S1^2/N1 + S2^2/N2 kept as paper_var_mean_deg2"
)
PHYSICAL_BOUNDS = {"C_gcm2s2": (0.0, np.inf), "T_s": (0.0, np.inf)}


@dataclass(frozen=True)
class AdmissibleRegion:
    """The prior range of the parameters (checked and reported, not imposed) and where it
    comes from, as the warnings say it."""

    C_gcm2s2: tuple[float, float]
    T_s: tuple[float, float]
    source: str = "stated in the plan"


@dataclass(frozen=True)
class LeftOutTrial:
    """A trial (one attempt of it) of the source that the analysis did not use, and why."""

    index: int
    attempt: int
    role: str
    status: str
    reason: str  # failed with its failure reason, superseded by a retry, or not acquired
    superseded_by: int | None = None  # the attempt that replaced this one


@dataclass(frozen=True)
class CampaignAnalysis:
    """Everything the seed-000 method concludes about one campaign (see module docstring)."""

    q: float
    constants: KnownConstants
    start: dict[str, float]
    trials: tuple[TrialStats, ...]
    cochran: CochranResult
    fit: FitResult
    fit_indices: tuple[int, ...]
    iteration_f_p: tuple[float, ...]
    adequacy: Adequacy
    error_agreement: ErrorAgreement
    controls: tuple[ControlResult, ...]
    assumptions: tuple[AssumptionCheck, ...]
    predictor: Predictor
    forecasts: tuple[Forecast, ...]
    admissible: AdmissibleRegion | None
    warnings: tuple[str, ...]
    left_out: tuple[LeftOutTrial, ...] = ()  # named by the caller that chose the trials
    transient: TransientCheck | None = None  # by the caller that has the settle records
    # covariance of the fit trials' means when they share the compensations' period and
    # damping error (`analysis.gls`): the fit is then generalised least squares; None: eq 1.6
    trial_covariance: np.ndarray | None = None

    @property
    def tested_range(self) -> TestedRange:
        """The motion the analysed trials (fit and control) covered: a forecast beyond it is
        an extrapolation of model 1.1."""
        return tested_range(
            [t.amplitude_cm for t in self.trials], [t.period_s for t in self.trials]
        )

    @property
    def estimates(self) -> dict[str, float]:
        return self.fit.estimates

    @property
    def confidence_intervals(self) -> dict[str, tuple[float, float]]:
        """Each parameter's (1 - q) confidence interval: a +- t(1 - q/2; n - 2) S{a}, S{a} by
        eq 1.10 and the t quantile as eq 2.11 takes it."""
        t = t_quantile(1 - self.q / 2, self.fit.dof)
        return {
            name: (value - t * self.fit.std_errors[name], value + t * self.fit.std_errors[name])
            for name, value in self.fit.estimates.items()
        }

    def to_dict(self) -> dict[str, Any]:
        fit = self.fit
        log = [
            {**asdict(record), "f_p": f_p}
            for record, f_p in zip(fit.log, self.iteration_f_p, strict=True)
        ]
        data = {
            "schema": "gyrostand.analysis/1",
            "q": self.q,
            "variance_basis": VARIANCE_BASIS,
            "sign_convention": SIGN_CONVENTION,
            "constants": asdict(self.constants),
            "trials": [asdict(t) for t in self.trials],
            "cochran": asdict(self.cochran),
            "fit": {
                "parameters": list(fit.names),
                "start": self.start,
                "estimates": fit.estimates,
                "std_errors": fit.std_errors,
                "confidence_intervals": self.confidence_intervals,
                "covariance": fit.covariance,
                "correlation": fit.correlation,
                "xtx_inv": fit.xtx_inv,
                "trial_indices": list(self.fit_indices),
                "fitted_deg": fit.fitted,
                "residuals_deg": fit.residuals,
                "rss": fit.rss,
                "s2": fit.s2,
                "n": fit.n,
                "dof": fit.dof,
                "iterations": fit.iterations,
                "converged": fit.converged,
                "reason": fit.reason,
                "path": fit.path,
                "fallback_reason": fit.fallback_reason,
                "condition_number": fit.condition_number,
                "log": log,
                "trial_covariance_deg2": self.trial_covariance,
            },
            "adequacy": {
                **asdict(self.adequacy),
                "basis": ADEQUACY_BASIS,
                "decision": self.adequacy.decision,
            },
            "error_agreement": asdict(self.error_agreement),
            "controls": [asdict(c) for c in self.controls],
            "assumptions": [{**asdict(a), "verdict": a.verdict} for a in self.assumptions],
            "predictor": self.predictor.to_dict(),
            "forecasts": [
                {
                    **asdict(f),
                    "lower_deg": f.interval_deg[0],
                    "upper_deg": f.interval_deg[1],
                }
                for f in self.forecasts
            ],
            "admissible": asdict(self.admissible) if self.admissible else None,
            "warnings": list(self.warnings),
            "left_out": [asdict(t) for t in self.left_out],
            "transient": None if self.transient is None else self.transient.to_dict(),
        }
        return json_safe(data)


def json_safe(value: Any) -> Any:
    """Plain JSON types: numpy scalars/arrays to floats/lists, tuples to lists, NaN/inf to None."""
    if is_dataclass(value) and not isinstance(value, type):
        return json_safe({f.name: getattr(value, f.name) for f in fields(value)})
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [json_safe(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else None
    return value


def _fit_trials(stats: tuple[TrialStats, ...]) -> list[TrialStats]:
    """The fitted trials, checked: enough of them, each with a positive variance."""
    indices = [s.index for s in stats]
    duplicated = [i for i, n in Counter(indices).items() if n > 1]
    if duplicated:
        raise AnalysisError(f"trial {duplicated[0]} appears more than once")
    fit = [s for s in stats if s.role == "fit"]
    m = len(PARAMETERS)
    if len(fit) < m + 1:
        raise TooFewTrialsError(
            f"{len(fit)} fit trials for {m} parameters: need at least {m + 1} (n - m >= 1)"
        )
    for s in fit:
        if s.var_deg2 is None:
            raise MissingDataError(f"trial {s.index}: a fit trial needs its variance (eq 2.3)")
        if s.var_deg2 == 0:
            raise ZeroVarianceError(
                f"trial {s.index}: variance S^2{{<delta_i>}} (eq 2.3) is zero: identical readings"
                " (stuck or coarsely quantised sensor?)"
            )
    return fit


def _conditions(stats: Sequence[TrialStats]) -> Conditions:
    return Conditions(
        direction_deg=np.array([s.direction_deg for s in stats]),
        amplitude_cm=np.array([s.amplitude_cm for s in stats]),
        period_s=np.array([s.period_s for s in stats]),
    )


def _check_design(model: RollingErrorModel, x: Conditions, theta0: dict[str, float]) -> None:
    """Refuse designs where X^T X is singular whatever C and T are."""
    alpha = model(x, **theta0)
    if np.all(np.abs(alpha) < 1e-12):
        raise SingularDesignError(
            "the model predicts no error in any fit trial (sin 2K = 0 or A = 0 in every one: "
            f"K = {sorted(set(x.direction_deg.tolist()))} deg): C and T cannot be estimated"
        )
    if np.unique(x.period_s).size == 1:
        raise SingularDesignError(
            f"all fit trials share one period tau = {x.period_s[0]} s: the partials x1 and x2 "
            "(eq 1.4) are proportional, X^T X is singular; rock at two periods at least"
        )
    jac = model.jacobian(x, **theta0)
    norms = np.linalg.norm(jac, axis=0)
    cond = float(np.linalg.cond(jac / norms)) if np.all(norms > 0) else np.inf
    if not cond < COND_LIMIT:
        raise SingularDesignError(f"X^T X is near-singular (condition number of X {cond:.3g})")


def analyze_campaign(
    trials: Sequence[TrialInput],
    constants: KnownConstants,
    *,
    q: float = 0.05,
    start: tuple[float, float] = (7e7, 0.55),
    admissible: AdmissibleRegion | None = None,
    forecast: ShipConditions | Sequence[ShipConditions] | None = None,
    eps: dict[str, float] | None = None,
    eps_se: float = 1e-3,
    n_repeat: int | None = None,
    independence: AssumptionCheck | None = None,
    inflation: Mapping[int, tuple[float, float]] | None = None,
    shared: Mapping[Series, SharedError] | None = None,
) -> CampaignAnalysis:
    """Run the seed-000 method on a campaign.

    independence: the check of independent observations when the caller has better evidence
    than the N observations themselves (the reading's correlation function, report.signal);
    default the lag-1 Ljung-Box test on the series.
    inflation: per trial index, the variance inflation f of its series before and under rocking
    (`analysis.effective`, from the reading's correlation function): each mean's variance, S_e,
    Cochran's and Fisher's tests then take N_eff = N/f observations per series.
    shared: per compensated series (trial index, j), its share in the period and damping error
    its compensation used (`analysis.gls`): the fit is then generalised least squares on the
    trial means' covariance, and S^2_r, the SEs, the intervals and Fisher's test are its.
    q: significance level of every test; start: (C0 in g cm^2 s^-2, T0 in s); eps: absolute
    thresholds of eq 1.8 per parameter (default: eps_se x the standard error at the iterate, i.e.
    steps below 0.1 % of a standard error); n_repeat: N of the mean-of-N prediction variant
    (default: the fit trials' series length)."""
    if not 0 < q < 1:
        raise AnalysisError(f"significance level q = {q} must lie in (0, 1)")
    theta0 = dict(zip(PARAMETERS, map(float, start), strict=True))
    if not (theta0["C_gcm2s2"] > 0 and theta0["T_s"] > 0):
        # at T = 0 the model is flat in T (dalpha/dT = 0): Gauss-Newton could never move T
        raise AnalysisError(f"start values must have C > 0 and T > 0, got {theta0}")
    inflation = inflation or {}
    stats = tuple(trial_statistics(t, inflation.get(t.index)) for t in trials)
    fit_stats = _fit_trials(stats)
    labels = [s.index for s in fit_stats]
    dofs = [s.dof for s in fit_stats]
    if any(s.n_eff_before is not None for s in fit_stats):
        dofs = [min(dofs)] * len(dofs)  # effective dof differ a little: the smallest, for all
    cochran = cochran_test([s.var_deg2 for s in fit_stats], dofs, q=q, labels=labels)
    model = RollingErrorModel(constants)
    x = _conditions(fit_stats)
    _check_design(model, x, theta0)
    y = [s.delta_deg for s in fit_stats]
    var_mean = [float(s.var_mean_deg2) for s in fit_stats]  # type: ignore[arg-type]
    control_stats = [s for s in stats if s.role == "control"]
    shared_part = shared_covariance(shared or {}, labels)
    covariance = None if shared_part is None else trial_covariance(var_mean, shared_part)
    full_covariance = None  # V of the fit trials and the controls, for the controls' intervals
    control_var_mean = [s.var_mean_deg2 for s in control_stats]
    if covariance is not None and control_stats and None not in control_var_mean:
        everyone = shared_covariance(shared or {}, labels + [s.index for s in control_stats])
        full_covariance = trial_covariance(var_mean + control_var_mean, everyone)  # type: ignore[arg-type, operator]
        full_covariance[: len(labels), : len(labels)] = covariance  # the fit's own
    options: dict[str, Any] = {
        "jacobian": model.jacobian,
        "bounds": PHYSICAL_BOUNDS,
        "x_scale": {k: max(abs(v), 1e-12) for k, v in theta0.items()},
        "eps": eps,
        "eps_se": eps_se,
    }
    if covariance is None:  # the paper's independent trial means: eq 1.6
        fit = fit_nonlinear(model, x, y, theta0, **options)
    else:  # eqs 1.6, 1.9-1.10 generalised: X^T X -> X^T (V/v)^-1 X, r^T r -> r^T (V/v)^-1 r
        fit = fit_generalised(model, x, y, theta0, covariance, **options)
    if not fit.converged:
        error = SingularDesignError if "degenerate" in fit.reason else ConvergenceError
        raise error(f"the fit of C and T failed: {fit.reason}")

    s2_e = cochran.pooled_variance  # eq 2.6
    dof_e = sum(dofs) // 2  # n (N - 1), as the paper's example (N_eff for N when correlated)
    dof_e_mean = None  # the independent means: S^2_e / N, nu_e
    if covariance is not None:
        parts = [s.own_variance for s in fit_stats]
        dof_e_mean = generalised_dof(parts, float(np.trace(covariance)))
    adequacy = adequacy_test(
        fit.s2,  # eq 2.7 = eq 1.9 at the solution
        fit.dof,
        s2_e,
        float(np.mean(var_mean if covariance is None else np.diag(covariance))),
        dof_e,
        q=q,
        homogeneous=cochran.homogeneous,
        generalised=covariance is not None,
        dof_e_mean=dof_e_mean,
    )
    predictor = Predictor(
        constants=constants,
        C_gcm2s2=fit.estimates["C_gcm2s2"],
        T_s=fit.estimates["T_s"],
        xtx_inv=tuple(tuple(float(v) for v in row) for row in fit.xtx_inv),
        s2_r=fit.s2,
        dof=fit.dof,
        q=q,
        n_repeat=n_repeat or Counter(s.n_under for s in fit_stats).most_common(1)[0][0],
    )
    x_control = _conditions(control_stats)
    control_var = None
    if full_covariance is not None:
        x_c = model.jacobian(x_control, **fit.estimates)
        control_var = control_variances(fit.jacobian, x_c, full_covariance, fit.xtx_inv, fit.s2)
    controls = judge_controls(
        predictor,
        x_control,
        np.array([s.delta_deg for s in control_stats]),
        [s.index for s in control_stats],
        s_e=cochran.s_e,
        dof_e=dof_e,
        variance_deg2=control_var,
    )
    assumptions = (
        normality_check(trials, q),
        independence or independence_check(trials, q),
        homogeneity_check(cochran),
    )
    if forecast is None:
        ships: Sequence[ShipConditions] = ()
    else:
        ships = (forecast,) if isinstance(forecast, ShipConditions) else forecast
    agreement = error_agreement(adequacy)
    return CampaignAnalysis(
        q=q,
        constants=constants,
        start=theta0,
        trials=stats,
        cochran=cochran,
        fit=fit,
        fit_indices=tuple(labels),
        iteration_f_p=tuple(r.s2 / s2_e for r in fit.log),
        adequacy=adequacy,
        error_agreement=agreement,
        controls=controls,
        assumptions=assumptions,
        predictor=predictor,
        forecasts=tuple(forecast_ship(predictor, ship) for ship in ships),
        admissible=admissible,
        warnings=_warnings(fit, cochran, adequacy, agreement, assumptions, admissible),
        trial_covariance=covariance,
    )


def _warnings(
    fit: FitResult,
    cochran: CochranResult,
    adequacy: Adequacy,
    agreement: ErrorAgreement,
    assumptions: tuple[AssumptionCheck, ...],
    admissible: AdmissibleRegion | None,
) -> tuple[str, ...]:
    """Plain-language cautions a report must carry."""
    found = []
    if fit.path != "gauss-newton":
        found.append(f"Gauss-Newton failed ({fit.fallback_reason}); trust-region result used")
    if admissible is not None:
        for name in PARAMETERS:
            lo, hi = getattr(admissible, name)
            value = fit.estimates[name]
            if not lo <= value <= hi:
                symbol, unit = ("T", " s") if name == "T_s" else ("C", " g cm^2 s^-2")
                found.append(
                    f"{symbol} = {value:.6g}{unit} lies outside the admissible region "
                    f"[{lo:g}, {hi:g}]{unit} {admissible.source}; reported unconstrained"
                )
    if not cochran.homogeneous:
        found.append(
            f"trial variances are not homogeneous (Cochran G_ex = {cochran.g_ex:.4f} >= "
            f"G* = {cochran.g_critical:.4f}; trial {cochran.largest}): S_e and the adequacy "
            + (
                "test are not valid"
                if adequacy.decision is None
                else "test on the paper's basis are not valid (the generalised fit's test, on "
                "the trial means, weighs each by its own variance)"
            )
        )
    if adequacy.decision is False:
        found.append(
            f"the model is NOT adequate on the trial means (F_p = {adequacy.f_p_mean:.3g} >= "
            f"F_T = {adequacy.f_critical_mean:.3g})"
            + (
                f"; the paper's single-observation basis would accept it (F_p = {adequacy.f_p:.3g})"
                if adequacy.adequate
                else ""
            )
        )
    if adequacy.decision is not None and agreement.too_small:  # tested: homogeneous, or GLS
        found.append(
            f"the residual variance is implausibly small: S^2_r = {adequacy.s2_r:.3g} is "
            f"{agreement.f_p:.3g} times the error of the trial means S^2_e/N = "
            f"{adequacy.s2_e_mean:.3g} deg^2 (P(F({agreement.dof_r}, "
            f"{dof_text(agreement.dof_e)}) <= {agreement.f_p:.3g}) = {agreement.p_low:.2g} "
            f"< q = {agreement.q:g}): the two "
            f"estimates of error disagree, and the t({agreement.dof_r}) intervals, which rest "
            "on S^2_r, may be too narrow"
        )
    for check in assumptions:
        if check.holds is False and check.name != "homogeneity":
            found.append(f"assumption of {check.name} violated: {check.detail}")
    return tuple(found)
