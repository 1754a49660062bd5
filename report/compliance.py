"""Compliance: each requirement of a named limits profile judged on the campaign's evidence.

A profile is a TOML file (shipped: ``profiles/imo-a424.toml``, ``imo-a821.toml``,
``iso-22090-1.toml``) stating the standard and the edition it follows, the motion envelope (and
latitude range) its limits apply to, and per requirement the clause, the limit in degrees
(optionally times sec(latitude)), the text the limit was checked against (``source``), whether it
was confirmed there (``verified``), the standard's test procedure where the stand can be compared
with it, and the evidence it is judged on. A requirement the campaign gives no evidence for, or
whose evidence was not obtained by the standard's procedure, is NOT ASSESSED with the reason.

Decision rules (stated in each item's ``detail``):
- heading_rms: only when the campaign's still series follow the standard's procedure (as many
  readings, the same interval): the largest RMS of a still series about its mean,
  sqrt(S^2 (N - 1) / N) from the series variance S^2 of eq 2.2, against the limit at the site;
- rolling_error_stand: the largest |<delta_i>| (eq 2.1 difference) over the trials whose motion
  lies inside the envelope, against the limit at the site latitude; not assessed when the
  standard's test moves several axes at once (the stand rocks about one);
- rolling_error_forecast: the largest |alpha_p| + half-width of the (1 - q) prediction interval
  (eqs 1.1, 2.10-2.11) over the whole envelope (`envelope_worst`), relative to the limit at each
  latitude; always indicative: a prediction by model 1.1 of Potemkin (1982), not the standard's
  test.
A judged requirement PASSes when the value does not exceed the limit, FAILs otherwise; when the
limit (or the envelope it needs) is not verified, or the evidence is indicative, the verdict is
INDICATIVE PASS or INDICATIVE FAIL instead. `Compliance.verdict` sums the items up.
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

from gyrostand.report import SHIPPED, SHIPPED_PROFILES
from gyrostand.report.errors import ReportError

if TYPE_CHECKING:  # annotations only (scipy is not loaded for this module)
    from gyrostand.analysis.campaign import CampaignAnalysis
    from gyrostand.analysis.forecast import EnvelopeWorst
    from gyrostand.report.model import PlanSummary

PASS, FAIL, NOT_ASSESSED = "PASS", "FAIL", "NOT ASSESSED"
INDICATIVE, INDICATIVE_PASS, INDICATIVE_FAIL = "INDICATIVE", "INDICATIVE PASS", "INDICATIVE FAIL"
INTERVAL_TOLERANCE = 0.05
"""A campaign's reading interval matches the standard's within this fraction."""


@dataclass(frozen=True)
class Envelope:
    """The ship motion and latitudes the limits apply to, with the text they were checked
    against."""

    period_s: tuple[float, float]
    max_acceleration_m_s2: float
    max_roll_deg: float
    max_pitch_deg: float
    max_latitude_deg: float
    forecast_periods_s: tuple[float, ...]
    source: str
    verified: bool

    def describe(self) -> str:
        lo, hi = self.period_s
        return (
            f"periods {lo:g}-{hi:g} s, horizontal acceleration <= "
            f"{self.max_acceleration_m_s2:g} m/s^2, roll <= {self.max_roll_deg:g} deg, "
            f"pitch <= {self.max_pitch_deg:g} deg, latitudes up to {self.max_latitude_deg:g} deg"
        )


@dataclass(frozen=True)
class Procedure:
    """The standard's test procedure for a requirement: in words, and the parameters the stand's
    record is compared with (readings per series and their interval; axes moved at once)."""

    text: str
    readings: int | None
    interval_s: float | None
    axes: int | None


@dataclass(frozen=True)
class Requirement:
    id: str
    clause: str
    requirement: str
    evidence: str
    limit_deg: float | None
    secant_latitude: bool
    source: str
    verified: bool
    procedure: Procedure | None


@dataclass(frozen=True)
class Profile:
    id: str
    name: str
    edition: str
    source: str
    caution: str
    envelope: Envelope
    requirements: tuple[Requirement, ...]
    path: str

    @property
    def max_latitude_deg(self) -> float:
        return self.envelope.max_latitude_deg


@dataclass(frozen=True)
class ComplianceItem:
    """One requirement judged: the limit as evaluated, the value compared, the verdict, whether
    the limit was verified in its source (an unverified envelope also makes the verdict
    indicative: ``detail`` says so), and the envelope's worst case for a forecast."""

    id: str
    clause: str
    requirement: str
    evidence: str
    source: str
    verified: bool
    stated_limit_deg: float | None
    secant_latitude: bool
    limit_deg: float | None
    limit_text: str
    value_deg: float | None
    verdict: str
    detail: str
    worst: EnvelopeWorst | None


