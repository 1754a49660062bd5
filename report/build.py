"""The report as one object: its inputs, the analysis results, the trial table in the paper's
form, the forecast grid with its worst case, and the compliance verdicts. Every number a renderer
prints is a field here (or of the `CampaignAnalysis` it holds); renderers only format.
"""

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.adequacy import ADEQUACY_BASIS
from gyrostand.analysis.campaign import CampaignAnalysis
from gyrostand.analysis.forecast import (
    Extrapolation,
    Forecast,
    ForecastGrid,
    TestedRange,
    acceleration_direction_deg,
    forecast_grid,
)
from gyrostand.analysis.quantiles import dof_text, t_quantile
from gyrostand.report.compliance import (
    INCONCLUSIVE,
    NOT_ASSESSED,
    PASS,
    Compliance,
    Profile,
    assess,
)
from gyrostand.report.model import NOT_STATED, ReportInputs
from gyrostand.report.signal import SignalSection, signal_section
from gyrostand.report.worst_case import WorstCase

SCHEMA = "gyrostand.report/5"
COURSE_STEP_DEG = 5.0  # forecast grid
TABLE_COURSE_STEP_DEG = 15.0  # forecast table


@dataclass(frozen=True)
class TrialRow:
    """Section 4, one trial in the paper's form: i, K, A, tau, p = 2 pi / tau (eq 1.1), <delta_i>
    (2.1), S^2{<delta_i>} (2.3), the variance of the mean S^2/N_eff with each series' N_eff =
    N/f (Sveshnikov 8.3; N for independent observations), nu (2.4); alpha_i is the fitted
    value (fit trials) or the prediction (control trials), v_i = <delta_i> - alpha_i."""

    index: int
    role: str
    direction_deg: float
    amplitude_cm: float
    period_s: float
    p_rad_s: float
    delta_deg: float
    var_deg2: float | None
    var_mean_deg2: float | None
    dof: int | None
    n_obs: int | None
    n_eff_before: float | None  # N_eff = N/f of each series (correlated observations), else N
    n_eff_under: float | None
    alpha_deg: float
    residual_deg: float


@dataclass(frozen=True)
class GridPoint:
    """One forecast grid point with its (1 - q) interval."""

    course_deg: float
    direction_deg: float
    roll_deg: float
    period_s: float
    latitude_deg: float
    alpha_deg: float
    half_width_deg: float
    extrapolation: Extrapolation | None  # beyond the trials' motion (None: inside it)

    @property
    def bound_deg(self) -> float:
        """|alpha| + half-width: the largest error the interval admits."""
        return abs(self.alpha_deg) + self.half_width_deg


@dataclass(frozen=True)
class ForecastSection:
    """Section 9: the plan's point forecast, the grid over course x roll x period x latitude,
    the table (plan's conditions, every 15 deg of course), the worst course per period and the
    worst case of the whole grid; the motion the trials covered (``tested``), how far the point
    forecast lies beyond it, and the dof of the fit every forecast rests on."""

    tested: TestedRange
    point_extrapolation: Extrapolation | None
    fit_dof: int
    point: Forecast
    grid: ForecastGrid
    amplitude_note: str
    table: tuple[GridPoint, ...]
    worst_by_period: tuple[GridPoint, ...]
    worst: GridPoint


@dataclass(frozen=True)
class MethodCheck:
    """A check of the method as the report states it wherever it appears (page 1, its section,
    the JSON): the verdict and, when an assumption it rests on fails, the caveat beside it."""

    name: str
    verdict: bool | None  # None: not made
    caveat: str | None


