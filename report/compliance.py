"""Compliance: each requirement of a named limits profile decided on the campaign's evidence.

A profile is a TOML file (shipped: ``profiles/imo-a424.toml``, ``imo-a821.toml``,
``iso-22090-1.toml``) stating the standard and the edition it follows, the decision rule, the
motion envelope (and latitude range) its limits apply to, and per requirement the clause, the
limit in degrees (optionally times sec(latitude)), the text the limit was checked against
(``source``), whether it was confirmed there (``verified``), who at the laboratory verified it
against which edition (``verified_by``), the standard's test procedure where the stand can be
compared with it, and the evidence it is judged on. A requirement the campaign gives no evidence
for, or whose evidence was not obtained by the standard's procedure, is NOT ASSESSED with the
reason.

Measured values and their expanded uncertainty U (about 95 %):
- heading_rms: only when the campaign's still series follow the standard's procedure (as many
  readings, the same interval): the largest RMS of a still series about its mean,
  sqrt(S^2 (N - 1) / N) from the series variance S^2 of eq 2.2; U = 2 u with u = RMS /
  sqrt(2 (N - 1)), the standard deviation of a standard deviation (GUM, JCGM 100:2008, E.4.3);
- rolling_error_stand: |<delta_i>| (eq 2.1) of the trials whose motion lies inside the envelope,
  the one the decision rule finds worst; U = t(0.975, nu_i) sqrt(S^2/N) with the variance of the
  mean difference and nu_i of eq 2.4; not assessed when the standard's test moves several axes
  at once (the stand rocks about one).
A forecast (rolling_error_forecast: |alpha_p| + half-width of the (1 - q) prediction interval,
eqs 1.1, 2.10-2.11, worst over the envelope, `envelope_worst`) is a prediction by model 1.1 of
Potemkin (1982), not a measurement by the standard's procedure: it is reported beside the
decisions (`Compliance.predictions`) and decides nothing.

Decision rule (ISO/IEC 17025:2017 7.8.6; ILAC-G8:09/2019 4.2), chosen in the profile:
``simple`` (4.2.1, guard band w = 0: PASS when value <= limit) or ``guarded`` (4.2.2, w = U: PASS
when value + U <= limit); FAIL otherwise. PASS or FAIL only on a limit that someone at the
laboratory verified against a named edition (``verified_by``; for envelope evidence the
envelope too); otherwise the requirement is UNVERIFIED, its comparison given in ``detail``.
`Compliance.decision` sums the requirements up: FAIL when one fails; INCONCLUSIVE when one is
UNVERIFIED; PASS when at least one passed and the rest were not assessed; NOT ASSESSED when
nothing was.
"""

from __future__ import annotations

import datetime as dt
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gyrostand.analysis.quantiles import dof_text, t_quantile
from gyrostand.report import SHIPPED, SHIPPED_PROFILES
from gyrostand.report.errors import ReportError

if TYPE_CHECKING:  # annotations only (scipy is not loaded for this module)
    from gyrostand.analysis.campaign import CampaignAnalysis
    from gyrostand.analysis.forecast import EnvelopeWorst, Extrapolation, MotionBox
    from gyrostand.analysis.procedures import ProcedureResults
    from gyrostand.report.model import PlanSummary
    from gyrostand.report.worst_case import WorstCase

PASS, FAIL, NOT_ASSESSED = "PASS", "FAIL", "NOT ASSESSED"
UNVERIFIED = "UNVERIFIED"  # a requirement compared with a limit the laboratory has not verified
INCONCLUSIVE = "INCONCLUSIVE"  # the overall decision when a requirement is unverified
DECISIONS = (PASS, FAIL, UNVERIFIED, NOT_ASSESSED)
PREDICTION = "PREDICTION"  # a forecast's place in the verdict column: it decides nothing
DECISION_RULES = {
    "simple": "simple acceptance (ILAC-G8:09/2019 4.2.1, guard band w = 0): PASS when the "
    "measured value does not exceed the limit",
    "guarded": "guarded acceptance (ILAC-G8:09/2019 4.2.2, guard band w = U): PASS when the "
    "measured value plus its expanded uncertainty U (about 95 %) does not exceed the limit",
}
INTERVAL_TOLERANCE = 0.05
"""A campaign's reading interval matches the standard's within this fraction."""