@dataclass(frozen=True)
class Compliance:
    profile_id: str
    profile_name: str
    edition: str
    source: str
    caution: str
    envelope: str
    envelope_source: str
    envelope_verified: bool
    site_latitude_deg: float | None
    items: tuple[ComplianceItem, ...]

    def count(self, verdict: str) -> int:
        """How many requirements got this verdict."""
        return sum(item.verdict == verdict for item in self.items)

    def limit_at(self, evidence: str, latitude_deg: float) -> float | None:
        """The limit of the first requirement judged on this evidence, at this latitude (None:
        no such requirement, or it states no limit)."""
        item = next((i for i in self.items if i.evidence == evidence), None)
        if item is None or item.stated_limit_deg is None:
            return None
        if not item.secant_latitude:
            return item.stated_limit_deg
        return float(secant_limit(item.stated_limit_deg, latitude_deg))

    @property
    def verdict(self) -> str:
        """The profile's verdict on the campaign, for a conformity statement:
        FAIL when some requirement fails on a verified limit; otherwise INDICATIVE when some
        result rests on an unverified limit or envelope or on a forecast (an INDICATIVE PASS or
        INDICATIVE FAIL); otherwise PASS when at least one requirement was assessed (all of them
        pass); NOT ASSESSED when none was. Requirements not assessed never make a PASS a FAIL:
        `summary` counts them."""
        if self.count(FAIL):
            return FAIL
        if self.count(INDICATIVE_PASS) or self.count(INDICATIVE_FAIL):
            return INDICATIVE
        return PASS if self.count(PASS) else NOT_ASSESSED

    @property
    def summary(self) -> str:
        """One line: the verdict, what it rests on, and how much was not assessed."""
        ids = {v: [i.id for i in self.items if i.verdict == v] for v in (FAIL, INDICATIVE_FAIL)}
        parts = [
            f"{self.count(v)} {v.lower()}" + (f" ({', '.join(ids[v])})" if ids.get(v) else "")
            for v in (PASS, FAIL, INDICATIVE_PASS, INDICATIVE_FAIL)
            if self.count(v)
        ]
        judged = "; ".join(parts) if parts else "no requirement judged"
        return (
            f"{self.verdict} against {self.profile_id}: {judged}; "
            f"{self.count(NOT_ASSESSED)} of {len(self.items)} not assessed"
        )


def secant_limit(limit_deg: float, latitude_deg: Any) -> Any:
    """limit x sec(latitude)."""
    return limit_deg / np.cos(np.radians(latitude_deg))


# ------------------------------------------------------------------------------- the profile