def method_checks(analysis: CampaignAnalysis) -> tuple[MethodCheck, ...]:
    """Cochran's homogeneity (eq 2.5), Fisher's adequacy on the trial means (eq 2.8,
    `ADEQUACY_BASIS`) and the control trials against their prediction intervals (eq 2.11).
    Cochran's and Fisher's tests assume independent observations: when the independence check
    fails, their verdicts lean towards acceptance and say so."""
    independence = next((c for c in analysis.assumptions if c.name == "independence"), None)
    leans = (
        None
        if independence is None or independence.holds is not False
        else f"the observations are not independent ({independence.detail}): S_e understates "
        "the scatter and the verdict leans towards acceptance"
    )
    a = analysis.adequacy
    controls = analysis.controls
    return (
        MethodCheck("variances homogeneous (Cochran)", analysis.cochran.homogeneous, leans),
        MethodCheck(
            f"model adequate (Fisher, on the {ADEQUACY_BASIS})",
            a.decision,
            "not tested: Cochran's test rejected homogeneity" if a.decision is None else leans,
        ),
        MethodCheck(
            "control trials within the prediction interval",
            all(c.within_interval for c in controls) if controls else None,
            None if controls else "no control trial",
        ),
    )


@dataclass(frozen=True)
class DegreesOfFreedom:
    """Where each number of degrees of freedom comes from, and the t quantiles of the control
    trials' bounds: ``nu_trial`` of each fit trial's S^2{<delta_i>} (eq 2.4), Cochran's k,
    nu_r = n - m of S^2_r (eq 2.7), nu_e of S^2_e (eq 2.6), t(1 - q/2; nu_r) of the prediction
    interval (eq 2.11) and t(1 - q/2; nu_e) of the S_e bound; ``text`` says it in words."""

    nu_trial: tuple[int, ...]
    n_obs: int | None
    k: int
    n_fit: int
    m: int
    dof_r: int
    dof_e: int
    q: float
    t_prediction: float
    t_s_e_bound: float
    text: str


def degrees_of_freedom(analysis: CampaignAnalysis) -> DegreesOfFreedom:
    fit = [t for t in analysis.trials if t.index in set(analysis.fit_indices)]
    nu = tuple(int(t.dof) for t in fit if t.dof)
    n_obs = fit[0].n_under if fit and len({t.n_under for t in fit}) == 1 else None
    a, q, m = analysis.adequacy, analysis.q, len(analysis.fit.names)
    t_pred = t_quantile(1 - q / 2, a.dof_r)
    t_bound = t_quantile(1 - q / 2, a.dof_e)
    each = (f"nu_i = {nu[0]} for each fit trial" if len(set(nu)) == 1 else f"nu_i = {list(nu)}") + (
        f": S^2{{<delta_i>}} (eq 2.3) adds the variances of two series of N = {n_obs} readings, "
        f"N - 1 = {n_obs - 1} each (eq 2.4)"
        if n_obs
        else " (eq 2.4)"
    )
    text = (
        f"{each}; Cochran's test compares k = {analysis.cochran.k} such variances; "
        f"nu_r = n - m = {analysis.fit.n} - {m} = {a.dof_r} (fit trials less the parameters C "
        f"and T); nu_e = sum(nu_i) / 2 = {a.dof_e}, as the paper's example counts the pooled "
        f"S_e^2 (eq 2.6: N - 1 per trial; both series would give {sum(nu)}). Control trials: "
        f"prediction interval t(1 - q/2; nu_r) = t({1 - q / 2:g}; {a.dof_r}) = {t_pred:.3f}, "
        f"S_e bound t(1 - q/2; nu_e) = t({1 - q / 2:g}; {a.dof_e}) = {t_bound:.3f}"
    )
    if analysis.trial_covariance is not None:  # the generalised fit's decision (`adequacy`)
        text += (
            f". The decision's error variance, the mean variance of V, has nu = "
            f"{dof_text(a.dof_e_mean)} (Welch-Satterthwaite over the parts a trial estimates "
            "from its own observations; a compensation's variance comes from the fit of the "
            "whole record and counts as known)"
        )
    return DegreesOfFreedom(
        nu, n_obs, analysis.cochran.k, analysis.fit.n, m, a.dof_r, a.dof_e, q, t_pred, t_bound, text
    )


