"""Compliance: each requirement of a named limits profile judged on the campaign's evidence.

A profile is a TOML file (the shipped one: ``profiles/imo-a424.toml``, IMO Resolution A.424(XI))
stating its source standard, the motion envelope its rolling requirement applies to, and per
requirement the clause, the limit in degrees (optionally times sec(latitude)) and the evidence it
is judged on. Evidence kinds are implemented here; a requirement the campaign gives no evidence
for is NOT ASSESSED, with the reason.

Decision rules (stated in each item's ``detail``):
- heading_rms: the largest RMS of the still-series observations about their series mean,
  sqrt(S^2 (N - 1) / N) from the series variance S^2 of eq 2.2, against the limit at the site;
- rolling_error_stand: the largest |<delta_i>| (eq 2.1 difference) over the trials whose motion
  lies inside the envelope, against the limit at the site latitude;
- rolling_error_forecast: the largest |alpha_p| + half-width of the (1 - q) prediction interval
  (eqs 1.1, 2.10-2.11) over the forecast grid points inside the envelope, each against the limit
  at its own latitude. Model 1.1 scales alpha with sec(latitude) exactly as the limit does, so the
  verdict does not depend on the latitude it is evaluated at.
PASS when the value does not exceed the limit, FAIL otherwise.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gyrostand.report.errors import ReportError

if TYPE_CHECKING:  # annotations only: the CLI reads SHIPPED without loading scipy
    from gyrostand.analysis.campaign import CampaignAnalysis
    from gyrostand.analysis.forecast import ForecastGrid

PASS, FAIL, NOT_ASSESSED = "PASS", "FAIL", "NOT ASSESSED"
SHIPPED = "imo-a424"


@dataclass(frozen=True)
class Envelope:
    """The ship motion a rolling requirement applies to."""

    period_s: tuple[float, float]
    max_acceleration_m_s2: float
    max_roll_deg: float
    max_pitch_deg: float
    forecast_periods_s: tuple[float, ...]

    def describe(self) -> str:
        lo, hi = self.period_s
        return (
            f"periods {lo:g}-{hi:g} s, horizontal acceleration <= "
            f"{self.max_acceleration_m_s2:g} m/s^2, roll <= {self.max_roll_deg:g} deg, "
            f"pitch <= {self.max_pitch_deg:g} deg"
        )


@dataclass(frozen=True)
class Requirement:
    id: str
    clause: str
    requirement: str
    evidence: str
    limit_deg: float | None
    secant_latitude: bool


@dataclass(frozen=True)
class Profile:
    id: str
    name: str
    source: str
    caution: str
    max_latitude_deg: float
    envelope: Envelope
    requirements: tuple[Requirement, ...]
    path: str


@dataclass(frozen=True)
class ComplianceItem:
    """One requirement judged: the limit as evaluated, the value compared, the verdict."""

    id: str
    clause: str
    requirement: str
    evidence: str
    limit_deg: float | None
    limit_text: str
    value_deg: float | None
    verdict: str
    detail: str


@dataclass(frozen=True)
class Compliance:
    profile_id: str
    profile_name: str
    source: str
    caution: str
    envelope: str
    site_latitude_deg: float | None
    items: tuple[ComplianceItem, ...]

    def count(self, verdict: str) -> int:
        """How many requirements got this verdict."""
        return sum(item.verdict == verdict for item in self.items)


def horizontal_acceleration_m_s2(amplitude_cm: Any, period_s: Any) -> Any:
    """Peak horizontal acceleration A p^2 of harmonic rocking (p = 2 pi / tau), in m/s^2."""
    return np.asarray(amplitude_cm) * (2 * np.pi / np.asarray(period_s)) ** 2 / 100.0


def secant_limit(limit_deg: float, latitude_deg: Any) -> Any:
    """limit x sec(latitude)."""
    return limit_deg / np.cos(np.radians(latitude_deg))


# ------------------------------------------------------------------------------- the profile


def _get(table: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    value = table.get(key)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise ReportError(f"compliance profile {where}: {key} is missing or of the wrong type")
    return value


def _numbers(table: dict[str, Any], key: str, where: str) -> tuple[float, ...]:
    values = _get(table, key, list, where)
    if not values or not all(isinstance(v, int | float) for v in values):
        raise ReportError(f"compliance profile {where}: {key} must be a list of numbers")
    return tuple(float(v) for v in values)


def load_profile(name_or_path: str | Path = SHIPPED) -> Profile:
    """A shipped profile by name (``imo-a424``) or a profile file by path."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        path, text = str(candidate), _read(candidate)
    else:
        resource = files("gyrostand.report") / "profiles" / f"{name_or_path}.toml"
        if not resource.is_file():
            raise ReportError(f"no compliance profile named {str(name_or_path)!r}")
        path, text = f"{name_or_path} (shipped)", resource.read_text(encoding="utf-8")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ReportError(f"compliance profile {path}: not valid TOML ({exc})") from None
    head = _get(doc, "profile", dict, path)
    env = _get(doc, "envelope", dict, path)
    period = _numbers(env, "period_s", "[envelope]")
    if len(period) != 2 or not 0 < period[0] < period[1]:
        raise ReportError("compliance profile [envelope]: period_s must be [low, high]")
    requirements = []
    for n, row in enumerate(_get(doc, "requirements", list, path), start=1):
        where = f"requirements[{n}]"
        evidence = _get(row, "evidence", str, where)
        if evidence not in EVIDENCE:
            raise ReportError(
                f"compliance profile {where}: unknown evidence {evidence!r} "
                f"(known: {', '.join(sorted(EVIDENCE))})"
            )
        limit = row.get("limit_deg")
        if limit is not None and (not isinstance(limit, int | float) or limit <= 0):
            raise ReportError(f"compliance profile {where}: limit_deg must be a positive number")
        if limit is None and evidence in NEEDS_LIMIT:
            raise ReportError(f"compliance profile {where}: evidence {evidence} needs limit_deg")
        requirements.append(
            Requirement(
                id=_get(row, "id", str, where),
                clause=_get(row, "clause", str, where),
                requirement=_get(row, "requirement", str, where),
                evidence=evidence,
                limit_deg=None if limit is None else float(limit),
                secant_latitude=bool(row.get("secant_latitude", False)),
            )
        )
    return Profile(
        id=_get(head, "id", str, "[profile]"),
        name=_get(head, "name", str, "[profile]"),
        source=_get(head, "source", str, "[profile]"),
        caution=str(head.get("caution", "")),
        max_latitude_deg=float(_get(head, "max_latitude_deg", (int, float), "[profile]")),
        envelope=Envelope(
            period_s=(period[0], period[1]),
            max_acceleration_m_s2=float(
                _get(env, "max_acceleration_m_s2", (int, float), "[envelope]")
            ),
            max_roll_deg=float(_get(env, "max_roll_deg", (int, float), "[envelope]")),
            max_pitch_deg=float(_get(env, "max_pitch_deg", (int, float), "[envelope]")),
            forecast_periods_s=_numbers(env, "forecast_periods_s", "[envelope]"),
        ),
        requirements=tuple(requirements),
        path=path,
    )


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ReportError(f"compliance profile {path}: cannot read it ({exc})") from None


