"""Fleet statistics of stored campaigns: the analysed campaigns of one instrument model as units
of a fleet (`analysis.fleet`), grouped by one of their labels, and the fleet's text."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from gyrostand.analysis.fleet import FleetAnalysis, FleetUnit
from gyrostand.db.queries import model_campaigns


@dataclass(frozen=True)
class LeftOut:
    """A campaign of the model that is not a unit of the fleet, and why."""

    campaign_id: int
    serial: str
    reason: str


@dataclass(frozen=True)
class FleetInputs:
    model: str
    factor: str
    units: tuple[FleetUnit, ...]
    left_out: tuple[LeftOut, ...]


def fleet_inputs(session: Session, model: str, factor: str) -> FleetInputs:
    """Each unit (serial) of `model` once: its latest completed, analysed campaign labelled
    `factor`, with the fit's C, T and standard errors from that campaign's latest analysis run;
    the model's other completed campaigns are left out with the reason."""
    units: dict[str, FleetUnit] = {}
    left_out = []
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
            continue
        left_out.append(LeftOut(c.campaign_id, c.serial, reason))
    ordered = sorted(units.values(), key=lambda u: u.campaign_id)
    return FleetInputs(model, factor, tuple(ordered), tuple(reversed(left_out)))


GROUP_HEADER = "  group      n  mean          sd            rms SE        t vs rest"


def _number(value: float, symbol: str) -> str:
    return f"{value / 1e7:.3f}e7" if symbol == "C" else f"{value:.4f}"


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
            "  group      n  mean          sd            rms SE",
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
            f"{a.s2_measurement:.3g} + type {a.s2_type:.3g})",
            f"  {a.verdict} (q = {a.q:g}, p = {a.p_value:.3g})",
        ]
        for s in p.smirnov:
            verdict = "differs from the rest" if s.differs else "no difference"
            lines.append(
                f"  Smirnov {s.group} ({s.n}) vs rest ({s.n_rest}): D = {s.statistic:.3f}, "
                f"p = {s.p_value:.3g} (level {s.q_each:.3g}): {verdict}"
            )
        outside = [
            f"{u.serial} ({u.group}, campaign {u.campaign_id}: {_number(u.value, p.symbol)}, "
            f"t = {u.t_statistic:+.2f})"
            for u in p.outliers
        ]
        lines.append("  outside the type's prediction interval: " + ("; ".join(outside) or "none"))
    for c in inputs.left_out:
        lines.append(f"left out: campaign {c.campaign_id} (serial {c.serial}): {c.reason}")
    return "\n".join(lines)