def _get(table: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    value = table.get(key)
    wrong_bool = isinstance(value, bool) != (kind is bool)
    if not isinstance(value, kind) or wrong_bool:
        raise ReportError(f"{where}: {key} is missing or of the wrong type")
    return value


def _optional(table: dict[str, Any], key: str, kind: type, where: str) -> Any:
    return None if key not in table else _get(table, key, kind, where)


def _numbers(table: dict[str, Any], key: str, where: str) -> tuple[float, ...]:
    values = _get(table, key, list, where)
    if not values or not all(isinstance(v, int | float) for v in values):
        raise ReportError(f"{where}: {key} must be a list of numbers")
    return tuple(float(v) for v in values)


def _number(table: dict[str, Any], key: str, where: str) -> float:
    return float(_get(table, key, (int, float), where))


def load_profile(name_or_path: str | Path = SHIPPED) -> Profile:
    """A shipped profile by name (one of `SHIPPED_PROFILES`) or a profile file by path."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        path, text = str(candidate), _read(candidate)
    else:
        resource = files("gyrostand.report") / "profiles" / f"{name_or_path}.toml"
        if not resource.is_file():
            raise ReportError(
                f"no compliance profile named {str(name_or_path)!r} "
                f"(shipped: {', '.join(SHIPPED_PROFILES)}; or give a .toml file)"
            )
        path, text = f"{name_or_path} (shipped)", resource.read_text(encoding="utf-8")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ReportError(f"compliance profile {path}: not valid TOML ({exc})") from None
    try:
        return _profile(doc, path)
    except ReportError as exc:
        raise ReportError(f"compliance profile {path}: {exc}") from None


def _profile(doc: dict[str, Any], path: str) -> Profile:
    head = _get(doc, "profile", dict, "top level")
    return Profile(
        id=_get(head, "id", str, "[profile]"),
        name=_get(head, "name", str, "[profile]"),
        edition=_get(head, "edition", str, "[profile]"),
        source=_get(head, "source", str, "[profile]"),
        caution=str(head.get("caution", "")),
        envelope=_envelope(_get(doc, "envelope", dict, "top level")),
        requirements=tuple(
            _requirement(row, f"requirements[{n}]")
            for n, row in enumerate(_get(doc, "requirements", list, "top level"), start=1)
        ),
        path=path,
    )


def _envelope(env: dict[str, Any]) -> Envelope:
    where = "[envelope]"
    period = _numbers(env, "period_s", where)
    if len(period) != 2 or not 0 < period[0] < period[1]:
        raise ReportError("[envelope]: period_s must be [low, high]")
    envelope = Envelope(
        period_s=(period[0], period[1]),
        max_acceleration_m_s2=_number(env, "max_acceleration_m_s2", where),
        max_roll_deg=_number(env, "max_roll_deg", where),
        max_pitch_deg=_number(env, "max_pitch_deg", where),
        max_latitude_deg=_number(env, "max_latitude_deg", where),
        forecast_periods_s=_numbers(env, "forecast_periods_s", where),
        source=_get(env, "source", str, where),
        verified=_get(env, "verified", bool, where),
    )
    if not 0 < envelope.max_latitude_deg < 90:
        raise ReportError("[envelope]: max_latitude_deg must lie in (0, 90)")
    if min(envelope.max_acceleration_m_s2, envelope.max_roll_deg, envelope.max_pitch_deg) <= 0:
        raise ReportError("[envelope]: the motion limits must be positive")
    return envelope


def _requirement(row: Any, where: str) -> Requirement:
    if not isinstance(row, dict):
        raise ReportError(f"{where}: must be a table ([[requirements]])")
    evidence = _get(row, "evidence", str, where)
    if evidence not in EVIDENCE:
        raise ReportError(
            f"{where}: unknown evidence {evidence!r} (known: {', '.join(sorted(EVIDENCE))})"
        )
    limit = _optional(row, "limit_deg", (int, float), where)
    if limit is not None and limit <= 0:
        raise ReportError(f"{where}: limit_deg must be a positive number")
    if limit is None and evidence in NEEDS_LIMIT:
        raise ReportError(f"{where}: evidence {evidence} needs limit_deg")
    procedure = _optional(row, "procedure", dict, where)
    return Requirement(
        id=_get(row, "id", str, where),
        clause=_get(row, "clause", str, where),
        requirement=_get(row, "requirement", str, where),
        evidence=evidence,
        limit_deg=None if limit is None else float(limit),
        secant_latitude=bool(_optional(row, "secant_latitude", bool, where)),
        source=_get(row, "source", str, where),
        verified=_get(row, "verified", bool, where),
        procedure=None if procedure is None else _procedure(procedure, f"{where}.procedure"),
    )


def _procedure(table: dict[str, Any], where: str) -> Procedure:
    readings = _optional(table, "readings", int, where)
    interval = _optional(table, "interval_s", (int, float), where)
    axes = _optional(table, "axes", int, where)
    if (readings is None) != (interval is None):
        raise ReportError(f"{where}: give readings and interval_s together")
    if any(v is not None and v <= 0 for v in (readings, interval, axes)):
        raise ReportError(f"{where}: readings, interval_s, axes must be > 0")
    return Procedure(
        text=_get(table, "text", str, where),
        readings=readings,
        interval_s=None if interval is None else float(interval),
        axes=axes,
    )


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ReportError(f"compliance profile {path}: cannot read it ({exc})") from None


# ------------------------------------------------------------------------------ the evidence


@dataclass(frozen=True)
class Evidence:
    """What the evaluators look at: the analysis, the plan's observation protocol (None: the
    data were imported without one), the profile."""

    analysis: CampaignAnalysis
    plan: PlanSummary | None
    profile: Profile

    @property
    def site_latitude_deg(self) -> float:
        return self.analysis.constants.latitude_deg


@dataclass(frozen=True)
class Finding:
    """An evaluator's answer: the value (None: not assessed), the latitude its limit is taken
    at, the explanation, why the value is only indicative even on a verified limit (None: it is
    not), and the envelope's worst case (forecasts)."""

    value_deg: float | None
    latitude_deg: float | None
    detail: str
    indicative: str | None = None
    worst: EnvelopeWorst | None = None