@dataclass(frozen=True)
class Conformity:
    """The report's one statement of conformity (ISO/IEC 17025:2017 7.8.6): the overall
    ``verdict`` (PASS, FAIL, INCONCLUSIVE or NOT ASSESSED), the ``statement`` that follows it
    (what it covers; the word itself is not repeated), the ``decision_rule`` applied, and every
    reason that keeps a PASS from being issued."""

    verdict: str
    statement: str
    decision_rule: str
    reasons: tuple[str, ...]


def conformity(
    compliance: Compliance,
    analysis: CampaignAnalysis | None,
    analysis_error: str | None,
    simulated: bool,
    planned_trials: int,
) -> Conformity:
    """The profile's decision (`Compliance.decision`), qualified by what it rests on: a PASS
    is INCONCLUSIVE when trials are missing, a statistical check of the method failed, or the
    instrument was simulated; a FAIL on a verified limit stands whatever else holds."""
    rule = compliance.decision_rule_text
    if analysis is None:
        return Conformity(
            NOT_ASSESSED, f"the campaign could not be analysed ({analysis_error}).", rule, ()
        )
    reasons = []
    if simulated:
        reasons.append("the instrument and the stand were simulated")
    missing = [t.index for t in analysis.left_out if t.superseded_by is None]
    if missing:
        reasons.append(
            f"{len(analysis.trials)} of {planned_trials} planned trials analysed "
            f"(trial {', '.join(map(str, missing))} not)"
        )
    checks = {
        "the trial variances are not homogeneous (Cochran)": not analysis.cochran.homogeneous,
        f"the model is not adequate (Fisher, on the {ADEQUACY_BASIS})": (
            analysis.adequacy.decision is False
        ),
        "a control trial lies outside its prediction interval": any(
            not c.within_interval for c in analysis.controls
        ),
        **{
            f"the assumption of {c.name} is violated": c.holds is False
            for c in analysis.assumptions
            if c.name != "homogeneity"
        },
    }
    reasons += [reason for reason, broken in checks.items() if broken]
    verdict = compliance.decision
    if verdict == PASS and reasons:
        verdict = INCONCLUSIVE
    statement = f"against {compliance.profile_name}: {compliance.summary}."
    if reasons:
        statement += " The result rests on a campaign in which " + "; ".join(reasons) + "."
    return Conformity(verdict, statement, rule, tuple(reasons))


@dataclass(frozen=True)
class Report:
    """``analysis`` is None when the campaign could not be analysed (``analysis_error`` says
    why): the report then documents the acquisition and assesses nothing of the fit. The
    signal analysis (section 10) stands on the raw reading alone."""

    schema: str
    generated_at: str
    inputs: ReportInputs
    analysis: CampaignAnalysis | None
    analysis_error: str | None
    trials: tuple[TrialRow, ...]
    forecast: ForecastSection | None
    compliance: Compliance
    signal: SignalSection
    conformity: Conformity
    checks: tuple[MethodCheck, ...] = ()  # `method_checks`; empty when not analysed
    dof: DegreesOfFreedom | None = None  # `degrees_of_freedom`; None when not analysed
    missing: tuple[str, ...] = ()  # the items of ISO/IEC 17025 7.8.2 it lacks (`missing_items`)
    draft: bool = False  # not for issue: DRAFT on every page (always when ``missing``)

    @property
    def compass_heading(self) -> str:
        """The compass's own heading at rest: the range of its still-series means (eq 2.1)."""
        means = (
            []
            if self.analysis is None
            else [t.before.mean_deg for t in self.analysis.trials if t.before is not None]
        )
        if not means:
            return "not recorded (no still-series readings)"
        lo, hi = min(means), max(means)
        return f"{lo:.3f} to {hi:.3f} deg, the means of the {len(means)} still series (eq 2.1)"

    @property
    def title(self) -> str:
        """The report's own title: the instrument, its serial and the report number."""
        ident = self.inputs.identification
        number = ident.report_number or f"of campaign {ident.campaign_id} (unnumbered)"
        return (
            f"Rolling-error test report {number}: {ident.instrument_model}, serial "
            f"{ident.instrument_serial}"
        )

    @property
    def end_of_report(self) -> str:
        """The line that closes the document (ISO/IEC 17025 7.8.2.1 d)."""
        number = self.inputs.identification.report_number
        return f"End of report {number}" if number else "End of report (unnumbered: a DRAFT)"


