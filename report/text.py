"""Plain-text rendering of a `CampaignAnalysis` for the terminal (`gyrostand analyze`): trial
table, the trials left out, Cochran, fit with its Gauss-Newton log, adequacy, control trials,
assumption checks, forecasts and warnings, in the report's symbols (its nomenclature table:
ν, τ, ⟨δᵢ⟩, Sₑ², ...) as Unicode text: `terminal_notation` typesets the analysis's own messages,
written in plain-text notation (nu_e, <delta_i>, S^2, +/-)."""

import re
from collections.abc import Sequence

from gyrostand.analysis.campaign import VARIANCE_BASIS, CampaignAnalysis
from gyrostand.analysis.forecast import SIGN_CONVENTION
from gyrostand.analysis.quantiles import dof_text

GREEK = {
    "alpha": "\u03b1",
    "delta": "\u03b4",
    "sigma": "\u03c3",
    "tau": "\u03c4",
    "nu": "\u03bd",
    "rho": "\u03c1",
}
"""The Greek letters the analysis's messages spell out (the HTML's notation uses them too)."""
SUBSCRIPTS = str.maketrans("0123456789aehijklmnoprstuvx", "₀₁₂₃₄₅₆₇₈₉ₐₑₕᵢⱼₖₗₘₙₒₚᵣₛₜᵤᵥₓ")
SUPERSCRIPTS = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")
_SUB = r"([0-9aehijklmnoprstuvx]{1,3})\b"  # a subscript Unicode has every letter of
TERMINAL_NOTATION = (
    (re.compile(r"<="), "≤"),
    (re.compile(r">="), "≥"),
    (re.compile(r"\+/-"), "±"),
    (re.compile(r"\bsqrt\("), "√("),
    (re.compile(r"\btheta0 ?h\b"), "θ₀h"),  # A = theta0 h: the roll amplitude by the arm
    (re.compile(r"\btheta0\b"), "θ₀"),
    (re.compile(r"\b(" + "|".join(GREEK) + r")(?=_|\b)"), lambda m: GREEK[m[1]]),
    (re.compile(r"<δ_i>"), "⟨δᵢ⟩"),  # the trial's mean difference
    # S^2_e: the subscript, then the power; S_e, nu_r, G_ex, alpha_p (not plan keys: n_obs)
    (
        re.compile(r"(?<!\w)([A-Zα-ω])\^(\d+)_" + _SUB),
        lambda m: m[1] + m[3].translate(SUBSCRIPTS) + m[2].translate(SUPERSCRIPTS),
    ),
    (re.compile(r"(?<!\w)([A-Zα-ω])_" + _SUB), lambda m: m[1] + m[2].translate(SUBSCRIPTS)),
    (re.compile(r"\^(-?\d+)"), lambda m: m[1].translate(SUPERSCRIPTS)),  # deg^2, s^-1
    (re.compile(r"(?<=deg) x (?=sec)|(?<=\(rad\)) x (?=arm)"), " × "),
)
"""Plain-text notation as the terminal shows it (subscripts Unicode lacks, as in F_T or N_eff,
stay written with '_')."""


def terminal_notation(text: str) -> str:
    """A message in plain-text notation (nu_e = 10, S^2_e, <delta_i>, +/-) in the report's
    symbols as Unicode text (νₑ = 10, Sₑ², ⟨δᵢ⟩, ±)."""
    for pattern, replacement in TERMINAL_NOTATION:
        text = pattern.sub(replacement, text)
    return text


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """Right-aligned columns under a rule."""
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True))  # noqa: E731
    return [line(headers), "  ".join("-" * w for w in widths), *(line(r) for r in rows)]


