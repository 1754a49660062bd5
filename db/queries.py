"""Queries shared by the acquisition runner, the CLI and the report: a campaign's ORM graph,
where to resume it, how far it has got, and the known constants B of its model."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from gyrostand.db.models import (
    EVENT_SEVERITIES,
    SERIES_J,
    Campaign,
    Event,
    Instrument,
    Observation,
    Series,
    Trial,
)


class CampaignNotFound(LookupError):
    """No campaign with that id in the database."""


def load_campaign(session: Session, campaign_id: int) -> Campaign:
    """The campaign with its instrument, trials (by index), series (by j) and observations (by k)
    loaded in a few SELECTs; events and analysis runs load lazily when touched."""
    campaign = session.scalar(
        select(Campaign)
        .where(Campaign.id == campaign_id)
        .options(
            selectinload(Campaign.instrument),
            selectinload(Campaign.trials)
            .selectinload(Trial.series)
            .selectinload(Series.observations),
        )
    )
    if campaign is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
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


def first_incomplete_series(session: Session, campaign_id: int) -> ResumePoint | None:
    """The first series (by trial index, then j) that is not completed, in a trial that is
    neither completed nor failed (failed trials keep their reason and are not retried).
    A series already holding N observations counts as done even if the process died before
    marking it completed. None when nothing is left to acquire."""
    n_obs = session.scalar(select(Campaign.n_obs).where(Campaign.id == campaign_id))
    if n_obs is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
    last_k = dict(
        session.execute(
            select(Series.id, func.max(Observation.k))
            .join(Observation, Observation.series_id == Series.id)
            .join(Trial, Trial.id == Series.trial_id)
            .where(Trial.campaign_id == campaign_id)
            .group_by(Series.id)
        ).all()
    )
    trials = session.scalars(
        select(Trial)
        .where(Trial.campaign_id == campaign_id, Trial.status.not_in(("completed", "failed")))
        .order_by(Trial.index)
        .options(selectinload(Trial.series))
    )
    for trial in trials:
        by_j = {series.j: series for series in trial.series}
        for j in SERIES_J:
            series = by_j.get(j)
            if series is None:
                return ResumePoint(trial.id, trial.index, j, None, 1)
            done = last_k.get(series.id, 0)
            if series.status != "completed" and done < n_obs:
                return ResumePoint(trial.id, trial.index, j, series.id, done + 1)
    return None


@dataclass(frozen=True)
class TrialProgress:
    """One trial's state: role, status (and failure reason), observations stored per series j."""

    index: int
    role: str
    status: str
    failure_reason: str | None
    observations_by_j: dict[int, int]


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
    """Counts by SQL aggregates (cheap while a campaign is running in another process)."""
    campaign = session.get(Campaign, campaign_id)
    if campaign is None:
        raise CampaignNotFound(f"no campaign {campaign_id} in the database")
    counts: dict[int, dict[int, int]] = {}
    for trial_id, j, n in session.execute(
        select(Series.trial_id, Series.j, func.count(Observation.id))
        .join(Trial, Trial.id == Series.trial_id)
        .outerjoin(Observation, Observation.series_id == Series.id)
        .where(Trial.campaign_id == campaign_id)
        .group_by(Series.trial_id, Series.j)
    ):
        counts.setdefault(trial_id, {})[j] = n
    trials = session.scalars(
        select(Trial).where(Trial.campaign_id == campaign_id).order_by(Trial.index)
    )
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
        trials=tuple(
            TrialProgress(t.index, t.role, t.status, t.failure_reason, counts.get(t.id, {}))
            for t in trials
        ),
        events_by_severity=events,
        resume=first_incomplete_series(session, campaign_id),
    )
