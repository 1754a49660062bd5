"""The engine's results into the database: one short transaction per result, so an observation is
durable the moment it completes and a killed process loses at most the one in progress."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand import SOFTWARE_VERSION
from gyrostand.acquisition.engine import Measured, ObservationResult, TrialState
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.db.lease import take_lease
from gyrostand.db.models import Campaign, Event, Observation, Series, Trial
from gyrostand.db.queries import (
    CampaignHeader,
    latest_attempt,
    new_campaign,
    reference_heading,
    trial_progress,
)
from gyrostand.db.session import writer
from gyrostand.plan.model import Plan


class CampaignStore:
    """Writes one campaign's acquisition results (implements `acquisition.engine.Sink`)."""

    def __init__(self, sessions: sessionmaker[Session], campaign_id: int) -> None:
        self.lease = take_lease(sessions, campaign_id)  # CampaignBusy: another process runs it
        self.sessions = writer(sessions)
        self.campaign_id = campaign_id
        self._session: Session | None = None
        with sessions() as session:
            rows = session.execute(
                select(Trial.index, Trial.id).where(
                    Trial.campaign_id == campaign_id, latest_attempt()
                )
            ).all()
            self._trial_ids = dict(rows)  # type: ignore[arg-type]
            self._series_ids: dict[tuple[int, int], int] = {
                (index, j): sid
                for index, j, sid in session.execute(
                    select(Trial.index, Series.j, Series.id)
                    .join(Series, Series.trial_id == Trial.id)
                    .where(Trial.campaign_id == campaign_id, latest_attempt())
                )
            }

    @classmethod
    def create(
        cls, sessions: sessionmaker[Session], plan: Plan, *, source: str = "stand"
    ) -> CampaignStore:
        """A new campaign (status running) with its instrument and pending trials."""
        header = CampaignHeader(
            model=plan.instrument.model,
            serial=plan.instrument.serial,
            lp_gcm2s2=plan.instrument.lp_gcm2s2,
            h1_gcm2s=plan.instrument.h1_gcm2s,
            latitude_deg=plan.site.latitude_deg,
            earth_rate_rad_s=plan.site.earth_rate_rad_s,
            gravity_cm_s2=plan.site.gravity_cm_s2,
            plan_toml=plan.text,
            operator=plan.operator,
            n_obs=plan.n_obs,
            software_version=SOFTWARE_VERSION,
        )
        with writer(sessions).begin() as session:
            campaign = new_campaign(session, header, status="running", source=source)
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
        """What is stored per trial, for the engine to resume after, by the one resume rule
        (`db.queries.TrialProgress`)."""
        with self.sessions() as session:
            return {
                t.index: TrialState(
                    completed=t.acquired,
                    series_done=t.series_done,
                    committed=t.last_k,
                    reference_deg=None if t.acquired else reference_heading(session, t.trial_id),
                )
                for t in trial_progress(session, self.campaign_id)
            }

    def complete_acquired(self) -> None:
        """Mark completed the trials whose two series hold N observations but that were not
        marked (the process stopped between the last observation and the stand's stop
        acknowledgement), each with an event; their measured motion was not recorded."""
        with self.sessions() as session:
            left = [
                t
                for t in trial_progress(session, self.campaign_id)
                if t.acquired and t.status not in ("completed", "failed")
            ]
        for t in left:
            self.trial_completed(t.index, None)
            self.event(
                "resume",
                "warning",
                f"trial {t.index} completed on resume: both series held their "
                f"{t.n_obs} observations when the previous run stopped; the stand's measured "
                "motion of this trial was not recorded (commanded values apply)",
                t.index,
            )

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

    def series_settled(self, trial: int, j: int, t_ms: int, outcome: SettleOutcome) -> None:
        with self._tx() as session:
            series = self._series(session, trial, j)
            series.status, series.settle_done_ms = "observing", t_ms
            series.settle_estimate_deg = outcome.estimate_deg
            series.settle_outcome = outcome.to_dict()

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
