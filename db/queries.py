"""Queries shared by the acquisition runner, the CLI, the report and the station: a campaign's
ORM graph, which attempt of each trial counts, where to resume it, how far it has got, the known
constants B of its model, and the campaign list."""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import ColumnElement, Subquery, func, select
from sqlalchemy.orm import Session, aliased, selectinload

from gyrostand.db.models import (
    EVENT_SEVERITIES,
    SERIES_J,
    AnalysisRun,
    Campaign,
    CampaignLabel,
    CampaignOrigin,
    Event,
    Instrument,
    Observation,
    RawLogSegment,
    Series,
    SignOff,
    Trial,
)


class CampaignNotFound(LookupError):
    """No campaign with that id in the database."""


def latest_attempt() -> ColumnElement[bool]:
    """SQL condition on `Trial`: the row is the latest attempt of its trial index, the one that
    stands for "trial i" (acquisition, resume, status, analysis); earlier attempts are failed
    ones that a retry superseded (`current_trials` is the same rule for loaded rows)."""
    later = aliased(Trial)
    return ~(
        select(later.id)
        .where(
            later.campaign_id == Trial.campaign_id,
            later.index == Trial.index,
            later.attempt > Trial.attempt,
        )
        .exists()
    )


def current_trials(trials: Iterable[Trial]) -> list[Trial]:
    """The latest attempt of each trial index among loaded rows (e.g. `Campaign.trials`), by
    index (`latest_attempt` in SQL)."""
    latest: dict[int, Trial] = {}
    for trial in trials:
        if trial.index not in latest or trial.attempt > latest[trial.index].attempt:
            latest[trial.index] = trial
    return [latest[index] for index in sorted(latest)]


def load_campaign(session: Session, campaign_id: int) -> Campaign:
    """The campaign with its instrument, trials (every attempt, by index and attempt), series
    (by j), observations (by k) and measured motion loaded in a few SELECTs; events and
    analysis runs load lazily when touched."""
    campaign = session.scalar(
        select(Campaign)
        .where(Campaign.id == campaign_id)
        .options(
            selectinload(Campaign.instrument),
            selectinload(Campaign.trials)
            .selectinload(Trial.series)
            .selectinload(Series.observations),
            selectinload(Campaign.trials).selectinload(Trial.series).selectinload(Series.motions),
        )
    )
    if campaign is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
    return campaign


class NotOnTheStand(ValueError):
    """A campaign imported from a file or replayed from a raw log: nothing more can be acquired
    into it (no resume, no retry)."""


def stand_campaign(session: Session, campaign_id: int) -> Campaign:
    """The campaign, when it was run on the stand; CampaignNotFound or NotOnTheStand (one line
    each) otherwise."""
    campaign = session.get(Campaign, campaign_id)
    if campaign is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
    if campaign.source != "stand":
        how = "replayed from a raw log" if campaign.source == "replay" else "imported from a file"
        raise NotOnTheStand(
            f"campaign {campaign_id} was {how} (source {campaign.source!r}): only a campaign "
            "run on the stand can be resumed or retried"
        )
    return campaign


def instrument_for(
    session: Session, model: str, serial: str, constants: dict[str, float]
) -> Instrument:
    """The stored instrument with this model, serial and constants, or a new (added) one."""
    for instrument in session.scalars(
        select(Instrument).where(Instrument.model == model, Instrument.serial == serial)
    ):
        if instrument.constants_json == constants:
            return instrument
    instrument = Instrument(model=model, serial=serial, constants_json=dict(constants))
    session.add(instrument)
    return instrument


@dataclass(frozen=True)
class CampaignHeader:
    """What a new campaign row holds besides its trials: the instrument (model, serial, known
    constants lP and H1), the site (latitude, Earth rate U, gravity g), the plan text and who
    ran it with which software."""

    model: str
    serial: str
    lp_gcm2s2: float
    h1_gcm2s: float
    latitude_deg: float
    earth_rate_rad_s: float
    gravity_cm_s2: float
    plan_toml: str
    operator: str
    n_obs: int
    software_version: str


