"""The report as one self-contained HTML document: Jinja2 template with autoescape on (operator
text and every stored string come out inert), CSS inline, plots inline as SVG data URIs.

The template only formats: every number is a field of the `Report` or of its `CampaignAnalysis`.
"""

import re
from importlib.resources import files

from jinja2 import Environment, FileSystemBytecodeCache, PackageLoader, StrictUndefined
from markupsafe import Markup, escape

from gyrostand.analysis.adequacy import ADEQUACY_BASIS_TEXT
from gyrostand.analysis.forecast import SIGN_CONVENTION
from gyrostand.report import plots
from gyrostand.report.build import COURSE_STEP_DEG, Report
from gyrostand.report.compliance import (
    DECISIONS,
    FAIL,
    INCONCLUSIVE,
    PASS,
    PREDICTION,
    UNVERIFIED,
)
from gyrostand.report.model import TrialAcquisition
from gyrostand.report.signal import TIME_SAVED_NOTE

TEMPLATES = files("gyrostand.report") / "templates"


def fmt(value: float | int | None, spec: str = "g", scale: float = 1.0) -> str:
    """A number in the given format (``scale`` divides it first, for columns in 1e-4 units);
    a dash when there is none."""
    if value is None:
        return "\u2013"
    text = format(value / scale if scale != 1.0 else value, spec)
    if text[:1] in "+-" and not text.strip("+-0.e"):  # no signed zero: "-0.000" -> "0.000"
        text = text[1:]
    return text


def sci(value: float | None, digits: int = 4) -> Markup:
    """4.1234 x 10^7 with a real superscript."""
    if value is None:
        return Markup("\u2013")
    mantissa, exponent = f"{value:.{digits}e}".split("e")
    return Markup(f"{escape(mantissa)}\u00d710<sup>{int(exponent)}</sup>")


def level(q: float) -> str:
    """The confidence level 1 - q as a percentage."""
    return f"{1 - q:.0%}"


BADGES = {
    PASS: "pass",
    FAIL: "fail",
    UNVERIFIED: "unverified",
    INCONCLUSIVE: "unverified",
    PREDICTION: "na",
}
"""The badge class of each verdict text (others: grey)."""


def verdict(value: bool | str | None, yes: str = "yes", no: str = "NO") -> Markup:
    """A verdict as a coloured badge: True/PASS green, False/FAIL red, UNVERIFIED and
    INCONCLUSIVE amber, None, NOT ASSESSED and PREDICTION grey."""
    if isinstance(value, str):
        text, kind = value, BADGES.get(value, "na")
    elif value is None:
        text, kind = "not assessed", "na"
    else:
        text, kind = (yes, "pass") if value else (no, "fail")
    return Markup(f'<span class="badge {kind}">{escape(text)}</span>')


GREEK = {"alpha": "\u03b1", "delta": "\u03b4", "sigma": "\u03c3", "tau": "\u03c4", "nu": "\u03bd"}
NOTATION = (
    (re.compile(r"&lt;=|<="), "\u2264"),
    (re.compile(r"&gt;=|>="), "\u2265"),
    (re.compile(r"\b(" + "|".join(GREEK) + r")(?=_|\b)"), lambda m: GREEK[m[1]]),
    (re.compile(r"&lt;(\u03b4_i)&gt;"), "\u27e8\\1\u27e9"),  # <delta_i>: the trial's mean
    # S_e, G_ex, alpha_p: a capital or Greek letter; not plan keys (n_obs, max_wait_s)
    (re.compile(r"(?<!\w)([A-Z\u03b1-\u03c9])_(\w{1,3})\b"), r"\1<sub>\2</sub>"),
    (re.compile(r"\^(-?\d+)"), r"<sup>\1</sup>"),  # m/s^2, A p^2
    (re.compile(r"\+/-"), "\u00b1"),
    (re.compile(r"(?<=deg) x (?=sec)"), " \u00d7 "),  # 0.75 deg x sec(latitude)
)
"""The plain-text notation of the analysis's and the profiles' messages, typeset."""