def missing_items(inputs: ReportInputs) -> tuple[str, ...]:
    """What a report must identify (ISO/IEC 17025:2017 7.8.2.1) and this one does not state:
    report number, laboratory, customer, the instrument's manufacturer, the dates of the
    trials, and the two sign-offs of the operator station (tested by, checked by). Empty: it
    can be issued as final."""
    ident, signed = inputs.identification, inputs.signatures
    stated = {
        "report number": ident.report_number is not None,
        "laboratory": ident.laboratory != NOT_STATED,
        "customer": ident.customer != NOT_STATED,
        "manufacturer": ident.manufacturer != NOT_STATED,
        "dates of the trials": ident.test_dates != NOT_STATED,
        "sign-off 'tested by'": signed.tested_by is not None,
        "sign-off 'checked by'": signed.checked_by is not None,
    }
    return tuple(item for item, given in stated.items() if not given)


def trial_rows(analysis: CampaignAnalysis) -> tuple[TrialRow, ...]:
    """The trial table: statistics from the analysis, alpha_i and v_i from the fit (fit trials)
    or the control judgement (control trials)."""
    fitted = dict(zip(analysis.fit_indices, analysis.fit.fitted, strict=True))
    residual = dict(zip(analysis.fit_indices, analysis.fit.residuals, strict=True))
    for c in analysis.controls:
        fitted[c.index], residual[c.index] = c.predicted_deg, c.residual_deg
    return tuple(
        TrialRow(
            index=t.index,
            role=t.role,
            direction_deg=t.direction_deg,
            amplitude_cm=t.amplitude_cm,
            period_s=t.period_s,
            p_rad_s=2 * np.pi / t.period_s,  # p of eq 1.1
            delta_deg=t.delta_deg,
            var_deg2=t.var_deg2,
            var_mean_deg2=t.var_mean_deg2,
            dof=t.dof,
            n_obs=t.n_under,
            n_eff_before=t.n_before if t.n_eff_before is None else t.n_eff_before,
            n_eff_under=t.n_under if t.n_eff_under is None else t.n_eff_under,
            alpha_deg=float(fitted[t.index]),
            residual_deg=float(residual[t.index]),
        )
        for t in analysis.trials
    )


def _point(grid: ForecastGrid, at: tuple[int, ...], tested: TestedRange) -> GridPoint:
    c, r, p, lat = at
    amplitude_cm = float(np.radians(grid.roll_deg[r]) * grid.arm_cm)
    return GridPoint(
        course_deg=float(grid.course_deg[c]),
        direction_deg=float(acceleration_direction_deg(grid.course_deg[c], grid.motion)),
        roll_deg=float(grid.roll_deg[r]),
        period_s=float(grid.period_s[p]),
        latitude_deg=float(grid.latitude_deg[lat]),
        alpha_deg=float(grid.alpha_deg[at]),
        half_width_deg=float(grid.half_width_deg[at]),
        extrapolation=tested.beyond(amplitude_cm, float(grid.period_s[p])),
    )