def new_campaign(
    session: Session,
    header: CampaignHeader,
    *,
    status: str,
    source: str,
    labels: Mapping[str, str] | None = None,
) -> Campaign:
    """A campaign row (added to `session`) for a stand run or an import, on the stored instrument
    with the same model, serial and constants when there is one, with its `labels`
    (key = value, e.g. factory = A)."""
    constants = {"lp_gcm2s2": header.lp_gcm2s2, "h1_gcm2s": header.h1_gcm2s}
    campaign = Campaign(
        instrument=instrument_for(session, header.model, header.serial, constants),
        plan_toml=header.plan_toml,
        plan_hash=hashlib.sha256(header.plan_toml.encode()).hexdigest(),
        operator=header.operator,
        latitude_deg=header.latitude_deg,
        earth_rate_rad_s=header.earth_rate_rad_s,
        gravity_cm_s2=header.gravity_cm_s2,
        n_obs=header.n_obs,
        status=status,
        source=source,
        started_at=None if source == "import" else datetime.now(UTC),  # stand runs and replays
        software_version=header.software_version,
        labels=[CampaignLabel(key=k, value=v) for k, v in sorted((labels or {}).items())],
    )
    session.add(campaign)
    return campaign


LABEL_KEY = re.compile(r"[a-z][a-z0-9_]{0,63}")
LABEL_VALUE_MAX = 200


def parse_label(text: str) -> tuple[str, str]:
    """`key=value` as a campaign label; ValueError (one line) naming what is wrong: the key is
    lower-case letters, digits and _ (at most 64, starting with a letter), the value printable
    and at most 200 characters."""
    key, sep, value = text.partition("=")
    key, value = key.strip(), value.strip()
    if not sep:
        raise ValueError(f"label {text!r} is not key=value (e.g. factory=A)")
    if not LABEL_KEY.fullmatch(key):
        raise ValueError(
            f"label key {key!r}: use lower-case letters, digits and _, starting with a letter "
            "(at most 64 characters)"
        )
    if not value or len(value) > LABEL_VALUE_MAX or not value.isprintable():
        raise ValueError(
            f"label {key}: the value must be 1 to {LABEL_VALUE_MAX} printable characters"
        )
    return key, value


def campaign_constants(campaign: Campaign) -> dict[str, float]:
    """The known parameters B of seed 000 eq 1.1 for this campaign: lP, H1 (instrument) and
    latitude, Earth rate U, gravity g (site). Keys: lp_gcm2s2, h1_gcm2s, latitude_deg,
    earth_rate_rad_s, gravity_cm_s2."""
    constants = {
        "latitude_deg": campaign.latitude_deg,
        "earth_rate_rad_s": campaign.earth_rate_rad_s,
        "gravity_cm_s2": campaign.gravity_cm_s2,
    }
    constants.update(campaign.instrument.constants_json)
    return constants


@dataclass(frozen=True)
class ResumePoint:
    """Where acquisition continues: series j of trial `trial_index`, at observation `next_k`.
    `series_id` is None when that series row has not been created yet."""

    trial_id: int
    trial_index: int
    j: int
    series_id: int | None
    next_k: int


@dataclass(frozen=True)
class EarlierAttempt:
    """An attempt at a trial that a retry superseded (it failed; its data stay with it)."""

    attempt: int
    status: str
    failure_reason: str | None


@dataclass(frozen=True)
class TrialProgress:
    """What the database holds for one trial (its latest attempt), read by the one resume rule
    (used by acquisition to resume, by `campaign status` and by the report): a series is done
    when it is marked completed or holds N observations; a trial is acquired when it is
    completed or failed (failed trials keep their reason; resume does not acquire them again,
    only a retry, which adds a new attempt) or both its series are done (the process may have
    died before marking it completed). `earlier` lists the attempts it superseded."""

    trial_id: int
    index: int
    role: str
    status: str
    failure_reason: str | None
    n_obs: int
    series_ids: dict[int, int]  # j -> series id
    series_status: dict[int, str]
    observations_by_j: dict[int, int]  # j -> observations stored
    last_k: dict[int, int]  # j -> highest k stored
    attempt: int = 1
    earlier: tuple[EarlierAttempt, ...] = ()

    @property
    def series_done(self) -> frozenset[int]:
        return frozenset(
            j
            for j in SERIES_J
            if self.series_status.get(j) == "completed" or self.last_k.get(j, 0) >= self.n_obs
        )

    @property
    def finished(self) -> bool:
        """Marked completed or failed."""
        return self.status in ("completed", "failed")

    @property
    def acquired(self) -> bool:
        return self.finished or self.series_done == frozenset(SERIES_J)

    @property
    def resume(self) -> ResumePoint | None:
        """The first series of this trial still to acquire (None: the trial is acquired)."""
        if self.acquired:
            return None
        j = next(j for j in SERIES_J if j not in self.series_done)
        return ResumePoint(
            self.trial_id, self.index, j, self.series_ids.get(j), self.last_k.get(j, 0) + 1
        )


