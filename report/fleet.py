"""Fleet statistics of stored campaigns: the analysed campaigns of one instrument model as units
of a fleet (`analysis.fleet`), grouped by one of their labels; the fleet's text, and the fleet
report (HTML, PDF, JSON) with the stand report's machinery (`report.html`, `report.pdf`)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from sqlalchemy.orm import Session

from gyrostand.analysis.fleet import FleetAnalysis, FleetUnit
from gyrostand.db.models import Campaign
from gyrostand.db.queries import method_checks, model_campaigns
from gyrostand.report.errors import ReportError

SCHEMA = "gyrostand.fleet-report/1"
FORMATS = {".html": "html", ".pdf": "pdf", ".json": "json"}
"""The fleet report's formats, by the output file's suffix."""


@dataclass(frozen=True)
class LeftOut:
    """A campaign of the model that is not a unit of the fleet, and why."""

    campaign_id: int
    serial: str
    reason: str


@dataclass(frozen=True)
class FailedCheck:
    """A unit whose own campaign failed a test of the method: it stays in the fleet, but its fit
    (and the standard errors the measurement share rests on) is questionable."""

    campaign_id: int
    serial: str
    checks: str


@dataclass(frozen=True)
class ProgrammeTrial:
    role: str
    direction_deg: float
    amplitude_cm: float
    period_s: float


@dataclass(frozen=True)
class Programme:
    """A test programme some units ran: their plan's trials (commanded motion, role), N and how
    a series was observed; the same for every unit whose plan differs only in what identifies
    the unit (serial, seed, a simulated compass's true C and T)."""

    trials: tuple[ProgrammeTrial, ...]
    n_obs: int | None
    observation: str
    campaign_ids: tuple[int, ...]

    @property
    def roles(self) -> str:
        """'4 fit, 2 control'."""
        counts: dict[str, int] = {}
        for t in self.trials:
            counts[t.role] = counts.get(t.role, 0) + 1
        return ", ".join(f"{n} {role}" for role, n in counts.items())


def programme_key(plan_toml: str, results: dict[str, Any]) -> tuple[object, ...]:
    """(trials, N, observation) of a campaign: from its stored plan, or for an imported
    campaign whose plan has no trials, from its analysis (the trials as the file gave them)."""
    import tomllib

    try:
        plan = tomllib.loads(plan_toml)
    except tomllib.TOMLDecodeError:
        plan = {}
    rows = plan.get("trials") or results.get("trials") or []
    trials = tuple(
        ProgrammeTrial(
            str(t.get("role", "fit")),
            float(t["direction_deg"]),
            float(t["amplitude_cm"]),
            float(t["period_s"]),
        )
        for t in rows
    )
    n_obs = (plan.get("campaign") or {}).get("n_obs")
    if n_obs is None and results.get("trials"):
        n_obs = results["trials"][0].get("n_before")
    if "campaign" in plan:  # a plan the stand ran (defaults: plan/model.py ObservationPlan)
        seen = plan.get("observation") or {}
        settle = (plan.get("settle") or {}).get("method", "band")
        observation = (
            f"windows of {seen.get('still_window_s', 60.0):g} s still and "
            f"{seen.get('rocking_window_periods', 10)} rocking periods; settle criterion: "
            f"{settle}"
        )
    else:
        observation = "imported measurements (no stand plan)"
    return trials, n_obs, observation


def programmes(session: Session, results: dict[int, dict[str, Any]]) -> tuple[Programme, ...]:
    """The test programmes the units ran (`results`: each unit's campaign and its analysis),
    each with its units' campaigns, most units first."""
    by_key: dict[tuple[object, ...], list[int]] = {}
    for campaign_id, analysis in sorted(results.items()):
        key = programme_key(session.get_one(Campaign, campaign_id).plan_toml, analysis)
        by_key.setdefault(key, []).append(campaign_id)
    return tuple(
        Programme(key[0], key[1], key[2], tuple(ids))  # type: ignore[arg-type]
        for key, ids in sorted(by_key.items(), key=lambda item: -len(item[1]))
    )


@dataclass(frozen=True)
class FleetInputs:
    model: str
    factor: str
    units: tuple[FleetUnit, ...]
    left_out: tuple[LeftOut, ...]
    failed_checks: tuple[FailedCheck, ...] = ()
    programmes: tuple[Programme, ...] = ()
    """The test programmes the units ran (`programmes`)."""


def failed_checks(results: dict[str, Any]) -> str:
    """What an analysis run failed of Cochran's test (eq 2.5) and Fisher's adequacy test (eq 2.8),
    in words; empty when it failed neither."""
    homogeneous, adequate = method_checks(results)
    failed = []
    if homogeneous is False:
        failed.append("Cochran's test: the trials' variances are not homogeneous")
    if adequate is False:
        failed.append("Fisher's test: the model is not adequate on the trial means")
    return "; ".join(failed)


def fleet_inputs(session: Session, model: str, factor: str) -> FleetInputs:
    """Each unit (serial) of `model` once: its latest completed, analysed campaign labelled
    `factor`, with the fit's C, T and standard errors from that campaign's latest analysis run;
    the model's other completed campaigns are left out with the reason, and the units whose run
    failed Cochran's or Fisher's test are named."""
    units: dict[str, FleetUnit] = {}
    results: dict[int, dict[str, Any]] = {}
    left_out, failed = [], []
    for c in reversed(model_campaigns(session, model, factor)):  # latest first
        fit = (c.results or {}).get("fit") or {}
        estimates, errors = fit.get("estimates") or {}, fit.get("std_errors") or {}
        if c.serial in units:
            reason = f"a later campaign of serial {c.serial} counts ({units[c.serial].campaign_id})"
        elif c.label is None:
            reason = f"no label {factor} (campaign run/import --tag {factor}=...)"
        elif c.results is None:
            reason = f"not analysed (gyrostand analyze {c.campaign_id})"
        elif not fit.get("converged") or None in (
            estimates.get("C_gcm2s2"),
            errors.get("C_gcm2s2"),
            estimates.get("T_s"),
            errors.get("T_s"),
        ):
            reason = "its analysis has no converged fit of C and T"
        else:
            units[c.serial] = FleetUnit(
                campaign_id=c.campaign_id,
                serial=c.serial,
                group=c.label,
                c_gcm2s2=float(estimates["C_gcm2s2"]),
                c_se=float(errors["C_gcm2s2"]),
                t_s=float(estimates["T_s"]),
                t_se=float(errors["T_s"]),
                when=c.started_at.isoformat(),
            )
            results[c.campaign_id] = c.results
            if checks := failed_checks(c.results):
                failed.append(FailedCheck(c.campaign_id, c.serial, checks))
            continue
        left_out.append(LeftOut(c.campaign_id, c.serial, reason))
    ordered = sorted(units.values(), key=lambda u: u.campaign_id)
    return FleetInputs(
        model,
        factor,
        tuple(ordered),
        tuple(reversed(left_out)),
        tuple(sorted(failed, key=lambda f: f.campaign_id)),
        programmes(session, results),
    )


def simulated_campaigns(session: Session, units: Sequence[FleetUnit]) -> tuple[int, ...]:
    """The units' campaigns that ran on the simulated stand, as the stand report decides."""
    from gyrostand.report.stored_plan import is_simulated  # the plan's models: analyze stays light

    return tuple(
        u.campaign_id for u in units if is_simulated(session.get_one(Campaign, u.campaign_id))
    )


GROUP_HEADER = "  group      n  mean          sd            rms SE        t vs rest"


def _number(value: float, symbol: str) -> str:
    return f"{value / 1e7:.3f}e7" if symbol == "C" else f"{value:.4f}"


def _ids(ids: Sequence[int]) -> str:
    return ", ".join(map(str, ids))


def programme_text(p: Programme) -> str:
    """A programme in one line: trials (role, K/A/τ), N, observation."""
    trials = "; ".join(
        f"{t.role} K {t.direction_deg:g} deg, A {t.amplitude_cm:g} cm, τ {t.period_s:g} s"
        for t in p.trials
    )
    n = "N not stated" if p.n_obs is None else f"N = {p.n_obs}"
    return f"{len(p.trials)} trials ({p.roles}): {trials}; {n}; {p.observation}"


def fleet_text(inputs: FleetInputs, analysis: FleetAnalysis) -> str:
    """The fleet analysis as text: per parameter the groups, Fisher's F test, Smirnov's tests
    and the units outside the type's prediction interval; then what was left out."""
    lines = [
        f"FLEET of {inputs.model}: {analysis.n_units} units grouped by {analysis.factor} "
        f"(q = {analysis.q:g}; Sveshnikov, section 8.2: Fisher's analysis of variance, Smirnov)",
    ]
    for p in analysis.parameters:
        a = p.anova
        lines += [
            "",
            f"{p.symbol} ({p.unit})",
            GROUP_HEADER,
        ]
        for g in p.groups:
            sd = "-" if g.sd is None else _number(g.sd, p.symbol)
            verdict = "differs" if g.differs else ""
            lines.append(
                f"  {g.group:<9} {g.n:>2}  {_number(g.mean, p.symbol):<12}  {sd:<12}  "
                f"{_number(g.rms_se, p.symbol):<12}  {g.t_vs_rest:+.2f} {verdict}".rstrip()
            )
        lines += [
            f"  analysis of variance: S² between = {a.s2_between:.4g} (ν = {a.dof_between}), "
            f"S² within = {a.s2_within:.4g} (ν = {a.dof_within}; units' scatter: measurement "
            f"{a.s2_measurement:.3g} + type {a.s2_type:.3g}, {100 * (1 - a.q):g} % interval "
            f"{a.s2_type_interval[0]:.3g} to {a.s2_type_interval[1]:.3g})",
            f"  {a.verdict} (q = {a.q:g}, p = {a.p_value:.3g})",
        ]
        for s in p.smirnov:
            lines.append(
                f"  Smirnov {s.group} ({s.n}) vs rest ({s.n_rest}): D = {s.statistic:.3f}, "
                f"p = {s.p_value:.3g} (level {s.q_each:.3g}): {p.smirnov_verdict(s)}"
            )
        outside = [
            f"{u.serial} ({u.group}, campaign {u.campaign_id}: {_number(u.value, p.symbol)}, "
            f"t = {u.t_statistic:+.2f})"
            for u in p.outliers
        ]
        lines.append("  outside the type's prediction interval: " + ("; ".join(outside) or "none"))
    for p in inputs.programmes:
        lines.append(f"test programme, campaigns {_ids(p.campaign_ids)}: {programme_text(p)}")
    for f in inputs.failed_checks:
        lines.append(
            f"in the fleet, its own analysis failed: campaign {f.campaign_id} "
            f"(serial {f.serial}): {f.checks}"
        )
    for c in inputs.left_out:
        lines.append(f"left out: campaign {c.campaign_id} (serial {c.serial}): {c.reason}")
    return "\n".join(lines)


def fleet_document(inputs: FleetInputs, analysis: FleetAnalysis) -> dict[str, Any]:
    """The fleet analysis as plain JSON types: model, the analysis (`FleetAnalysis.to_dict`),
    the units, the campaigns left out and the units whose own analysis failed a test."""
    return {
        "model": inputs.model,
        **analysis.to_dict(),
        "units": [asdict(u) for u in inputs.units],
        "left_out": [asdict(c) for c in inputs.left_out],
        "failed_checks": [asdict(f) for f in inputs.failed_checks],
        "programmes": [asdict(p) for p in inputs.programmes],
    }


@dataclass(frozen=True)
class FleetReport:
    """The fleet report: what it rests on (`inputs`), the analysis, and its identification."""

    inputs: FleetInputs
    analysis: FleetAnalysis
    generated_at: str
    database: str
    software: str
    simulated: tuple[int, ...]
    """The units' campaigns that ran on the simulated stand (`simulated_campaigns`)."""
    marked_draft: bool = False
    """Marked DRAFT by the user (`fleet report --draft`)."""
    number: str | None = None
    laboratory: str | None = None

    @property
    def missing(self) -> tuple[str, ...]:
        """What the report lacks to be issued (ISO/IEC 17025 7.8.2): its number, the laboratory."""
        items = (("report number", self.number), ("laboratory", self.laboratory))
        return tuple(name for name, value in items if not value)

    @property
    def draft(self) -> bool:
        """DRAFT: marked so, or lacking an item it needs to be issued."""
        return self.marked_draft or bool(self.missing)

    @property
    def title(self) -> str:
        """The report's own title: its number, the model, the grouping."""
        number = f"Fleet report {self.number}" if self.number else "Fleet report (unnumbered)"
        draft = "DRAFT: " if self.draft else ""
        return f"{draft}{number}: {self.inputs.model}, by {self.inputs.factor}"

    @property
    def ordered_units(self) -> tuple[FleetUnit, ...]:
        """The units in the control charts' order: by campaign start, then serial."""
        return tuple(sorted(self.inputs.units, key=lambda u: (u.when or "", u.serial)))


def fleet_json(report: FleetReport) -> str:
    """The fleet report as one JSON document (schema gyrostand.fleet-report/1): identification,
    then `fleet_document`."""
    document = {
        "schema": SCHEMA,
        "generated_at": report.generated_at,
        "software": report.software,
        "database": report.database,
        "draft": report.draft,
        "missing": list(report.missing),
        "number": report.number,
        "laboratory": report.laboratory,
        "simulated_campaigns": list(report.simulated),
        **fleet_document(report.inputs, report.analysis),
    }
    return json.dumps(document, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def render_fleet_html(report: FleetReport) -> str:
    """The fleet report as one self-contained HTML document (the stand report's style sheet and
    filters; the control charts inline)."""
    from markupsafe import Markup

    from gyrostand.report import fleet_plots
    from gyrostand.report.html import TEMPLATES, environment

    template = environment().get_template("fleet.html.j2")
    order = [u.serial for u in report.ordered_units]
    return template.render(
        r=report,
        inputs=report.inputs,
        a=report.analysis,
        charts={
            p.symbol: Markup(fleet_plots.control_chart(p, order, report.analysis.factor))
            for p in report.analysis.parameters
        },
        css=Markup((TEMPLATES / "report.css").read_text(encoding="utf-8")),
    )


def fleet_format(path: Path) -> str:
    """The format an output file's suffix names (ReportError for any other)."""
    try:
        return FORMATS[path.suffix.lower()]
    except KeyError:
        known = ", ".join(FORMATS)
        raise ReportError(f"{path}: the suffix names no fleet report format ({known})") from None


def write_fleet_report(report: FleetReport, path: Path) -> Path:
    """Write the report in the format the suffix of `path` names (ReportError when it cannot)."""
    kind = fleet_format(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if kind == "json":
            path.write_text(fleet_json(report), encoding="utf-8")
        elif kind == "html":
            path.write_text(render_fleet_html(report), encoding="utf-8")
        else:
            from gyrostand.report.pdf import Attachment, write_pdf

            data = Attachment(
                path.with_suffix(".json").name,
                fleet_json(report),
                "application/json",
                "the fleet report as data",
            )
            write_pdf(render_fleet_html(report), path, (data,), report.generated_at)
    except OSError as error:
        why = f"{path.parent} is a file" if path.parent.is_file() else error.strerror or error
        raise ReportError(f"cannot write {path}: {why}") from None
    return path