@dataclass(frozen=True)
class Verification:
    """Who at the laboratory verified a limit (or the envelope), when, against which edition."""

    name: str
    date: str
    edition: str

    def describe(self) -> str:
        return f"verified by {self.name} on {self.date} against {self.edition}"


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
    verified_by: Verification | None = None

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
    band_deg: float | None = None  # settling: the band width the readings must stay within


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
    verified_by: Verification | None = None
    limit_h: float | None = None  # a limit in hours (the settling time)

    @property
    def unit(self) -> str:
        return "h" if self.limit_h is not None else "deg"


@dataclass(frozen=True)
class Profile:
    id: str
    name: str
    edition: str
    source: str
    caution: str
    decision_rule: str  # a key of DECISION_RULES
    envelope: Envelope
    requirements: tuple[Requirement, ...]
    path: str

    @property
    def max_latitude_deg(self) -> float:
        return self.envelope.max_latitude_deg


@dataclass(frozen=True)
class ComplianceItem:
    """One requirement: the limit as evaluated, the measured value with its expanded
    uncertainty U (how U was obtained in ``uncertainty_text``), the acceptance limit of the
    decision rule (limit - w), the decision (one of DECISIONS), whether the limit was
    confirmed in its source and who verified it (None: nobody at the laboratory: UNVERIFIED).
    A prediction (`Compliance.predictions`) has no decision: ``verdict`` is PREDICTION,
    ``exceeds`` says whether the predicted bound exceeds the limit, ``worst`` is the
    envelope's worst case."""

    id: str
    clause: str
    requirement: str
    evidence: str
    source: str
    verified: bool
    verified_by: str | None
    stated_limit_deg: float | None
    secant_latitude: bool
    limit_deg: float | None
    limit_text: str
    value_deg: float | None
    uncertainty_deg: float | None
    uncertainty_text: str
    acceptance_limit_deg: float | None
    verdict: str
    detail: str
    exceeds: bool | None
    worst: EnvelopeWorst | None
    extrapolation: Extrapolation | None  # a prediction beyond the trials' motion
    unit: str = "deg"  # of the value, U, the limits: "h" for the settling time, else "deg"


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
    decision_rule: str  # a key of DECISION_RULES
    items: tuple[ComplianceItem, ...]  # the decisions, one per measured requirement
    predictions: tuple[ComplianceItem, ...]  # forecasts: no decision

    @property
    def decision_rule_text(self) -> str:
        return DECISION_RULES[self.decision_rule]

    def count(self, verdict: str) -> int:
        """How many requirements got this decision."""
        return sum(item.verdict == verdict for item in self.items)

    def ids(self, verdict: str) -> tuple[str, ...]:
        """The requirements that got this decision."""
        return tuple(item.id for item in self.items if item.verdict == verdict)

    def limit_at(self, evidence: str, latitude_deg: float) -> float | None:
        """The limit of the first requirement judged on this evidence, at this latitude (None:
        no such requirement, or it states no limit)."""
        item = next((i for i in self.items + self.predictions if i.evidence == evidence), None)
        if item is None or item.stated_limit_deg is None:
            return None
        if not item.secant_latitude:
            return item.stated_limit_deg
        return float(secant_limit(item.stated_limit_deg, latitude_deg))

    @property
    def decision(self) -> str:
        """The profile's overall decision: FAIL when a requirement fails; otherwise
        INCONCLUSIVE when one rests on a limit the laboratory has not verified; otherwise PASS
        when at least one passed (the others not assessed); NOT ASSESSED when none was."""
        if self.count(FAIL):
            return FAIL
        if self.count(UNVERIFIED):
            return INCONCLUSIVE
        return PASS if self.count(PASS) else NOT_ASSESSED

    @property
    def summary(self) -> str:
        """One line of counts, the requirements named (the decision word is not repeated)."""
        parts = [
            f"{self.count(v)} {v.lower()} ({', '.join(self.ids(v))})"
            for v in (PASS, FAIL, UNVERIFIED)
            if self.count(v)
        ]
        judged = "; ".join(parts) if parts else "no requirement compared with its limit"
        return (
            f"{judged}; {self.count(NOT_ASSESSED)} of {len(self.items)} requirements of "
            f"{self.profile_id} not assessed"
        )