def trial_progress(session: Session, campaign_id: int) -> tuple[TrialProgress, ...]:
    """Every trial of the campaign (its latest attempt, by index) with its series' observation
    counts, by SQL aggregates (cheap while a campaign is running in another process)."""
    n_obs = session.scalar(select(Campaign.n_obs).where(Campaign.id == campaign_id))
    if n_obs is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
    series: dict[int, list[tuple[int, int, str, int, int]]] = {}
    for trial_id, series_id, j, status, count, last in session.execute(
        select(
            Series.trial_id,
            Series.id,
            Series.j,
            Series.status,
            func.count(Observation.id),
            func.coalesce(func.max(Observation.k), 0),
        )
        .join(Trial, Trial.id == Series.trial_id)
        .outerjoin(Observation, Observation.series_id == Series.id)
        .where(Trial.campaign_id == campaign_id, latest_attempt())
        .group_by(Series.id)
    ):
        series.setdefault(trial_id, []).append((series_id, j, status, count, last))
    earlier: dict[int, list[EarlierAttempt]] = {}
    for index, attempt, status, reason in session.execute(
        select(Trial.index, Trial.attempt, Trial.status, Trial.failure_reason)
        .where(Trial.campaign_id == campaign_id, ~latest_attempt())
        .order_by(Trial.index, Trial.attempt)
    ):
        earlier.setdefault(index, []).append(EarlierAttempt(attempt, status, reason))
    trials = session.execute(
        select(Trial.id, Trial.index, Trial.attempt, Trial.role, Trial.status, Trial.failure_reason)
        .where(Trial.campaign_id == campaign_id, latest_attempt())
        .order_by(Trial.index)
    )
    return tuple(
        TrialProgress(
            trial_id=trial_id,
            index=index,
            role=role,
            status=status,
            failure_reason=reason,
            n_obs=n_obs,
            series_ids={j: sid for sid, j, _, _, _ in series.get(trial_id, [])},
            series_status={j: st for _, j, st, _, _ in series.get(trial_id, [])},
            observations_by_j={j: n for _, j, _, n, _ in series.get(trial_id, [])},
            last_k={j: k for _, j, _, _, k in series.get(trial_id, [])},
            attempt=attempt,
            earlier=tuple(earlier.get(index, ())),
        )
        for trial_id, index, attempt, role, status, reason in trials
    )


def first_incomplete_series(session: Session, campaign_id: int) -> ResumePoint | None:
    """Where acquisition continues (`TrialProgress.resume` of the first trial not acquired);
    None when nothing is left to acquire."""
    return next(
        (t.resume for t in trial_progress(session, campaign_id) if t.resume is not None), None
    )


def reference_heading(session: Session, trial_id: int) -> float | None:
    """The trial's first stored observation (series 1 first): the reference a resumed trial
    takes its headings about."""
    return session.scalar(
        select(Observation.value_deg)
        .join(Series, Series.id == Observation.series_id)
        .where(Series.trial_id == trial_id)
        .order_by(Series.j, Observation.k)
        .limit(1)
    )


@dataclass(frozen=True)
class CampaignSummary:
    """Where a campaign stands (for `gyrostand campaign status` and the report)."""

    campaign_id: int
    status: str
    source: str
    operator: str
    instrument: str
    n_obs: int
    started_at: datetime | None
    finished_at: datetime | None
    trials: tuple[TrialProgress, ...]
    events_by_severity: dict[str, int]
    resume: ResumePoint | None

    @property
    def trials_completed(self) -> int:
        return sum(t.status == "completed" for t in self.trials)

    @property
    def trials_failed(self) -> int:
        return sum(t.status == "failed" for t in self.trials)

    @property
    def observations_stored(self) -> int:
        return sum(sum(t.observations_by_j.values()) for t in self.trials)