def notation(text: str) -> Markup:
    """A message written in plain-text notation (S_e, <delta_i>, A p^2 <= 1 m/s^2) as HTML
    with subscripts, superscripts and symbols; the text is escaped first."""
    html = str(escape(text))
    for pattern, replacement in NOTATION:
        html = pattern.sub(replacement, html)
    return Markup(html)


def environment() -> Environment:
    """The Jinja2 environment of the reports: autoescape, strict, the formatting filters."""
    env = Environment(
        loader=PackageLoader("gyrostand.report", "templates"),
        # the compiled templates kept in a per-user temporary folder, checked against their
        # source: compiling the report's template took 0.2 s CPU of every fresh process
        bytecode_cache=FileSystemBytecodeCache(),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters.update(fmt=fmt, sci=sci, verdict=verdict, level=level, notation=notation)
    return env


def _heading_title(t: TrialAcquisition) -> str:
    return (
        f"Trial {t.index} ({t.role}): K = {t.cmd_direction_deg:g} deg, "
        f"A = {t.cmd_amplitude_cm:g} cm, τ = {t.cmd_period_s:g} s (commanded)"
    )


def _figures(report: Report) -> dict[str, object]:
    """Every plot of the report as an <img> element (trusted: made here from numbers only)."""
    trials = {t.index: t for t in report.inputs.acquisition}
    figures: dict[str, object] = {
        "headings": {
            r.index: Markup(plots.heading_plot(r, _heading_title(trials[r.index])))
            for r in report.inputs.records
            if r.trace is not None or any(s.observations for s in r.series)
        },
    }
    noise = report.signal.noise
    if noise is not None:
        figures["correlation"] = Markup(plots.correlation_plot(noise))
        figures["spectrum"] = Markup(plots.spectrum_plot(noise))
        figures["allan"] = Markup(plots.allan_plot(noise))
    a = report.analysis
    if a is None:
        return figures
    bound = a.controls[0].s_e_bound_deg if a.controls else None  # as the controls were judged
    figures["measured"] = Markup(plots.measured_vs_model(report.trials))
    figures["residuals"] = Markup(plots.residuals_plot(report.trials, a.cochran.s_e, bound))
    figures["iterations"] = Markup(plots.iteration_path_plot(a))
    if report.forecast is not None:
        latitude = report.forecast.point.conditions.latitude_deg
        limit = report.compliance.limit_at("rolling_error_forecast", latitude)
        figures["forecast"] = Markup(plots.forecast_plot(report.forecast, limit))
    return figures


def _contents(report: Report) -> list[tuple[str, str]]:
    """The table of contents: (section id, title), in the document's order."""
    results = [
        ("trials", "Trial table"),
        ("reproducibility", "Reproducibility"),
        ("fit", "Fit of model 1.1"),
        ("adequacy", "Adequacy and assumptions"),
        ("controls", "Control trials"),
        ("forecast", "Forecast at sea"),
    ]
    appendices = [("plan-text", "Appendix B: the plan as submitted")]
    if report.analysis is not None:
        appendices.insert(0, ("observations", "Appendix A: every observation"))
    return [
        ("identification", "Identification"),
        ("method", "Method and references"),
        ("plan", "The plan"),
        ("acquisition", "Acquisition summary"),
        *results,
        ("signal", "The reading's random part and the settle points"),
        ("compliance", "Compliance"),
        ("signatures", "Signatures"),
        *appendices,
    ]


def render_html(report: Report) -> str:
    """The whole report as HTML text."""
    template = environment().get_template("report.html.j2")
    css = (TEMPLATES / "report.css").read_text(encoding="utf-8")
    return template.render(
        r=report,
        a=report.analysis,
        sig=report.signal,
        inputs=report.inputs,
        ident=report.inputs.identification,
        figures=_figures(report),
        toc=_contents(report),
        css=Markup(css),
        sign_convention=SIGN_CONVENTION,
        time_saved_note=TIME_SAVED_NOTE,
        course_step_deg=COURSE_STEP_DEG,
        DECISIONS=DECISIONS,
        adequacy_basis=ADEQUACY_BASIS_TEXT,
    )