def secant_limit(limit_deg: float, latitude_deg: Any) -> Any:
    """limit x sec(latitude) (of an array of latitudes too). numpy imported here: `plan check`
    reads a profile's procedures and needs none."""
    import numpy as np

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
    rule = _get(head, "decision_rule", str, "[profile]")
    if rule not in DECISION_RULES:
        raise ReportError(
            f"[profile]: decision_rule {rule!r} is neither of {', '.join(DECISION_RULES)}"
        )
    return Profile(
        id=_get(head, "id", str, "[profile]"),
        name=_get(head, "name", str, "[profile]"),
        edition=_get(head, "edition", str, "[profile]"),
        source=_get(head, "source", str, "[profile]"),
        caution=str(head.get("caution", "")),
        decision_rule=rule,
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
        verified_by=_verification(env, where),
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
    limit_h = _optional(row, "limit_h", (int, float), where)
    if limit_h is not None and (limit_h <= 0 or limit is not None):
        raise ReportError(f"{where}: limit_h must be a positive number, and not with limit_deg")
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
        verified_by=_verification(row, where),
        limit_h=None if limit_h is None else float(limit_h),
    )


def _verification(table: dict[str, Any], where: str) -> Verification | None:
    """``verified_by = { name = "...", date = YYYY-MM-DD, edition = "..." }``: only with
    ``verified = true`` (a limit not confirmed in its source cannot have been verified)."""
    entry = _optional(table, "verified_by", dict, where)
    if entry is None:
        return None
    if not table.get("verified"):
        raise ReportError(f"{where}: verified_by needs verified = true")
    at = f"{where}.verified_by"
    date = entry.get("date")
    if not isinstance(date, dt.date) or isinstance(date, dt.datetime):
        raise ReportError(f"{at}: date must be a TOML date (YYYY-MM-DD)")
    name, edition = _get(entry, "name", str, at).strip(), _get(entry, "edition", str, at).strip()
    if not name or not edition:
        raise ReportError(f"{at}: name and edition must not be empty")
    return Verification(name, date.isoformat(), edition)