def campaign_summary(session: Session, campaign_id: int) -> CampaignSummary:
    """Where a campaign stands, by SQL aggregates."""
    campaign = session.get(Campaign, campaign_id)
    if campaign is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
    trials = trial_progress(session, campaign_id)
    events = dict.fromkeys(EVENT_SEVERITIES, 0)
    events.update(
        session.execute(
            select(Event.severity, func.count())
            .where(Event.campaign_id == campaign_id)
            .group_by(Event.severity)
        ).all()
    )
    return CampaignSummary(
        campaign_id=campaign.id,
        status=campaign.status,
        source=campaign.source,
        operator=campaign.operator,
        instrument=f"{campaign.instrument.model} #{campaign.instrument.serial}",
        n_obs=campaign.n_obs,
        started_at=campaign.started_at,
        finished_at=campaign.finished_at,
        trials=trials,
        events_by_severity=events,
        resume=next((t.resume for t in trials if t.resume is not None), None),
    )


def raw_log_segments(session: Session, campaign_id: int) -> list[RawLogSegment]:
    """The campaign's raw log files in the order they were written."""
    return list(
        session.scalars(
            select(RawLogSegment)
            .where(RawLogSegment.campaign_id == campaign_id)
            .order_by(RawLogSegment.seq)
        )
    )


@dataclass(frozen=True)
class CampaignFilter:
    """Which campaigns `campaign_list` returns (None: any). `labels`: every key = value must be
    among the campaign's labels (the stand is the label `stand`); `since`/`until`: when the
    campaign started (imports: when they were stored), `until` exclusive; `text`: in the
    operator, instrument model or serial, or a label's key or value, in any case (a substring,
    no wildcards)."""

    model: str | None = None
    serial: str | None = None
    status: str | None = None
    labels: tuple[tuple[str, str], ...] = ()
    since: datetime | None = None
    until: datetime | None = None
    text: str | None = None


def method_checks(results: dict[str, Any]) -> tuple[bool | None, bool | None]:
    """An analysis run's Cochran homogeneity and Fisher adequacy on the trial means, the basis
    the decision stands on (`analysis.adequacy.ADEQUACY_BASIS`; None: the test was not made,
    e.g. Fisher's after Cochran's failed)."""
    return (
        (results.get("cochran") or {}).get("homogeneous"),
        (results.get("adequacy") or {}).get("adequate_mean_basis"),
    )


def verdict(results: dict[str, Any] | None) -> str:
    """An analysis run's results in a few words: Cochran's homogeneity and Fisher's adequacy."""
    if results is None:
        return "not analysed"
    homogeneous, adequate = (
        "?" if value is None else ("yes" if value else "no") for value in method_checks(results)
    )
    return f"homogeneous {homogeneous}, adequate on trial means {adequate}"


@dataclass(frozen=True)
class Estimate:
    """A fitted parameter and its confidence interval."""

    value: float
    low: float
    high: float


@dataclass(frozen=True)
class CampaignResult:
    """The campaign's latest analysis run (recorded by `gyrostand report` or `analyze`): C and T
    with their (1 - q) confidence intervals, Cochran's homogeneity and Fisher's adequacy
    decisions (None: not made), `db.queries.verdict` in words."""

    run_id: int
    confidence: float
    c_gcm2s2: Estimate | None
    t_s: Estimate | None
    homogeneous: bool | None
    adequate: bool | None
    verdict: str


