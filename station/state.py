"""What the station shows of a campaign, read from the database that the acquisition process
writes: its live state (progress, current series, trace, events). The campaign list is
`db.queries.campaign_list`."""

from __future__ import annotations

import json
import re
import statistics
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from gyrostand.db.models import (
    AnalysisRun,
    Campaign,
    Event,
    Observation,
    RawLogSegment,
    Series,
    Trial,
)
from gyrostand.db.queries import (
    CampaignResult,
    campaign_result,
    campaign_summary,
    latest_attempt,
    live_file_of,
    raw_log_segments,
)

TRACE_POINTS = 600
"""Points of the heading trace sent to the page: about what a screen's plot is wide."""
EVENTS_SHOWN = 50


@dataclass(frozen=True)
class TrialLine:
    """A trial of the campaign page: progress, commanded and measured K, A, tau."""

    index: int
    attempt: int
    role: str
    status: str
    failure_reason: str | None
    observations: dict[int, int]
    commanded: tuple[float, float, float]
    measured: tuple[float | None, float | None, float | None]


@dataclass(frozen=True)
class Current:
    """The series being acquired: where, in which phase, and its statistics so far."""

    trial: int
    attempt: int
    j: int
    phase: str
    k: int
    mean_deg: float | None
    spread_deg: float | None
    settle_estimate_deg: float | None


STOP_REASONS = ("interrupted", "failed")
"""Event kinds that say why a campaign stopped, paused or failed (with any error event)."""


@dataclass(frozen=True)
class LiveState:
    """A campaign as the page shows it; `as_json()` is what the update stream sends.

    `trace` holds (stand time s, observation mean deg) of every stored observation window,
    decimated to `TRACE_POINTS`; ETAs extrapolate the stand and wall time per observation so
    far (None before the first observation)."""

    campaign_id: int
    status: str
    instrument: str
    operator: str
    n_obs: int
    n_trials: int
    observations: int
    observations_planned: int
    current: Current | None
    trials: tuple[TrialLine, ...]
    stand_time_s: float | None
    eta_stand_s: float | None
    eta_wall_s: float | None
    trace: tuple[tuple[float, float], ...]
    events: tuple[dict[str, Any], ...]
    reason: str | None
    """Why it stopped, paused or failed: the stored event that says so (None otherwise)."""
    result: CampaignResult | None

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


def fingerprint(session: Session, campaign_id: int) -> tuple[Any, ...]:
    """A few aggregates that change whenever the acquisition writes something the campaign
    page shows (status, an event, a run, an observation, a series' or trial's status): the update
    stream builds the whole state only when they change."""
    head = session.execute(
        select(
            select(Campaign.status).where(Campaign.id == campaign_id).scalar_subquery(),
            select(func.max(Event.id)).where(Event.campaign_id == campaign_id).scalar_subquery(),
            select(func.max(RawLogSegment.seq))  # a new run: a new live file
            .where(RawLogSegment.campaign_id == campaign_id)
            .scalar_subquery(),
            select(func.max(Observation.id))
            .join(Series, Series.id == Observation.series_id)
            .join(Trial, Trial.id == Series.trial_id)
            .where(Trial.campaign_id == campaign_id)
            .scalar_subquery(),
            select(func.max(AnalysisRun.id))  # analysed: the result to show
            .where(AnalysisRun.campaign_id == campaign_id)
            .scalar_subquery(),
        )
    ).one()
    steps = session.execute(
        select(Trial.status, Series.status, func.count())
        .join(Series, Series.trial_id == Trial.id, isouter=True)
        .where(Trial.campaign_id == campaign_id)
        .group_by(Trial.status, Series.status)
        .order_by(Trial.status, Series.status)
    ).all()
    return (*head, *map(tuple, steps))


def live_file(session: Session, campaign_id: int) -> Path | None:
    """The live file of the campaign's latest run (it exists while that run acquires)."""
    segments = raw_log_segments(session, campaign_id)
    return live_file_of(segments[-1].path) if segments else None


def read_live(path: Path | None) -> dict[str, Any] | None:
    """The running acquisition's latest snapshot (`acquisition.progress.LiveFile`), or None."""
    if path is None:
        return None
    try:
        return dict(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError):
        return None


def decimate(
    points: list[tuple[float, float]], limit: int = TRACE_POINTS
) -> list[tuple[float, float]]:
    """At most `limit` points: the lowest and highest value of each of limit/2 equal slices
    (in time order), so that spikes stay visible."""
    if len(points) <= limit:
        return points
    buckets = limit // 2
    size = len(points) / buckets
    out: list[tuple[float, float]] = []
    for b in range(buckets):
        chunk = points[round(b * size) : round((b + 1) * size)]
        low = min(chunk, key=lambda p: p[1])
        high = max(chunk, key=lambda p: p[1])
        out.extend(sorted({low, high}))
    return out


