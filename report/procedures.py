"""The plan's procedures against the compliance profile's: every key left out filled with the
profile's value, every key given that differs recorded as a departure (allowed, and stated in
the report beside the clause it is judged on)."""

from __future__ import annotations

import math

from gyrostand.plan.model import Plan
from gyrostand.plan.procedures import ProcedurePlan, ResolvedProcedure, RollingPoint
from gyrostand.report.compliance import Profile, Requirement

EVIDENCE = {  # the profile requirement whose procedure gives a kind's defaults
    "settling": "settling_time",
    "settle_point": "settle_point_error",
    "repeatability": "settle_point_error",
    "rolling": "rolling_error_stand",
}


def _requirement(profile: Profile, evidence: str) -> Requirement | None:
    return next((r for r in profile.requirements if r.evidence == evidence), None)


def envelope_points(profile: Profile, direction_deg: float = 45.0) -> tuple[RollingPoint, ...]:
    """The envelope's forecast periods, each at the profile's largest horizontal acceleration
    (A p^2 = a_max, p = 2 pi / tau), on an intercardinal course."""
    env = profile.envelope
    return tuple(
        RollingPoint(
            direction_deg=direction_deg,
            amplitude_cm=round(100.0 * env.max_acceleration_m_s2 / (2 * math.pi / tau) ** 2, 1),
            period_s=tau,
        )
        for tau in env.forecast_periods_s
    )


def resolve(plan: Plan, profile: Profile) -> tuple[ResolvedProcedure, ...]:
    """The plan's procedures, filled from the profile, with their departures."""
    return tuple(_resolve(p, plan, profile) for p in plan.procedure)


def _resolve(proc: ProcedurePlan, plan: Plan, profile: Profile) -> ResolvedProcedure:
    req = _requirement(profile, EVIDENCE[proc.kind])
    standard = None if req is None else req.procedure
    given = proc.model_fields_set
    fill: dict[str, object] = {}
    departures: list[str] = []

    def default(key: str, value: float | None, fallback: float, unit: str) -> None:
        """The profile's value (or the fallback when it states none); a departure when the
        plan gives another."""
        mine = getattr(proc, key)
        if key not in given:
            fill[key] = value if value is not None else fallback
        elif value is not None and not math.isclose(float(mine), float(value)):
            departures.append(f"{key} {mine:g}{unit} instead of the standard's {value:g}{unit}")

    if proc.kind == "settling":
        default("band_deg", None if standard is None else standard.band_deg, 0.7, " deg")
        limit_s = None if req is None or req.limit_h is None else req.limit_h * 3600.0
        default("max_wait_s", limit_s, 6 * 3600.0, " s")
        model = plan.settle.transient_model
        if "fit_from_s" not in given and model is not None:
            fill["fit_from_s"] = model.undamped_period_s / 4
    elif proc.kind in ("settle_point", "repeatability", "rolling"):
        readings = None if standard is None else standard.readings
        interval = None if standard is None else standard.interval_s
        rolling = proc.kind == "rolling"  # the standard states no reading times under rolling
        default("readings", readings, 5 if rolling else 10, "")
        default("interval_s", interval, 120.0 if rolling else 1200.0, " s")
    if proc.kind == "rolling" and proc.points is None:
        fill["points"] = envelope_points(profile)
    elif proc.kind == "rolling":
        departures.append(
            f"{len(proc.points or ())} points of the plan's instead of the envelope's "
            f"{len(profile.envelope.forecast_periods_s)} at its largest acceleration"
        )
    return ResolvedProcedure(proc.model_copy(update=fill), tuple(departures))