def campaign_result(session: Session, campaign_id: int) -> CampaignResult | None:
    """The result of the campaign's latest analysis run, or None (not analysed)."""
    run = session.scalars(
        select(AnalysisRun)
        .where(AnalysisRun.campaign_id == campaign_id)
        .order_by(AnalysisRun.id.desc())
        .limit(1)
    ).first()
    if run is None:
        return None
    results = run.results_json
    fit = results.get("fit") or {}
    estimates, intervals = fit.get("estimates") or {}, fit.get("confidence_intervals") or {}

    def estimate(name: str) -> Estimate | None:
        if estimates.get(name) is None or name not in intervals:
            return None
        return Estimate(estimates[name], *intervals[name])

    homogeneous, adequate = method_checks(results)
    return CampaignResult(
        run_id=run.id,
        confidence=1.0 - float(results.get("q", 0.05)),
        c_gcm2s2=estimate("C_gcm2s2"),
        t_s=estimate("T_s"),
        homogeneous=homogeneous,
        adequate=adequate,
        verdict=verdict(results),
    )


@dataclass(frozen=True)
class CampaignRow:
    """One campaign of `gyrostand campaign list` and of the station's campaigns page."""

    campaign_id: int
    model: str
    serial: str
    status: str
    source: str
    operator: str
    started_at: datetime
    """When it started (imports: when they were stored)."""
    finished_at: datetime | None
    labels: dict[str, str]
    observations: int
    verdict: str
    """Its latest analysis run's `verdict`."""
    origin: tuple[str, int] | None = None
    """A merged campaign's origin: the file or URL it was merged from and its id there."""


def latest_runs() -> Subquery:
    """Each analysed campaign's latest analysis run: columns campaign_id, run_id."""
    return (
        select(AnalysisRun.campaign_id, func.max(AnalysisRun.id).label("run_id"))
        .group_by(AnalysisRun.campaign_id)
        .subquery()
    )


def campaign_list(session: Session, where: CampaignFilter) -> list[CampaignRow]:
    """The campaigns that pass `where`, by id, with their labels, observation counts and latest
    analysis's verdict."""
    started = func.coalesce(Campaign.started_at, Campaign.created_at)
    query = (
        select(Campaign.id, Instrument.model, Instrument.serial, Campaign.status)
        .add_columns(Campaign.source, Campaign.operator, started, Campaign.finished_at)
        .join(Instrument, Instrument.id == Campaign.instrument_id)
        .order_by(Campaign.id)
    )
    for column, value in (
        (Instrument.model, where.model),
        (Instrument.serial, where.serial),
        (Campaign.status, where.status),
    ):
        if value is not None:
            query = query.where(column == value)
    if where.text is not None:
        labelled = (
            select(CampaignLabel.id)
            .where(
                CampaignLabel.campaign_id == Campaign.id,
                CampaignLabel.key.icontains(where.text, autoescape=True)
                | CampaignLabel.value.icontains(where.text, autoescape=True),
            )
            .exists()
        )
        query = query.where(
            Campaign.operator.icontains(where.text, autoescape=True)
            | Instrument.model.icontains(where.text, autoescape=True)
            | Instrument.serial.icontains(where.text, autoescape=True)
            | labelled
        )
    if where.since is not None:
        query = query.where(started >= where.since)
    if where.until is not None:
        query = query.where(started < where.until)
    for key, value in where.labels:
        query = query.where(
            select(CampaignLabel.id)
            .where(
                CampaignLabel.campaign_id == Campaign.id,
                CampaignLabel.key == key,
                CampaignLabel.value == value,
            )
            .exists()
        )
    rows = session.execute(query).all()
    ids = [row[0] for row in rows]
    labels: dict[int, dict[str, str]] = {i: {} for i in ids}
    for campaign_id, key, value in session.execute(
        select(CampaignLabel.campaign_id, CampaignLabel.key, CampaignLabel.value)
        .where(CampaignLabel.campaign_id.in_(ids))
        .order_by(CampaignLabel.key)
    ):
        labels[campaign_id][key] = value
    counts = dict(
        session.execute(
            select(Trial.campaign_id, func.count(Observation.id))
            .join(Series, Series.trial_id == Trial.id)
            .join(Observation, Observation.series_id == Series.id)
            .where(Trial.campaign_id.in_(ids))
            .group_by(Trial.campaign_id)
        ).all()
    )
    latest = latest_runs()
    results = dict(
        session.execute(
            select(latest.c.campaign_id, AnalysisRun.results_json)
            .join(AnalysisRun, AnalysisRun.id == latest.c.run_id)
            .where(latest.c.campaign_id.in_(ids))
        ).all()
    )
    origins = {
        campaign_id: (merged_from, source_id)
        for campaign_id, merged_from, source_id in session.execute(
            select(
                CampaignOrigin.campaign_id,
                CampaignOrigin.merged_from,
                CampaignOrigin.source_campaign_id,
            ).where(CampaignOrigin.campaign_id.in_(ids))
        )
    }
    return [
        CampaignRow(
            campaign_id=i,
            model=model,
            serial=serial,
            status=status,
            source=source,
            operator=operator,
            started_at=as_utc(started_at),
            finished_at=None if finished_at is None else as_utc(finished_at),
            labels=labels[i],
            observations=counts.get(i, 0),
            verdict=verdict(results.get(i)),
            origin=origins.get(i),
        )
        for i, model, serial, status, source, operator, started_at, finished_at in rows
    ]