# ------------------------------------------------------------------------------ the evidence


@dataclass(frozen=True)
class Evidence:
    """What the evaluators look at."""

    analysis: CampaignAnalysis
    grid: ForecastGrid | None
    profile: Profile

    @property
    def site_latitude_deg(self) -> float:
        return self.analysis.constants.latitude_deg


@dataclass(frozen=True)
class Finding:
    """An evaluator's answer: the value (None: not assessed), the latitude its limit is taken
    at, and the explanation."""

    value_deg: float | None
    latitude_deg: float | None
    detail: str


def _not_assessed(why: str) -> Finding:
    return Finding(None, None, why)


def _settling_time(e: Evidence) -> Finding:
    return _not_assessed(
        "the campaign starts with the compass running; no run-up from switch-on is recorded "
        "(the settle waits in the plan follow changes of rocking, not a start)"
    )


def _settle_point_error(e: Evidence) -> Finding:
    return _not_assessed(
        "the campaign records no reference (true) heading of the stand, so the settle point "
        "heading cannot be compared with the true heading"
    )


def _settle_repeatability(e: Evidence) -> Finding:
    return _not_assessed("one run-up only and no reference heading: repeatability not measured")


def _speed_course_errors(e: Evidence) -> Finding:
    return _not_assessed("the rolling stand does not reproduce changes of ship speed or course")


def _heading_rms(e: Evidence) -> Finding:
    still = [(t.index, t.before) for t in e.analysis.trials if t.before is not None]
    if not still:
        return _not_assessed(
            "no still-series readings: the data were imported as per-trial summaries"
        )
    rms = {i: math.sqrt(s.var_deg2 * (s.n - 1) / s.n) for i, s in still}
    worst = max(rms, key=rms.__getitem__)
    return Finding(
        rms[worst],
        e.site_latitude_deg,
        f"largest RMS about the series mean over {len(rms)} still series (trial {worst}, "
        f"N = {dict(still)[worst].n}); readings are the plan's window means, not the "
        "standard's 10 readings at 20 min",
    )