def _not_assessed(why: str) -> Finding:
    return Finding(None, None, why)


def _procedure_differs(req: Requirement, e: Evidence) -> str | None:
    """Why the campaign's still series do not follow the standard's reading procedure (None:
    they do, or the profile states no reading procedure)."""
    proc = req.procedure
    if proc is None or proc.readings is None or proc.interval_s is None:
        return None
    standard = f"the standard asks {proc.text}"
    plan = e.plan
    if plan is None or plan.still_window_s is None:
        return f"{standard}; the campaign's reading times are not recorded (imported data)"
    interval = plan.still_window_s + (plan.spacing_s or 0.0)
    n = plan.n_obs
    if n == proc.readings and abs(interval / proc.interval_s - 1) <= INTERVAL_TOLERANCE:
        return None
    return (
        f"{standard}; the campaign took {n} readings per still series, each the mean of a "
        f"{plan.still_window_s:g} s window, one every {interval:g} s (over "
        f"{n * interval / 60:.4g} min)"
    )


def _settling_time(req: Requirement, e: Evidence) -> Finding:
    return _not_assessed(
        "the campaign starts with the compass running; no run-up from switch-on is recorded "
        "(the settle waits in the plan follow changes of rocking, not a start)"
    )


def _settle_point_error(req: Requirement, e: Evidence) -> Finding:
    differs = _procedure_differs(req, e)
    return _not_assessed(
        "the campaign records no reference (true) heading of the stand, so the settle point "
        "heading cannot be compared with the true heading"
        + ("" if differs is None else f"; and the stand procedure differs: {differs}")
    )


def _settle_repeatability(req: Requirement, e: Evidence) -> Finding:
    return _not_assessed("one run-up only and no reference heading: repeatability not measured")


def _speed_course_errors(req: Requirement, e: Evidence) -> Finding:
    return _not_assessed("the rolling stand does not reproduce changes of ship speed or course")