def as_utc(value: datetime) -> datetime:
    """A stored wall time as aware UTC (SQLite gives it back naive)."""
    return value if value.tzinfo is not None else value.replace(tzinfo=UTC)


@dataclass(frozen=True)
class AnalysedCampaign:
    """A campaign of one instrument model for fleet statistics: its unit, its value of a label
    key (None: not labelled), when it started and its latest analysis run's results (None: never
    analysed)."""

    campaign_id: int
    serial: str
    label: str | None
    started_at: datetime
    results: dict[str, Any] | None


def model_campaigns(session: Session, model: str, key: str) -> list[AnalysedCampaign]:
    """The completed campaigns of instrument `model`, by id, with their label `key` and latest
    analysis run."""
    latest = latest_runs()
    label = aliased(CampaignLabel)
    rows = session.execute(
        select(
            Campaign.id,
            Instrument.serial,
            label.value,
            func.coalesce(Campaign.started_at, Campaign.created_at),
            AnalysisRun.results_json,
        )
        .join(Instrument, Instrument.id == Campaign.instrument_id)
        .outerjoin(label, (label.campaign_id == Campaign.id) & (label.key == key))
        .outerjoin(latest, latest.c.campaign_id == Campaign.id)
        .outerjoin(AnalysisRun, AnalysisRun.id == latest.c.run_id)
        .where(Instrument.model == model, Campaign.status == "completed")
        .order_by(Campaign.id)
    ).all()
    return [
        AnalysedCampaign(campaign_id, serial, value, as_utc(started), results)
        for campaign_id, serial, value, started, results in rows
    ]


RUN_START = "run start"
"""The event of a resumed run (not a re-run of a simulation) at its first stand time: the
compass's state does not carry over this boundary (`report.transient`)."""


def last_stand_time_ms(session: Session, campaign_id: int) -> int:
    """The latest stand time any run of the campaign stored (0 for none): where a resumed run's
    stand clock goes on from."""
    trial_ids = select(Trial.id).where(Trial.campaign_id == campaign_id)
    series_ids = select(Series.id).where(Series.trial_id.in_(trial_ids))
    latest = [
        select(func.max(Event.stand_time_ms)).where(Event.campaign_id == campaign_id),
        select(func.max(Series.settle_done_ms)).where(Series.id.in_(series_ids)),
        select(func.max(Observation.window_end_ms)).where(Observation.series_id.in_(series_ids)),
    ]
    return max((session.scalar(q) or 0 for q in latest), default=0)


def live_file_of(raw_log: str | Path) -> Path:
    """Where a running acquisition keeps its latest progress snapshot (JSON, deleted when the
    run ends): beside the run's raw log, campaign-ID.live.json."""
    return Path(raw_log).with_suffix(".live.json")


def live_watch_of(live_file: Path) -> Path:
    """Touched by the operator station while a page shows the run's live view (beside the live
    file, campaign-ID.live.watch): the acquisition then rewrites its live file often."""
    return live_file.with_suffix(".watch")


def sign_offs(session: Session, campaign_id: int) -> dict[str, SignOff]:
    """The campaign's signatures (entered at the operator station) by role."""
    rows = session.scalars(select(SignOff).where(SignOff.campaign_id == campaign_id))
    return {s.role: s for s in rows}