def _opt(value: float | None, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def _verdict(value: bool | None, yes: str, no: str) -> str:
    return "not assessed" if value is None else yes if value else no


PARAMETERS = {"C_gcm2s2": ("C", "g·cm²·s⁻²"), "T_s": ("T", "s")}
"""The model's parameters (the fit's keys) as the report names them: symbol, unit."""


def _symbol(name: str) -> str:
    return PARAMETERS.get(name, (name, ""))[0]


def trials_section(a: CampaignAnalysis) -> list[str]:
    rows = [
        [
            str(t.index),
            t.role,
            f"{t.direction_deg:g}",
            f"{t.amplitude_cm:g}",
            f"{t.period_s:g}",
            f"{t.delta_deg:+.4f}",
            _opt(None if t.var_deg2 is None else t.var_deg2 * 1e4, ".3f"),
            _opt(None if t.var_mean_deg2 is None else t.var_mean_deg2 * 1e4, ".3f"),
            _opt(t.dof, "d"),
        ]
        for t in a.trials
    ]
    headers = ["i", "role", "K deg", "A cm", "τ s", "⟨δᵢ⟩ deg", "S² 10⁻⁴", "S²/N 10⁻⁴", "ν"]
    if any(t.n_eff_under is not None for t in a.trials):  # correlated: N_eff beside eq 2.3
        headers[6:8] = ["S²{⟨δᵢ⟩} 10⁻⁴", "S²/N_eff 10⁻⁴"]
        headers += ["N_eff 1/2", "paper S²/N 10⁻⁴"]
        for row, t in zip(rows, a.trials, strict=True):
            if t.n_eff_under is None:
                row += ["", ""]
                continue
            paper = _opt(t.paper_var_mean_deg2 * 1e4, ".3f")
            row += [f"{t.n_eff_before:.1f}/{t.n_eff_under:.1f}", paper]
    return [
        "TRIALS (eqs 2.1-2.4; variances in 10⁻⁴ deg²)",
        *_table(headers, rows),
        f"variance basis: {terminal_notation(VARIANCE_BASIS)}",
    ]


def left_out_section(a: CampaignAnalysis) -> list[str]:
    return [
        "TRIALS LEFT OUT OF THE ANALYSIS",
        *(
            f"trial {t.index} attempt {t.attempt} ({t.role}, {t.status}): "
            + terminal_notation(t.reason)
            for t in a.left_out
        ),
    ]


def transient_section(a: CampaignAnalysis) -> list[str]:
    t = a.transient
    assert t is not None
    lines = [
        "TRANSIENT LEFT IN EACH SERIES (transient model, Bezvesilna & Gura)",
        f"period {t.undamped_period_s:.0f} s, damping ratio {t.damping_ratio:.3f}: the plan's",
    ]
    if t.record_period_s is not None:
        lines.append(
            f"the record alone: {t.record_period_s:.0f} ± {t.record_period_se_s:.0f} s, "
            f"{t.record_damping_ratio:.3f} ± {t.record_damping_ratio_se:.3f}"
            + (": CONTRADICTS the plan's" if t.plan_contradicted else "")
        )
    rows = [
        [
            str(s.trial),
            str(s.j),
            "no" if s.compensation_se_deg is None else f"SE {s.compensation_se_deg:.4f}",
            f"{s.left_deg:+.4f}",
            f"{s.standard_error_deg:.4f}",
            f"{s.bound_deg:.4f}",
            f"{s.bound_deg / a.cochran.s_e:.2f}",
        ]
        for s in t.series
    ]
    headers = ["i", "j", "compensated", "left deg", "SE deg", "bound deg", "bound/Sₑ"]
    return [*lines, *_table(headers, rows), "bound = |left| + 2 SE"]


def cochran_section(a: CampaignAnalysis) -> list[str]:
    c = a.cochran
    verdict = "homogeneous" if c.homogeneous else f"NOT homogeneous (trial {c.largest})"
    return [
        "COCHRAN TEST (eqs 2.5-2.6)",
        f"Gₑₓ = {c.g_ex:.4f}, G* = {c.g_critical:.4f} (q = {c.q}, ν = {c.nu}, k = {c.k}): "
        f"{verdict}",
        f"Sₑ² = {c.pooled_variance:.4g} deg², Sₑ = {c.s_e:.4f} deg",
    ]


def fit_section(a: CampaignAnalysis) -> list[str]:
    fit = a.fit
    names = fit.names
    rows = [
        [
            str(r.iteration),
            *(f"{r.theta[n]:.7g}" for n in names),
            *(f"{r.step[n]:+.4g}" for n in names),
            f"{r.s2:.4g}",
            f"{f_p:.4g}",
        ]
        for r, f_p in zip(fit.log, a.iteration_f_p, strict=True)
    ]
    symbols = [_symbol(n) for n in names]
    headers = ["d", *(f"{s}_d" for s in symbols), *(f"a({s})" for s in symbols), "S²", "Fₚ"]
    estimates = [
        [
            f"{_symbol(n)}, {PARAMETERS.get(n, (n, '-'))[1]}",
            f"{fit.estimates[n]:.8g}",
            f"{fit.std_errors[n]:.4g}",
            f"{abs(fit.std_errors[n] / fit.estimates[n]):.2%}" if fit.estimates[n] else "-",
        ]
        for n in names
    ]
    state = "converged" if fit.converged else "NOT converged"
    return [
        "FIT OF MODEL 1.1 (Gauss-Newton, eqs 1.2-1.10; S² in deg²)",
        *_table(headers, rows),
        "",
        *_table(["parameter", "estimate", "std error", "rel. SE"], estimates),
        f"S² = {fit.s2:.6g} deg² (ν = {fit.dof}), residual sum of squares {fit.rss:.6g} deg², "
        f"n = {fit.n}, condition number {fit.condition_number:.3g}",
        f"path: {fit.path}, iterations: {fit.iterations}, {state} ({fit.reason})",
        *([f"Gauss-Newton abandoned: {fit.fallback_reason}"] if fit.fallback_reason else []),
        *([] if a.trial_covariance is None else [GENERALISED]),
        *(
            f"{1 - a.q:.0%} confidence interval of {_symbol(n)} (eq 1.10, t as eq 2.11): "
            f"[{lo:.6g}, {hi:.6g}]"
            for n, (lo, hi) in a.confidence_intervals.items()
        ),
        f"correlation(C, T) = {fit.correlation[0, 1]:+.3f}",
    ]


GENERALISED = (
    "generalised least squares: the compensated trial means share the error of the period and "
    "damping their compensations used (Bezvesilna & Gura), so eqs 1.6 and 1.9-1.10 take "
    "Xᵀ(V/v)⁻¹X for XᵀX and rᵀ(V/v)⁻¹r for rᵀr, V the trial means' covariance, v its mean "
    "variance (S² stays in deg²; intervals and Fₚ from this S², ν = n − m as before); a "
    "control trial's prediction variance takes its own variance for eq 2.10's 1, less twice "
    "its covariance with the estimates through V"
)


def adequacy_section(a: CampaignAnalysis) -> list[str]:
    d = a.adequacy
    return [
        "ADEQUACY (eqs 2.7-2.8)",
        f"Sᵣ² = {d.s2_r:.4g} deg² (νᵣ = {d.dof_r}), Sₑ² = {d.s2_e:.4g} deg² "
        f"(νₑ = {d.dof_e}), F_T(1 − {d.q}; {d.dof_r}, {d.dof_e}) = {d.f_critical:.3f}",
        f"the decision, on the trial means (Sₑ²/N = {d.s2_e_mean:.4g} deg², ν = "
        f"{dof_text(d.dof_e_mean)}): Fₚ = {d.f_p_mean:.3f} against F_T = "
        f"{d.f_critical_mean:.3f} (p-value {d.p_value_mean:.3g}): "
        + _verdict(d.decision, "adequate", "NOT adequate"),
        f"for comparison, the paper's basis (eq 2.8): Fₚ = {d.f_p:.3f} "
        f"(p-value {d.p_value:.3g}): "
        + _verdict(d.adequate, "would be adequate", "would NOT be adequate"),
    ]


def controls_section(a: CampaignAnalysis) -> list[str]:
    if not a.controls:
        return ["CONTROL TRIALS", "none"]
    rows = [
        [
            str(c.index),
            f"{c.observed_deg:+.4f}",
            f"{c.predicted_deg:+.4f}",
            f"{c.residual_deg:+.4f}",
            f"{c.residual_over_s_e:+.2f}",
            "yes" if c.within_s_e_bound else "NO",
            f"{c.half_width_deg:.4f}",
            "yes" if c.within_interval else "NO",
        ]
        for c in a.controls
    ]
    bound = a.controls[0].s_e_bound_deg
    return [
        "CONTROL TRIALS (predicted by the fit, eqs 2.10-2.11)",
        *_table(
            ["i", "⟨δᵢ⟩ deg", "αᵢ deg", "vᵢ deg", "vᵢ/Sₑ", "|vᵢ| ≤ bound", "PI ±", "in PI"],
            rows,
        ),
        f"bound = t(1 − q/2; νₑ) Sₑ = {bound:.4f} deg; PI: {1 - a.q:.0%} prediction interval",
    ]


def assumptions_section(a: CampaignAnalysis) -> list[str]:
    lines = ["ASSUMPTIONS (Potemkin 1982, section 2)"]
    for check in a.assumptions:
        stat = "" if check.statistic is None else f", statistic {check.statistic:.4g}"
        p = "" if check.p_value is None else f", p-value {check.p_value:.3g}"
        lines.append(
            terminal_notation(
                f"{check.name}: {check.verdict} ({check.method}{stat}{p}; {check.detail})"
            )
        )
    return lines


def forecasts_section(a: CampaignAnalysis) -> list[str]:
    if not a.forecasts:
        return ["FORECAST", "none requested"]
    lines = ["FORECAST (eqs 1.1, 2.10-2.11)", terminal_notation(SIGN_CONVENTION)]
    for f in a.forecasts:
        s = f.conditions
        lo, hi = f.interval_deg
        given = "" if s.amplitude_cm is None else f" given; θ₀h = {s.amplitude_from_roll_cm:.4g}"
        lines += [
            f"{s.motion} {s.roll_deg:g} deg at arm {s.arm_cm:g} cm (A = {f.amplitude_cm:.4g} cm"
            f"{given}), "
            f"τ = {s.period_s:g} s, course {s.course_deg:g} deg (K = {f.direction_deg:g} deg), "
            f"latitude {s.latitude_deg:g} deg",
            f"αₚ = {f.alpha_deg:+.3f} deg, S = {f.se_deg:.4f} deg, t = {f.t:.3f}: "
            f"{f.alpha_deg:+.3f} ± {f.half_width_deg:.3f} deg [{lo:+.3f}, {hi:+.3f}] "
            f"({1 - a.q:.0%}); mean of N: ± {f.half_width_mean_deg:.3f} deg",
        ]
    return lines


def render_text(analysis: CampaignAnalysis) -> str:
    """The whole analysis as plain text, sections separated by blank lines."""
    sections = [
        trials_section(analysis),
        *([left_out_section(analysis)] if analysis.left_out else []),
        cochran_section(analysis),
        fit_section(analysis),
        adequacy_section(analysis),
        controls_section(analysis),
        assumptions_section(analysis),
        forecasts_section(analysis),
        *([transient_section(analysis)] if analysis.transient else []),
    ]
    if analysis.warnings:
        sections.append(["WARNINGS", *(f"- {terminal_notation(w)}" for w in analysis.warnings)])
    return "\n\n".join("\n".join(s) for s in sections) + "\n"