def forecast_section(analysis: CampaignAnalysis, periods_s: tuple[float, ...]) -> ForecastSection:
    """The grid around the plan's forecast conditions: course 0-360 deg every 5 deg, the plan's
    roll angle, arm and latitude, the plan's period and ``periods_s``."""
    point = analysis.forecasts[0]
    ship = point.conditions
    arm_cm, note = ship.arm_cm, f"A = roll angle x arm = {point.amplitude_cm:.4g} cm"
    if ship.amplitude_cm is not None:  # the plan's amplitude overrides theta0 h: keep it
        arm_cm = ship.amplitude_cm / np.radians(ship.roll_deg)
        note = (
            f"A = {ship.amplitude_cm:g} cm as the plan gives it (roll angle x arm would be "
            f"{ship.amplitude_from_roll_cm:.4g} cm)"
        )
    periods = np.unique(np.array([ship.period_s, *periods_s]))
    grid = forecast_grid(
        analysis.predictor,
        course_deg=np.arange(0.0, 360.0 + COURSE_STEP_DEG / 2, COURSE_STEP_DEG),
        roll_deg=(ship.roll_deg,),
        period_s=periods,
        latitude_deg=(ship.latitude_deg,),
        arm_cm=arm_cm,
        motion=ship.motion,
    )
    plan_p = int(np.flatnonzero(periods == ship.period_s)[0])
    in_table = np.flatnonzero(
        (np.mod(grid.course_deg, TABLE_COURSE_STEP_DEG) == 0) & (grid.course_deg < 360)
    )
    bound = np.abs(grid.alpha_deg) + grid.half_width_deg
    tested = analysis.tested_range
    worst_by_period = tuple(
        _point(grid, (int(np.argmax(bound[:, 0, p, 0])), 0, p, 0), tested)
        for p in range(periods.size)
    )
    worst = np.unravel_index(int(np.argmax(bound)), bound.shape)
    return ForecastSection(
        tested=tested,
        point_extrapolation=tested.beyond(point.amplitude_cm, ship.period_s),
        fit_dof=analysis.fit.dof,
        point=point,
        grid=grid,
        amplitude_note=note,
        table=tuple(_point(grid, (int(c), 0, plan_p, 0), tested) for c in in_table),
        worst_by_period=worst_by_period,
        worst=_point(grid, tuple(int(i) for i in worst), tested),
    )


def build_report(
    inputs: ReportInputs,
    analysis: CampaignAnalysis | str,
    profile: Profile,
    *,
    generated_at: str,
    signal: SignalSection | None = None,
    draft: bool = False,
    worst_cases: tuple[WorstCase, ...] = (),
) -> Report:
    """Assemble the report; ``analysis`` is the analysis or, when it failed, the reason.
    ``generated_at`` is the report's only wall-clock field (ISO 8601 text); ``signal`` the
    signal analysis the analysis used (default: made from the inputs' reading record);
    ``worst_cases`` the forecast's worst cases recorded with it (`worst_case.WorstCase`). The
    report is a DRAFT when ``draft`` or when it lacks an item of `missing_items`."""
    if signal is None:
        signal = signal_section(
            inputs.reading, inputs.reading_note, inputs.records, inputs.acceptance
        )
    fitted = None if isinstance(analysis, str) else analysis
    compliance = assess(
        profile,
        fitted,
        None if fitted is None else inputs.plan,
        imported=inputs.identification.source == "import",
        procedures=inputs.procedures,
        worst_cases=worst_cases,
    )
    section = (
        forecast_section(fitted, profile.envelope.forecast_periods_s)
        if fitted is not None and fitted.forecasts
        else None
    )
    error = analysis if isinstance(analysis, str) else None
    missing = missing_items(inputs)
    return Report(
        schema=SCHEMA,
        generated_at=generated_at,
        inputs=inputs,
        analysis=fitted,
        analysis_error=error,
        trials=() if fitted is None else trial_rows(fitted),
        forecast=section,
        compliance=compliance,
        signal=signal,
        conformity=conformity(
            compliance,
            fitted,
            error,
            inputs.identification.simulated,
            len(inputs.plan.trials),
        ),
        checks=() if fitted is None else method_checks(fitted),
        dof=None if fitted is None else degrees_of_freedom(fitted),
        missing=missing,
        draft=draft or bool(missing),
    )
