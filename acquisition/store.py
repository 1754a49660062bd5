"""The engine's results into the database: one short transaction per result, so an observation is
durable the moment it completes and a killed process loses at most the one in progress."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand import SOFTWARE_VERSION
from gyrostand.acquisition.engine import Measured, ObservationResult, TrialState
from gyrostand.db.models import Campaign, Event, Observation, Series, Trial
from gyrostand.db.queries import instrument_for
from gyrostand.plan.model import Plan


class CampaignStore:
    """Writes one campaign's acquisition results (implements `acquisition.engine.Sink`)."""

    def __init__(self, sessions: sessionmaker[Session], campaign_id: int) -> None:
        self.sessions = sessions
        self.campaign_id = campaign_id
        self._session: Session | None = None
        with sessions() as session:
            rows = session.execute(
                select(Trial.index, Trial.id).where(Trial.campaign_id == campaign_id)
            ).all()
            self._trial_ids = dict(rows)  # type: ignore[arg-type]
            self._series_ids: dict[tuple[int, int], int] = {
                (index, j): sid
                for index, j, sid in session.execute(
                    select(Trial.index, Series.j, Series.id)
                    .join(Series, Series.trial_id == Trial.id)
                    .where(Trial.campaign_id == campaign_id)
                )
            }

    @classmethod
    def create(
        cls, sessions: sessionmaker[Session], plan: Plan, *, source: str = "stand"
    ) -> CampaignStore:
        """A new campaign (status running) with its instrument and pending trials."""
        with sessions.begin() as session:
            instrument = instrument_for(
                session,
                plan.instrument.model,
                plan.instrument.serial,
                {"lp_gcm2s2": plan.instrument.lp_gcm2s2, "h1_gcm2s": plan.instrument.h1_gcm2s},
            )
            campaign = Campaign(
                instrument=instrument,
                plan_toml=plan.text,
                plan_hash=plan.sha256,
                operator=plan.operator,
                latitude_deg=plan.site.latitude_deg,
                earth_rate_rad_s=plan.site.earth_rate_rad_s,
                gravity_cm_s2=plan.site.gravity_cm_s2,
                n_obs=plan.n_obs,
                status="running",
                source=source,
                started_at=datetime.now(UTC),
                software_version=SOFTWARE_VERSION,
            )
            session.add(campaign)
            for t in plan.trials:
                session.add(
                    Trial(
                        campaign=campaign,
                        index=t.index,
                        role=t.role,
                        cmd_direction_deg=t.direction_deg,
                        cmd_amplitude_cm=t.amplitude_cm,
                        cmd_period_s=t.period_s,
                        status="pending",
                    )
                )
            session.flush()
            campaign_id = campaign.id
        return cls(sessions, campaign_id)

    @contextmanager
    def _tx(self) -> Iterator[Session]:
        """A transaction per write (durable at once), unless inside `deferred()`."""
        if self._session is not None:
            yield self._session
            return
        with self.sessions.begin() as session:
            yield session

    @contextmanager
    def deferred(self) -> Iterator[None]:
        """Everything written inside goes in one transaction (replay: all or nothing, and no
        commit per observation when durability comes from the log itself)."""
        with self.sessions.begin() as session:
            self._session = session
            try:
                yield
            finally:
                self._session = None

    # ------------------------------------------------------------------------ campaign level
    def progress(self) -> dict[int, TrialState]:
        """What is stored per trial, for the engine to resume after. A series holding N
        observations counts as done; failed trials are not retried (their reason stays)."""
        with self.sessions() as session:
            n_obs = session.get_one(Campaign, self.campaign_id).n_obs
            trials = session.scalars(select(Trial).where(Trial.campaign_id == self.campaign_id))
            state: dict[int, TrialState] = {}
            for trial in trials:
                committed = {
                    j: k
                    for j, k in session.execute(
                        select(Series.j, func.max(Observation.k))
                        .join(Observation, Observation.series_id == Series.id)
                        .where(Series.trial_id == trial.id)
                        .group_by(Series.j)
                    )
                }
                done = {
                    s.j
                    for s in trial.series
                    if s.status == "completed" or committed.get(s.j, 0) >= n_obs
                }
                first = session.scalar(
                    select(Observation.value_deg)
                    .join(Series, Series.id == Observation.series_id)
                    .where(Series.trial_id == trial.id)
                    .order_by(Series.j, Observation.k)
                    .limit(1)
                )
                state[trial.index] = TrialState(
                    completed=trial.status in ("completed", "failed"),
                    series_done=frozenset(done),
                    committed=committed,
                    reference_deg=first,
                )
            return state

    def set_status(self, status: str) -> None:
        with self._tx() as session:
            campaign = session.get_one(Campaign, self.campaign_id)
            campaign.status = status
            if status in ("completed", "failed", "stopped", "paused"):
                campaign.finished_at = datetime.now(UTC)
            else:
                campaign.finished_at = None

    def raw_log(self) -> tuple[str | None, str | None]:
        with self.sessions() as session:
            campaign = session.get_one(Campaign, self.campaign_id)
            return campaign.raw_log_path, campaign.raw_log_sha256

    def set_raw_log(self, path: str, sha256: str | None) -> None:
        with self._tx() as session:
            campaign = session.get_one(Campaign, self.campaign_id)
            campaign.raw_log_path, campaign.raw_log_sha256 = path, sha256

    # ---------------------------------------------------------------------------------- Sink
    def _series(self, session: Session, trial: int, j: int) -> Series:
        sid = self._series_ids.get((trial, j))
        if sid is not None:
            return session.get_one(Series, sid)
        series = Series(trial_id=self._trial_ids[trial], j=j, status="pending")
        session.add(series)
        session.flush()
        self._series_ids[(trial, j)] = series.id
        return series

    def trial_started(self, trial: int) -> None:
        with self._tx() as session:
            session.get_one(Trial, self._trial_ids[trial]).status = "running"

    def series_settling(self, trial: int, j: int, t_ms: int) -> None:
        with self._tx() as session:
            series = self._series(session, trial, j)
            series.status, series.settle_started_ms, series.settle_done_ms = "settling", t_ms, None

    def series_settled(self, trial: int, j: int, t_ms: int, estimate_deg: float) -> None:
        with self._tx() as session:
            series = self._series(session, trial, j)
            series.status, series.settle_done_ms = "observing", t_ms
            series.settle_estimate_deg = estimate_deg

    def observation(self, obs: ObservationResult) -> None:
        with self._tx() as session:
            series = self._series(session, obs.trial, obs.j)
            session.add(
                Observation(
                    series_id=series.id,
                    k=obs.k,
                    value_deg=obs.value_deg,
                    window_start_ms=obs.window_start_ms,
                    window_end_ms=obs.window_end_ms,
                    frames_used=obs.frames_used,
                    frames_lost=obs.frames_lost,
                    flags=obs.flags,
                )
            )

    def series_completed(self, trial: int, j: int) -> None:
        with self._tx() as session:
            self._series(session, trial, j).status = "completed"

    def trial_completed(self, trial: int, measured: Measured | None) -> None:
        with self._tx() as session:
            row = session.get_one(Trial, self._trial_ids[trial])
            row.status = "completed"
            if measured is not None:
                row.meas_direction_deg = measured.direction_deg
                row.meas_amplitude_cm = measured.amplitude_cm
                row.meas_period_s = measured.period_s

    def trial_failed(self, trial: int, j: int | None, reason: str) -> None:
        with self._tx() as session:
            row = session.get_one(Trial, self._trial_ids[trial])
            row.status, row.failure_reason = "failed", reason
            if j is not None:
                self._series(session, trial, j).status = "failed"

    def event(
        self,
        kind: str,
        severity: str,
        message: str,
        trial: int | None = None,
        j: int | None = None,
        t_ms: int | None = None,
    ) -> None:
        with self._tx() as session:
            session.add(
                Event(
                    campaign_id=self.campaign_id,
                    trial_id=None if trial is None else self._trial_ids[trial],
                    series_id=None
                    if trial is None or j is None
                    else self._series_ids.get((trial, j)),
                    stand_time_ms=t_ms,
                    kind=kind,
                    severity=severity,
                    message=message,
                )
            )