def _rolling_error_stand(e: Evidence) -> Finding:
    env = e.profile.envelope
    lo, hi = env.period_s
    inside, outside = [], []
    for t in e.analysis.trials:
        accel = float(horizontal_acceleration_m_s2(t.amplitude_cm, t.period_s))
        ok = lo <= t.period_s <= hi and accel <= env.max_acceleration_m_s2
        (inside if ok else outside).append(t)
    if not inside:
        return _not_assessed(
            f"no trial inside the envelope ({env.describe()}); trials "
            f"{', '.join(str(t.index) for t in outside)} lie outside it"
        )
    worst = max(inside, key=lambda t: abs(t.delta_deg))
    left_out = f"; outside the envelope: {', '.join(str(t.index) for t in outside)}"
    return Finding(
        abs(worst.delta_deg),
        e.site_latitude_deg,
        f"largest |<delta_i>| over trials {', '.join(str(t.index) for t in inside)} "
        f"(trial {worst.index}){left_out if outside else ''}",
    )


def _rolling_error_forecast(e: Evidence) -> Finding:
    g = e.grid
    if g is None:
        return _not_assessed("the plan states no ship conditions to forecast")
    env = e.profile.envelope
    course, roll, period, lat = np.meshgrid(
        g.course_deg, g.roll_deg, g.period_s, g.latitude_deg, indexing="ij"
    )
    amplitude = np.radians(roll) * g.arm_cm
    max_angle = env.max_roll_deg if g.motion == "roll" else env.max_pitch_deg
    inside = (
        (period >= env.period_s[0])
        & (period <= env.period_s[1])
        & (horizontal_acceleration_m_s2(amplitude, period) <= env.max_acceleration_m_s2)
        & (roll <= max_angle)
        & (np.abs(lat) <= e.profile.max_latitude_deg)
    )
    if not inside.any():
        return _not_assessed(f"no forecast point inside the envelope ({env.describe()})")
    bound = np.abs(g.alpha_deg) + g.half_width_deg
    ratio = np.where(inside, bound / secant_limit(1.0, lat), -np.inf)
    at = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    alpha, half = float(g.alpha_deg[at]), float(g.half_width_deg[at])
    return Finding(
        float(bound[at]),
        float(lat[at]),
        f"worst of {int(inside.sum())} grid points inside the envelope: alpha_p = "
        f"{alpha:+.3f} +/- {half:.3f} deg at course {course[at]:g} deg, {g.motion} "
        f"{roll[at]:g} deg, tau = {period[at]:g} s, latitude {lat[at]:g} deg "
        f"({1 - g.q:.0%} interval)",
    )


EVIDENCE: dict[str, Callable[[Evidence], Finding]] = {
    "settling_time": _settling_time,
    "settle_point_error": _settle_point_error,
    "settle_repeatability": _settle_repeatability,
    "speed_course_errors": _speed_course_errors,
    "heading_rms": _heading_rms,
    "rolling_error_stand": _rolling_error_stand,
    "rolling_error_forecast": _rolling_error_forecast,
}
NEEDS_LIMIT = {"heading_rms", "rolling_error_stand", "rolling_error_forecast"}


def _judge(req: Requirement, finding: Finding, profile: Profile) -> ComplianceItem:
    value, lat = finding.value_deg, finding.latitude_deg
    limit: float | None = req.limit_deg
    limit_text = "-" if limit is None else f"{limit:g} deg"
    if limit is not None and req.secant_latitude:
        limit_text += " x sec(latitude)"
    verdict, detail = NOT_ASSESSED, finding.detail
    if value is None or limit is None:
        limit = None
    elif req.secant_latitude and (lat is None or abs(lat) > profile.max_latitude_deg):
        limit, detail = None, f"latitude {lat} deg lies beyond the standard's range; {detail}"
    else:
        if req.secant_latitude:
            limit = float(secant_limit(limit, lat))
            limit_text = f"{req.limit_deg:g} deg x sec({lat:g} deg) = {limit:.3f} deg"
        verdict = PASS if value <= limit else FAIL
    return ComplianceItem(
        id=req.id,
        clause=req.clause,
        requirement=req.requirement,
        evidence=req.evidence,
        limit_deg=limit,
        limit_text=limit_text,
        value_deg=value,
        verdict=verdict,
        detail=detail,
    )


def assess(
    profile: Profile, analysis: CampaignAnalysis | None, grid: ForecastGrid | None
) -> Compliance:
    """Every requirement of the profile judged on this campaign (all NOT ASSESSED when the
    campaign could not be analysed)."""
    if analysis is None:
        findings = [_not_assessed("the campaign could not be analysed")] * len(profile.requirements)
        latitude = None
    else:
        evidence = Evidence(analysis, grid, profile)
        findings = [EVIDENCE[req.evidence](evidence) for req in profile.requirements]
        latitude = evidence.site_latitude_deg
    return Compliance(
        profile_id=profile.id,
        profile_name=profile.name,
        source=profile.source,
        caution=profile.caution,
        envelope=profile.envelope.describe(),
        site_latitude_deg=latitude,
        items=tuple(
            _judge(req, finding, profile)
            for req, finding in zip(profile.requirements, findings, strict=True)
        ),
    )