def _procedure(table: dict[str, Any], where: str) -> Procedure:
    readings = _optional(table, "readings", int, where)
    interval = _optional(table, "interval_s", (int, float), where)
    axes = _optional(table, "axes", int, where)
    band = _optional(table, "band_deg", (int, float), where)
    if (readings is None) != (interval is None):
        raise ReportError(f"{where}: give readings and interval_s together")
    if any(v is not None and v <= 0 for v in (readings, interval, axes, band)):
        raise ReportError(f"{where}: readings, interval_s, axes, band_deg must be > 0")
    return Procedure(
        text=_get(table, "text", str, where),
        readings=readings,
        interval_s=None if interval is None else float(interval),
        axes=axes,
        band_deg=None if band is None else float(band),
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

    analysis: CampaignAnalysis | None  # None: only the procedures' evidence (`_measured_by`)
    plan: PlanSummary | None
    profile: Profile
    imported: bool = False  # the data were imported from a file, not acquired on the stand
    procedures: ProcedureResults | None = None  # the standard's own tests, when run
    worst_cases: tuple[WorstCase, ...] = ()  # found when the analysis was recorded

    @property
    def site_latitude_deg(self) -> float:
        if self.analysis is None:
            assert self.procedures is not None  # (assess)
            return self.procedures.latitude_deg
        return self.analysis.constants.latitude_deg


@dataclass(frozen=True)
class Finding:
    """An evaluator's answer: the value (None: not assessed), the latitude its limit is taken
    at, the explanation, the value's expanded uncertainty U and how it was obtained (a
    forecast: its prediction interval is in the value), and the envelope's worst case
    (forecasts)."""

    value_deg: float | None
    latitude_deg: float | None
    detail: str
    uncertainty_deg: float | None = None
    uncertainty_text: str = ""
    worst: EnvelopeWorst | None = None
    extrapolation: Extrapolation | None = None


def _guard(e: Evidence, uncertainty_deg: float) -> float:
    """The guard band w of the profile's decision rule (ILAC-G8:09/2019 4.2.1-4.2.2)."""
    return uncertainty_deg if e.profile.decision_rule == "guarded" else 0.0


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


def _departs(e: Evidence, kind: str) -> str:
    """The sentence on the plan's departure from the standard's procedure (empty: none)."""
    assert e.procedures is not None
    how = e.procedures.departure(kind)
    return "" if how is None else f"; the procedure departs from the standard's: {how}"


def _settling_time(req: Requirement, e: Evidence) -> Finding:
    if e.procedures is not None and e.procedures.settling is not None:
        s = e.procedures.settling
        if not s.settled:
            from gyrostand.analysis.procedures import MAX_HORIZON

            bound_h = MAX_HORIZON * s.record_s / 3600.0
            why = (
                f"run-up from switch-on: the fitted reading does not settle within "
                f"+/-{s.half_band_deg:g} deg of its settle point within {bound_h:.3g} h (ten "
                f"times the {s.record_s / 3600:.3g} h record)" + _departs(e, "settling")
            )
            if req.limit_h is None or bound_h <= req.limit_h:
                return _not_assessed(f"{why}: not compared with the limit")
            return Finding(bound_h, e.site_latitude_deg, why, 0.0, "a lower bound: U = 0")
        return Finding(
            s.value_s / 3600.0,
            e.site_latitude_deg,
            f"run-up from switch-on: the reading stays within +/-{s.half_band_deg:g} deg of its "
            f"settle point {s.settle_point_deg:.3f} deg from {s.value_s / 60:.1f} min on, by the "
            "settle model of Bezvesilna & Gura (eq 3, omega and xi fitted: damped period "
            f"{s.period_s / 60:.1f} min) on the record from {s.fit_from_s / 60:.1f} min to "
            f"{s.record_s / 3600:.2f} h"
            + (", extrapolated past the record's end" if s.extrapolated else "")
            + _departs(e, "settling"),
            s.expanded_s / 3600.0,
            "U = 2 u, u propagated from the fit's covariance (GUM eq 13)",
        )
    if e.imported:
        return _not_assessed("the imported data record no run-up from switch-on")
    return _not_assessed(
        "the campaign starts with the compass running; no run-up from switch-on is recorded "
        "(the settle waits in the plan follow changes of rocking, not a start)"
    )


def _settle_point(e: Evidence) -> Any:
    """The settle point procedure's result (None: not run)."""
    return None if e.procedures is None else e.procedures.settle_point


def _readings_text(p: Any) -> str:
    return f"{p.n} readings {p.interval_s / 60:g} min apart after settling"


def _settle_point_error(req: Requirement, e: Evidence) -> Finding:
    if (p := _settle_point(e)) is not None:
        if p.error_deg is None:
            return _not_assessed("settle point error: not assessed (no reference heading)")
        assert e.procedures is not None and e.procedures.reference_deg is not None
        return Finding(
            abs(p.error_deg),
            e.site_latitude_deg,
            f"settle point heading {p.heading_deg:.3f} deg (mean of {_readings_text(p)}) "
            f"against the reference heading {e.procedures.reference_deg:g} deg: error "
            f"{p.error_deg:+.3f} deg" + _departs(e, "settle_point"),
            p.error_expanded_deg,
            f"U = k u, u^2 = S^2/N + u(reference)^2, k = {p.coverage_factor:.2f} "
            "(t, Welch-Satterthwaite, GUM G.4.1)",
        )
    differs = _procedure_differs(req, e)
    return _not_assessed(
        "no reference (true) heading is recorded with the campaign's observations, so the "
        "settle point heading cannot be compared with the true heading"
        + ("" if differs is None else f"; and the stand procedure differs: {differs}")
    )


def _settle_repeatability(req: Requirement, e: Evidence) -> Finding:
    if e.procedures is not None and (r := e.procedures.repeatability) is not None:
        points = ", ".join(f"{v:.3f}" for v in r.settle_points_deg)
        return Finding(
            r.range_deg,
            e.site_latitude_deg,
            f"range of the settle points of {len(r.settle_points_deg)} run-ups ({points} deg), "
            "each from switch-on" + _departs(e, "repeatability"),
            r.expanded_deg,
            "U = 2 sqrt(u_max^2 + u_min^2), u = S / sqrt(N) of each run-up's readings",
        )
    if e.imported:
        return _not_assessed(
            "the imported data record no run-up and no reference heading: repeatability not "
            "measured"
        )
    return _not_assessed("one run-up only and no reference heading: repeatability not measured")


def _speed_course_errors(req: Requirement, e: Evidence) -> Finding:
    return _not_assessed("the rolling stand does not reproduce changes of ship speed or course")


def _heading_rms(req: Requirement, e: Evidence) -> Finding:
    if (p := _settle_point(e)) is not None:
        return Finding(
            p.rms_deg,
            e.site_latitude_deg,
            f"RMS of the {_readings_text(p)} about their mean" + _departs(e, "settle_point"),
            p.rms_expanded_deg,
            f"U = 2 u, u = RMS / sqrt(2 (N - 1)) with N = {p.n} (GUM E.4.3)",
        )
    differs = _procedure_differs(req, e)
    if differs is not None:
        return _not_assessed(f"not assessed: the stand procedure differs: {differs}")
    still = [(t.index, t.before) for t in e.analysis.trials if t.before is not None]
    if not still:
        return _not_assessed(
            "no still-series readings: the data were imported as per-trial summaries"
        )
    rms = {i: math.sqrt(s.var_deg2 * (s.n - 1) / s.n) for i, s in still}  # eq 2.2, N - 1 -> N
    n = dict(still)
    # U = 2 u(RMS), u = RMS / sqrt(2 (N - 1)): GUM (JCGM 100:2008) E.4.3
    u = {i: 2 * rms[i] / math.sqrt(2 * (n[i].n - 1)) for i in rms}
    worst = max(rms, key=lambda i: rms[i] + _guard(e, u[i]))
    seconds = None if e.plan is None else e.plan.still_window_s
    window = "" if seconds is None else f", each reading a {seconds:g} s window mean"
    return Finding(
        rms[worst],
        e.site_latitude_deg,
        f"largest RMS about the series mean over {len(rms)} still series (trial {worst}, "
        f"N = {n[worst].n}){window}; "
        + (
            "the profile states no reading procedure to compare with"
            if req.procedure is None
            else f"the readings follow the standard's procedure ({req.procedure.text})"
        ),
        u[worst],
        f"U = 2 u, u = RMS / sqrt(2 (N - 1)) with N = {n[worst].n} (GUM E.4.3)",
    )


def _rolling_error_stand(req: Requirement, e: Evidence) -> Finding:
    from gyrostand.analysis.forecast import horizontal_acceleration_m_s2

    proc = req.procedure
    if proc is not None and proc.axes is not None and proc.axes > 1:
        return _not_assessed(
            f"not assessed: the stand procedure differs: the standard asks {proc.text}; the "
            "stand rocks about one axis at a time, in one direction K per trial"
        )
    if e.procedures is not None and e.procedures.rolling:
        return _rolling_procedure(e)
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
    basis = {t.index: _mean_variance(t, e.analysis) for t in inside}
    unknown = [i for i, b in basis.items() if b is None]
    if unknown:
        return _not_assessed(
            f"the uncertainty of <delta_i> is unknown for trial {', '.join(map(str, unknown))}: "
            "no variance given, and the trial variances are not homogeneous (Cochran), so the "
            "pooled S_e^2 cannot stand in"
        )
    u = {i: _t975(b[1]) * math.sqrt(b[0]) for i, b in basis.items() if b is not None}
    worst = max(inside, key=lambda t: abs(t.delta_deg) + _guard(e, u[t.index]))
    var, dof, how_u = basis[worst.index] or (0.0, 0, "")
    left_out = f"; outside the envelope: {', '.join(str(t.index) for t in outside)}"
    how = "" if proc is None else f"; the standard's procedure: {proc.text}"
    return Finding(
        abs(worst.delta_deg),
        e.site_latitude_deg,
        f"largest |<delta_i>| over trials {', '.join(str(t.index) for t in inside)} "
        f"(trial {worst.index}), one axis rocked per trial{left_out if outside else ''}{how}",
        u[worst.index],
        f"U = t(0.975, nu = {dof_text(dof)}) sqrt(S^2/N) = {_t975(dof):.3f} \u00d7 "
        f"{math.sqrt(var):.4f} deg, "
        f"{how_u}",
    )


def _rolling_procedure(e: Evidence) -> Finding:
    """The rolling procedure's points: the worst measured one decides; points beyond the
    stand are left to the forecast (named, decide nothing)."""
    assert e.procedures is not None
    measured = [r for r in e.procedures.rolling if not r.forecast]
    forecast = [r for r in e.procedures.rolling if r.forecast]

    def name(r: Any) -> str:
        return f"K {r.direction_deg:g} deg, A {r.amplitude_cm:g} cm, tau {r.period_s:g} s"

    left = (
        ""
        if not forecast
        else "; beyond the stand, forecast by model 1.1 (the forecast row, no decision): "
        + "; ".join(name(r) for r in forecast)
    )
    if not measured:
        return _not_assessed(f"no point of the rolling procedure within the stand's reach{left}")
    worst = max(measured, key=lambda r: abs(r.error_deg) + _guard(e, r.expanded_deg))
    return Finding(
        abs(worst.error_deg),
        e.site_latitude_deg,
        f"largest |error| against the static settle point over {len(measured)} rolling points "
        f"(at {name(worst)}: {worst.error_deg:+.3f} deg){left}" + _departs(e, "rolling"),
        worst.expanded_deg,
        "U = k u, u^2 = u(rolling mean)^2 + u(settle point)^2, k by Welch-Satterthwaite "
        "(GUM G.4.1)",
    )


def _mean_variance(trial: Any, analysis: CampaignAnalysis) -> tuple[float, float, str] | None:
    """The variance of a trial's mean difference <delta_i>, its degrees of freedom and where
    they come from: the trial's own (`TrialStats.mean_dof`: eq 2.4, with a compensated
    series' part known), or, for a trial given without a variance, the pooled S^2_e / N with
    nu_e (eq 2.6) when Cochran found the variances homogeneous (None otherwise)."""
    if trial.var_mean_deg2 is not None and trial.dof:
        return (
            trial.var_mean_deg2,
            trial.mean_dof,
            "the trial's own variance (nu by eq 2.4; a compensated series' part known)",
        )
    if not analysis.cochran.homogeneous:
        return None
    a = analysis.adequacy
    return a.s2_e_mean, a.dof_e, "the pooled S_e^2 / N (eq 2.6; no variance of its own)"


def _t975(dof: float) -> float:
    return t_quantile(0.975, dof)


def _forecast_box(analysis: CampaignAnalysis, profile: Profile) -> MotionBox:
    """The motion the forecast's worst case is sought over: the profile's envelope for the
    plan's motion (roll or pitch)."""
    from gyrostand.analysis.forecast import MotionBox

    ship = analysis.forecasts[0].conditions
    env = profile.envelope
    return MotionBox(
        max_angle_deg=env.max_roll_deg if ship.motion == "roll" else env.max_pitch_deg,
        period_s=env.period_s,
        max_acceleration_m_s2=env.max_acceleration_m_s2,
        max_latitude_deg=env.max_latitude_deg,
    )


def _worst_case(req: Requirement, e: Evidence) -> WorstCase:
    """The forecast's worst case over the envelope: the one found when the analysis was
    recorded, else searched now."""
    from gyrostand.analysis.forecast import envelope_worst
    from gyrostand.report.worst_case import WorstCase

    assert e.analysis is not None and e.analysis.forecasts  # (_rolling_error_forecast)
    ship = e.analysis.forecasts[0].conditions
    box = _forecast_box(e.analysis, e.profile)
    for known in e.worst_cases:
        if (known.box, known.arm_cm, known.motion, known.secant_latitude) == (
            box,
            ship.arm_cm,
            ship.motion,
            req.secant_latitude,
        ):
            return known
    worst = envelope_worst(
        e.analysis.predictor,
        box,
        arm_cm=ship.arm_cm,
        motion=ship.motion,
        secant_latitude=req.secant_latitude,
    )
    return WorstCase(box, ship.arm_cm, ship.motion, req.secant_latitude, worst)


def worst_cases(profile: Profile, analysis: CampaignAnalysis) -> tuple[WorstCase, ...]:
    """The worst cases the profile's forecast requirements ask of this analysis (none without
    a forecast): recorded with the analysis (`report.stored`)."""
    if not analysis.forecasts:
        return ()
    evidence = Evidence(analysis, None, profile)
    return tuple(
        _worst_case(req, evidence)
        for req in profile.requirements
        if req.evidence == "rolling_error_forecast"
    )


def _rolling_error_forecast(req: Requirement, e: Evidence) -> Finding:
    from gyrostand.analysis.forecast import ShipConditions, forecast_ship

    if not e.analysis.forecasts:
        return _not_assessed("the plan states no ship conditions (arm, motion) to forecast")
    ship = e.analysis.forecasts[0].conditions
    env = e.profile.envelope
    found = _worst_case(req, e)
    box, w = found.box, found.worst
    tested = e.analysis.tested_range
    beyond = tested.beyond(w.amplitude_cm, w.period_s)
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
        "steady error of one-axis motion; yaw and simultaneous axes are not modelled. "
        + (
            ""
            if beyond is None
            else f"The trials covered {tested.describe()}: {beyond.text}, from a fit with "
            f"nu_r = {e.analysis.fit.dof} degrees of freedom. "
        )
        + "A "
        "prediction by model 1.1 of Potemkin (1982), not a test by the standard's procedure: "
        "it decides nothing",
        uncertainty_text=f"the {1 - w.q:.0%} prediction interval is in the value",
        worst=w,
        extrapolation=beyond,
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
    value, lat, u = finding.value_deg, finding.latitude_deg, finding.uncertainty_deg
    unit = req.unit
    limit: float | None = req.limit_deg if req.limit_h is None else req.limit_h
    limit_text = "-" if limit is None else f"{limit:g} {unit}"
    if limit is not None and req.secant_latitude:
        limit_text += " x sec(latitude)"
    forecast = req.evidence == "rolling_error_forecast"
    verdict, detail, accept, exceeds = NOT_ASSESSED, finding.detail, None, None
    if value is None or limit is None:
        limit = None
    elif req.secant_latitude and (lat is None or abs(lat) > profile.max_latitude_deg):
        limit, detail = None, f"latitude {lat} deg lies beyond the standard's range; {detail}"
    else:
        if req.secant_latitude:
            limit = float(secant_limit(limit, lat))
            limit_text = f"{req.limit_deg:g} deg x sec({lat:.4g} deg) = {limit:.3f} deg"
        exceeds = value > limit
        if not forecast:
            assert u is not None  # every measured finding states its uncertainty
            w = u if profile.decision_rule == "guarded" else 0.0
            accept = limit - w  # ILAC-G8:09/2019 4.2.1 (w = 0), 4.2.2 (w = U)
            unverified = [
                *([] if req.verified_by else ["the limit"]),
                *(
                    ["the motion envelope"]
                    if req.evidence in NEEDS_ENVELOPE and not profile.envelope.verified_by
                    else []
                ),
            ]
            compared = (
                f"{value:.3f} +/- {u:.3f} {unit} against the acceptance limit {accept:.3f} {unit} "
                f"({profile.decision_rule} acceptance)"
            )
            if unverified:
                verdict = UNVERIFIED
                detail = (
                    f"{detail}. No decision: {' and '.join(unverified)} "
                    f"{'are' if len(unverified) > 1 else 'is'} not verified by the "
                    f"laboratory; {compared} would " + ("pass" if value <= accept else "fail")
                )
            else:
                verdict = PASS if value <= accept else FAIL
                detail = f"{detail}. {compared}"
    return ComplianceItem(
        id=req.id,
        clause=req.clause,
        requirement=req.requirement,
        evidence=req.evidence,
        source=req.source,
        verified=req.verified,
        verified_by=None if req.verified_by is None else req.verified_by.describe(),
        stated_limit_deg=req.limit_deg if req.limit_h is None else req.limit_h,
        secant_latitude=req.secant_latitude,
        limit_deg=limit,
        limit_text=limit_text,
        value_deg=value,
        uncertainty_deg=u,
        uncertainty_text=finding.uncertainty_text,
        acceptance_limit_deg=accept,
        verdict=PREDICTION if forecast else verdict,
        detail=detail,
        exceeds=exceeds,
        worst=finding.worst,
        extrapolation=finding.extrapolation,
        unit=unit,
    )


def _measured_by(procedures: ProcedureResults | None, evidence: str) -> bool:
    """Whether the standard's procedures give this evidence (judged without the analysis)."""
    if procedures is None:
        return False
    return {
        "settling_time": procedures.settling is not None,
        "settle_point_error": procedures.settle_point is not None,
        "heading_rms": procedures.settle_point is not None,
        "settle_repeatability": procedures.repeatability is not None,
        "rolling_error_stand": bool(procedures.rolling),
    }.get(evidence, False)


def assess(
    profile: Profile,
    analysis: CampaignAnalysis | None,
    plan: PlanSummary | None = None,
    *,
    imported: bool = False,
    procedures: ProcedureResults | None = None,
    worst_cases: tuple[WorstCase, ...] = (),
) -> Compliance:
    """Every requirement of the profile judged on this campaign and its plan's observation
    protocol (all NOT ASSESSED when the campaign could not be analysed); ``imported``: the data
    came from a file, and the reasons say so rather than describe the stand; ``worst_cases``:
    the forecast's worst cases found when the analysis was recorded."""
    if analysis is None and procedures is None:
        findings = [_not_assessed("the campaign could not be analysed")] * len(profile.requirements)
        latitude = None
    else:
        evidence = Evidence(analysis, plan, profile, imported, procedures, worst_cases)
        findings = [
            EVIDENCE[req.evidence](req, evidence)
            if analysis is not None or _measured_by(procedures, req.evidence)
            else _not_assessed("the campaign could not be analysed")
            for req in profile.requirements
        ]
        latitude = evidence.site_latitude_deg
    judged = [
        _judge(req, finding, profile)
        for req, finding in zip(profile.requirements, findings, strict=True)
    ]
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
        decision_rule=profile.decision_rule,
        items=tuple(i for i in judged if i.verdict != PREDICTION),
        predictions=tuple(i for i in judged if i.verdict == PREDICTION),
    )