def _heading_rms(req: Requirement, e: Evidence) -> Finding:
    differs = _procedure_differs(req, e)
    if differs is not None:
        return _not_assessed(f"not assessed: the stand procedure differs: {differs}")
    still = [(t.index, t.before) for t in e.analysis.trials if t.before is not None]
    if not still:
        return _not_assessed(
            "no still-series readings: the data were imported as per-trial summaries"
        )
    rms = {i: math.sqrt(s.var_deg2 * (s.n - 1) / s.n) for i, s in still}  # eq 2.2, N - 1 -> N
    worst = max(rms, key=rms.__getitem__)
    seconds = None if e.plan is None else e.plan.still_window_s
    window = "" if seconds is None else f", each reading a {seconds:g} s window mean"
    return Finding(
        rms[worst],
        e.site_latitude_deg,
        f"largest RMS about the series mean over {len(rms)} still series (trial {worst}, "
        f"N = {dict(still)[worst].n}){window}; "
        + (
            "the profile states no reading procedure to compare with"
            if req.procedure is None
            else f"the readings follow the standard's procedure ({req.procedure.text})"
        ),
    )


def _rolling_error_stand(req: Requirement, e: Evidence) -> Finding:
    from gyrostand.analysis.forecast import horizontal_acceleration_m_s2

    proc = req.procedure
    if proc is not None and proc.axes is not None and proc.axes > 1:
        return _not_assessed(
            f"not assessed: the stand procedure differs: the standard asks {proc.text}; the "
            "stand rocks about one axis at a time, in one direction K per trial"
        )
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
    how = "" if proc is None else f"; the standard's procedure: {proc.text}"
    return Finding(
        abs(worst.delta_deg),
        e.site_latitude_deg,
        f"largest |<delta_i>| over trials {', '.join(str(t.index) for t in inside)} "
        f"(trial {worst.index}), one axis rocked per trial{left_out if outside else ''}{how}",
    )


def _rolling_error_forecast(req: Requirement, e: Evidence) -> Finding:
    from gyrostand.analysis.forecast import (
        MotionBox,
        ShipConditions,
        envelope_worst,
        forecast_ship,
    )

    if not e.analysis.forecasts:
        return _not_assessed("the plan states no ship conditions (arm, motion) to forecast")
    ship = e.analysis.forecasts[0].conditions
    env = e.profile.envelope
    box = MotionBox(
        max_angle_deg=env.max_roll_deg if ship.motion == "roll" else env.max_pitch_deg,
        period_s=env.period_s,
        max_acceleration_m_s2=env.max_acceleration_m_s2,
        max_latitude_deg=env.max_latitude_deg,
    )
    w = envelope_worst(
        e.analysis.predictor,
        box,
        arm_cm=ship.arm_cm,
        motion=ship.motion,
        secant_latitude=req.secant_latitude,
    )
    at_max = forecast_ship(
        e.analysis.predictor,
        ShipConditions(
            w.angle_deg, w.arm_cm, w.period_s, w.course_deg, env.max_latitude_deg, w.motion
        ),
    )
    return Finding(
        w.bound_deg,
        w.latitude_deg,
        f"worst case over the envelope ({ship.motion} up to {box.max_angle_deg:g} deg at the "
        f"plan's arm h = {w.arm_cm:g} cm, A = theta0 h, A p^2 <= "
        f"{env.max_acceleration_m_s2:g} m/s^2, periods {env.period_s[0]:g}-{env.period_s[1]:g} s, "
        f"courses 0-360 deg, latitudes 0-{env.max_latitude_deg:g} deg): alpha_p = "
        f"{w.alpha_deg:+.3f} +/- {w.half_width_deg:.3f} deg ({1 - w.q:.0%} interval) at "
        f"{ship.motion} {w.angle_deg:.2f} deg, tau = {w.period_s:.2f} s, acceleration "
        f"{w.acceleration_m_s2:.3f} m/s^2, course {w.course_deg:.1f} deg, latitude "
        f"{w.latitude_deg:.1f} deg; at {env.max_latitude_deg:g} deg the same motion gives "
        f"{abs(at_max.alpha_deg) + at_max.half_width_deg:.3f} deg. Model 1.1 predicts the "
        "steady error of one-axis motion; yaw and simultaneous axes are not modelled",
        indicative="a prediction by model 1.1 of Potemkin (1982), not a test by the standard's "
        "procedure",
        worst=w,
    )


