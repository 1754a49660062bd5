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
from gyrostand.analysis.quantiles import dof_text
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
from gyrostand.report.text import GREEK

TEMPLATES = files("gyrostand.report") / "templates"


def fmt(value: float | int | None, spec: str = "g", scale: float = 1.0) -> str:
    """A number in the given format (``scale`` divides it first, for columns in 1e-4 units);
    a dash when there is none."""
    if value is None:
        return "\u2013"
    text = format(value / scale if scale != 1.0 else value, spec)
    if text[:1] in "+-" and not text.strip("+-0.e"):  # no signed zero: "-0.000" -> "0.000"
        text = text[1:]
    return E_NOTATION.sub(_power_of_ten, text)


E_NOTATION = re.compile(r"(?<=\d)e([+-]?)0*(\d+)$")
SUPERSCRIPT = str.maketrans(
    "0123456789-", "\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079\u207b"
)


def _power_of_ten(match: re.Match[str]) -> str:
    """'e-06' as '×10⁻⁶': a report prints no computer notation (2.23e-07)."""
    sign = "-" if match[1] == "-" else ""
    return "\u00d710" + (sign + match[2]).translate(SUPERSCRIPT)


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


NOTATION = (
    (re.compile(r"&lt;=|<="), "\u2264"),
    (re.compile(r"\btheta0\b"), "\u03b8<sub>0</sub>"),  # A = theta0 h: the roll amplitude
    (re.compile(r"\bsqrt\("), "\u221a("),
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


LOCAL_PATH = re.compile(
    r"(?:sqlite:///?)?(?:[\w.~-]*/)+([\w.-]+\.(?:blf|asc|csv|xlsx|parquet|toml|sqlite|db))\b"
)
"""A file path on the machine that wrote the report (a raw log, an imported file, a SQLite
database): the report names the file, its SHA-256 identifies it; the JSON keeps the path."""


def file_names(text: str) -> str:
    """`text` with every local file path cut to the file's name (a server URL is kept)."""
    return LOCAL_PATH.sub(r"\1", text)


def _comment_at(line: str) -> int | None:
    """Where a TOML comment starts on `line` (outside a one-line string), None for none."""
    quote = None
    for i, ch in enumerate(line):
        if quote is not None:
            if ch == "\\" and quote == '"':
                continue
            if ch == quote and line[i - 1 : i] != "\\":
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return i
    return None


def without_comments(toml: str) -> str:
    """The plan's TOML without its comments (the author's notes to themselves): comment lines
    and trailing comments dropped, multi-line strings kept whole; blank runs closed up."""
    lines: list[str] = []
    in_string = False
    for line in toml.splitlines():
        opens = line.count('"""') + line.count("'''")
        if in_string or opens:
            lines.append(line.rstrip())
            in_string = in_string != (opens % 2 == 1)
            continue
        at = _comment_at(line)
        kept = (line if at is None else line[:at]).rstrip()
        if kept or (at is None and lines and lines[-1]):
            lines.append(kept)
    return "\n".join(lines).strip() + "\n"


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
    env.filters.update(
        fmt=fmt,
        sci=sci,
        verdict=verdict,
        level=level,
        notation=notation,
        file_names=file_names,
        without_comments=without_comments,
        dof=dof_text,
    )
    return env


NOMENCLATURE = (
    (
        "C",
        "reduced elastic compliance coefficient of the gyrosphere (model 1.1); "
        "1 g&middot;cm&sup2;&middot;s<sup>&minus;2</sup> = 10<sup>&minus;7</sup> "
        "kg&middot;m&sup2;&middot;s<sup>&minus;2</sup>",
        "g&middot;cm&sup2;&middot;s<sup>&minus;2</sup>",
    ),
    ("T", "time constant of the gyrosphere's centre-of-mass displacement (model 1.1)", "s"),
    ("K", "direction of rocking, from the compass's north", "deg"),
    ("A", "amplitude of rocking: the arc the compass travels, A = &theta;<sub>0</sub>h", "cm"),
    (
        "&theta;<sub>0</sub>, h",
        "roll (or pitch) angle amplitude; the compass's arm from the axis",
        "deg, cm",
    ),
    ("&tau;", "period of rocking", "s"),
    ("p", "angular frequency of rocking, p = 2&pi;/&tau;", "s<sup>&minus;1</sup>"),
    (
        "lP, H<sub>1</sub>, &Omega;, g, &phi;",
        "known constants: pendulum moment, angular momentum, "
        "the Earth's rate (U in [1]), gravity, latitude",
        "as stated",
    ),
    ("i, j, k", "trial; series (j = 1 still, j = 2 rocking); observation in a series", "&ndash;"),
    (
        "N, N<sub>eff</sub>",
        "observations per series; their number worth of independent ones",
        "&ndash;",
    ),
    (
        "&lang;&delta;<sub>i</sub>&rang;",
        "rolling error measured in trial i: mean of series 2 minus mean of series 1",
        "deg",
    ),
    (
        "&alpha;<sub>i</sub>, &alpha;<sub>p</sub>",
        "rolling error by model 1.1: fitted for trial i; predicted at sea",
        "deg",
    ),
    (
        "v<sub>i</sub>",
        "residual, &lang;&delta;<sub>i</sub>&rang; &minus; &alpha;<sub>i</sub>",
        "deg",
    ),
    (
        "S&sup2;, S&sup2;<sub>e</sub>, S&sup2;<sub>r</sub>",
        "sample variance; error (pooled) and residual variance",
        "deg&sup2;",
    ),
    ("&nu;", "degrees of freedom (subscripts e, r as the variances)", "&ndash;"),
    ("q", "significance level of the tests", "&ndash;"),
    ("G, F", "Cochran's and Fisher's statistics (critical values G*, F<sub>T</sub>)", "&ndash;"),
    (
        "p-value",
        "probability of a statistic at least as extreme under the hypothesis tested",
        "&ndash;",
    ),
    ("U", "expanded uncertainty (about 95 %) of a measured value", "as the value"),
    (
        "u, R&#770;(u)",
        "lag; the reading's estimated correlation function (eq 8.92)",
        "s, deg&sup2;",
    ),
    (
        "&sigma;&sup2;, &mu;, &beta;, u<sub>k</sub>",
        "correlation model: variance, decay rate, frequency; correlation time (eq 8.89)",
        "deg&sup2;, s<sup>&minus;1</sup>, rad/s, s",
    ),
    (
        "t<sub>a</sub>, &sigma;<sub>A</sub>(t<sub>a</sub>)",
        "averaging time; Allan deviation of the reading",
        "s, deg",
    ),
)
"""The report's symbols (its nomenclature table): one quantity each."""


EVENTS_SUMMARISED = {
    "command": "motion commands (the commanded motion of each trial: Acquisition per trial)",
    "early settle": "settle points found by the transient model (Settle points)",
}
"""Event kinds the report's event table counts instead of listing (their information-only
events; the JSON keeps them all): another table gives each."""


def _heading_title(t: TrialAcquisition) -> str:
    return (
        f"Trial {t.index} ({t.role}): K = {t.cmd_direction_deg:g} deg, "
        f"A = {t.cmd_amplitude_cm:g} cm, τ = {t.cmd_period_s:g} s (commanded)"
    )


def _figures(report: Report) -> dict[str, object]:
    """Every plot of the report as an <img> element (trusted: made here from numbers only)."""
    trials = {t.index: t for t in report.inputs.acquisition}
    with plots.reused_layouts():  # the trials' figures on one figure of each layout
        headings = {
            r.index: Markup(plots.heading_plot(r, _heading_title(trials[r.index])))
            for r in report.inputs.records
            if r.trace is not None or any(s.observations for s in r.series)
        }
    figures: dict[str, object] = {"headings": headings}
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
        NOMENCLATURE=NOMENCLATURE,
        EVENTS_SUMMARISED=EVENTS_SUMMARISED,
    )