def live_state(session: Session, campaign_id: int) -> LiveState:
    """The campaign's state now (CampaignNotFound when there is none)."""
    summary = campaign_summary(session, campaign_id)
    campaign = session.get_one(Campaign, campaign_id)
    rows = session.execute(
        select(Trial).where(Trial.campaign_id == campaign_id, latest_attempt())
    ).scalars()
    by_id = {t.id: t for t in rows}
    trials = tuple(
        TrialLine(
            index=p.index,
            attempt=p.attempt,
            role=p.role,
            status=p.status,
            failure_reason=p.failure_reason,
            observations=dict(p.observations_by_j),
            commanded=(
                by_id[p.trial_id].cmd_direction_deg,
                by_id[p.trial_id].cmd_amplitude_cm,
                by_id[p.trial_id].cmd_period_s,
            ),
            measured=(
                by_id[p.trial_id].meas_direction_deg,
                by_id[p.trial_id].meas_amplitude_cm,
                by_id[p.trial_id].meas_period_s,
            ),
        )
        for p in summary.trials
    )
    trace = [
        (end / 1000.0, value)
        for end, value in session.execute(
            select(Observation.window_end_ms, Observation.value_deg)
            .join(Series, Series.id == Observation.series_id)
            .join(Trial, Trial.id == Series.trial_id)
            .where(Trial.campaign_id == campaign_id, Observation.window_end_ms.is_not(None))
            .order_by(Observation.window_end_ms, Observation.id)  # in stand time, over runs
        )
    ]
    events = tuple(
        {
            "id": e.id,
            "stand_time_s": None if e.stand_time_ms is None else e.stand_time_ms / 1000,
            "wall_time": e.wall_time.isoformat(timespec="seconds"),
            "kind": e.kind,
            "severity": e.severity,
            "message": e.message,
        }
        for e in reversed(
            session.scalars(
                select(Event)
                .where(Event.campaign_id == campaign_id)
                .order_by(Event.id.desc())
                .limit(EVENTS_SHOWN)
            ).all()
        )
    )
    done = summary.observations_stored
    planned = 2 * summary.n_obs * len(trials)
    stand_now = trace[-1][0] if trace else None
    eta_stand = eta_wall = None
    if done and stand_now is not None and campaign.started_at is not None:
        left = planned - done
        eta_stand = stand_now / done * left
        started = campaign.started_at
        if started.tzinfo is None:  # SQLite gives naive UTC times back
            started = started.replace(tzinfo=UTC)
        end = campaign.finished_at or datetime.now(UTC)
        if end.tzinfo is None:
            end = end.replace(tzinfo=UTC)
        eta_wall = (end - started).total_seconds() / done * left
    return LiveState(
        campaign_id=campaign_id,
        status=summary.status,
        instrument=summary.instrument,
        operator=summary.operator,
        n_obs=summary.n_obs,
        n_trials=len(trials),
        observations=done,
        observations_planned=planned,
        current=_current(session, summary.resume),
        trials=trials,
        stand_time_s=stand_now,
        eta_stand_s=eta_stand,
        eta_wall_s=eta_wall,
        trace=tuple(decimate(trace)),
        events=events,
        reason=_reason(summary.status, events),
        result=campaign_result(session, campaign_id),
    )


def _reason(status: str, events: tuple[dict[str, Any], ...]) -> str | None:
    if status not in ("stopped", "paused", "failed"):
        return None
    why = [e for e in events if e["kind"] in STOP_REASONS or e["severity"] == "error"]
    return why[-1]["message"] if why else None


def report_files(folder: Path, campaign_id: int) -> list[Path]:
    """The report files of the campaign in `folder` (campaign-ID.html, campaign-ID-trials.csv,
    ... whatever their profile), newest first."""
    name = re.compile(rf"campaign-{campaign_id}([.-].*)?\.(html|pdf|json|csv)")
    try:
        found = [p for p in folder.iterdir() if name.fullmatch(p.name) and p.is_file()]
    except OSError:
        return []
    return sorted(found, key=lambda p: (-p.stat().st_mtime_ns, p.name))


def report_decision(folder: Path, campaign_id: int) -> str | None:
    """The conformity decision of the campaign's newest JSON report in `folder`, or None when
    there is none."""
    newest = next((p for p in report_files(folder, campaign_id) if p.suffix == ".json"), None)
    return None if newest is None else conformity_verdict(newest)


def conformity_verdict(report_json: Path) -> str | None:
    """A JSON report's overall decision (PASS, FAIL, INCONCLUSIVE, NOT ASSESSED), or None when
    it cannot be read."""
    try:
        return str(json.loads(report_json.read_text(encoding="utf-8"))["conformity"]["verdict"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _current(session: Session, resume: Any) -> Current | None:
    """The first series not acquired (where the campaign is, or will continue)."""
    if resume is None:
        return None
    trial = session.get_one(Trial, resume.trial_id)
    series = None if resume.series_id is None else session.get(Series, resume.series_id)
    values = (
        []
        if series is None
        else list(
            session.scalars(
                select(Observation.value_deg)
                .where(Observation.series_id == series.id)
                .order_by(Observation.k)
            )
        )
    )
    status = "pending" if series is None else series.status
    phase = f"{status}, rocking" if resume.j == 2 and status != "pending" else status
    return Current(
        trial=resume.trial_index,
        attempt=trial.attempt,
        j=resume.j,
        phase=phase,
        k=resume.next_k,
        mean_deg=statistics.fmean(values) if values else None,
        spread_deg=statistics.stdev(values) if len(values) > 1 else None,
        settle_estimate_deg=None if series is None else series.settle_estimate_deg,
    )