EVIDENCE: dict[str, Callable[[Requirement, Evidence], Finding]] = {
    "settling_time": _settling_time,
    "settle_point_error": _settle_point_error,
    "settle_repeatability": _settle_repeatability,
    "speed_course_errors": _speed_course_errors,
    "heading_rms": _heading_rms,
    "rolling_error_stand": _rolling_error_stand,
    "rolling_error_forecast": _rolling_error_forecast,
}
NEEDS_LIMIT = {"heading_rms", "rolling_error_stand", "rolling_error_forecast"}
NEEDS_ENVELOPE = {"rolling_error_stand", "rolling_error_forecast"}


def _judge(req: Requirement, finding: Finding, profile: Profile) -> ComplianceItem:
    value, lat = finding.value_deg, finding.latitude_deg
    limit: float | None = req.limit_deg
    limit_text = "-" if limit is None else f"{limit:g} deg"
    if limit is not None and req.secant_latitude:
        limit_text += " x sec(latitude)"
    uses_envelope = req.evidence in NEEDS_ENVELOPE
    verdict, detail = NOT_ASSESSED, finding.detail
    if value is None or limit is None:
        limit = None
    elif req.secant_latitude and (lat is None or abs(lat) > profile.max_latitude_deg):
        limit, detail = None, f"latitude {lat} deg lies beyond the standard's range; {detail}"
    else:
        if req.secant_latitude:
            limit = float(secant_limit(limit, lat))
            limit_text = f"{req.limit_deg:g} deg x sec({lat:.4g} deg) = {limit:.3f} deg"
        why = [
            *([] if req.verified else ["the limit is not verified against the standard's text"]),
            *(
                ["the motion envelope is not verified"]
                if uses_envelope and not profile.envelope.verified
                else []
            ),
            *([] if finding.indicative is None else [finding.indicative]),
        ]
        passed = value <= limit
        if why:
            verdict = INDICATIVE_PASS if passed else INDICATIVE_FAIL
            detail = f"{detail}. Indicative only: {'; '.join(why)}"
        else:
            verdict = PASS if passed else FAIL
    return ComplianceItem(
        id=req.id,
        clause=req.clause,
        requirement=req.requirement,
        evidence=req.evidence,
        source=req.source,
        verified=req.verified,
        stated_limit_deg=req.limit_deg,
        secant_latitude=req.secant_latitude,
        limit_deg=limit,
        limit_text=limit_text,
        value_deg=value,
        verdict=verdict,
        detail=detail,
        worst=finding.worst,
    )


def assess(
    profile: Profile, analysis: CampaignAnalysis | None, plan: PlanSummary | None = None
) -> Compliance:
    """Every requirement of the profile judged on this campaign and its plan's observation
    protocol (all NOT ASSESSED when the campaign could not be analysed)."""
    if analysis is None:
        findings = [_not_assessed("the campaign could not be analysed")] * len(profile.requirements)
        latitude = None
    else:
        evidence = Evidence(analysis, plan, profile)
        findings = [EVIDENCE[req.evidence](req, evidence) for req in profile.requirements]
        latitude = evidence.site_latitude_deg
    return Compliance(
        profile_id=profile.id,
        profile_name=profile.name,
        edition=profile.edition,
        source=profile.source,
        caution=profile.caution,
        envelope=profile.envelope.describe(),
        envelope_source=profile.envelope.source,
        envelope_verified=profile.envelope.verified,
        site_latitude_deg=latitude,
        items=tuple(
            _judge(req, finding, profile)
            for req, finding in zip(profile.requirements, findings, strict=True)
        ),
    )
