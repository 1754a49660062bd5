"""The engine's results into the database: an observation is committed the moment it completes (with
the engine's writes held back before it), the engine's other writes at the end of the engine's
call at the latest; a killed process loses at most the observation in progress and what the engine
wrote since the last commit (a prefix of its writes is always what is stored). Fewer transactions
than one per write: each costs an fsync (synchronous=FULL) and 0.5-2 ms of SQLAlchemy (issue 37)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from typing import Concatenate, ParamSpec

from sqlalchemy import delete, insert, select, update
from sqlalchemy.orm import Session, sessionmaker

from gyrostand import SOFTWARE_VERSION
from gyrostand.acquisition.engine import Measured, ObservationResult, SeriesCompensation, TrialState
from gyrostand.acquisition.retry import new_attempt
from gyrostand.acquisition.serial_input import serial_source
from gyrostand.analysis.measured_motion import MeasuredMotion
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.db.lease import take_lease
from gyrostand.db.models import (
    Campaign,
    Event,
    MeasuredMotionRow,
    Observation,
    RawLogSegment,
    Series,
    Trial,
)
from gyrostand.db.queries import (
    CampaignHeader,
    latest_attempt,
    new_campaign,
    raw_log_segments,
    reference_heading,
    trial_progress,
)
from gyrostand.db.session import writer
from gyrostand.devices.decoder import source_info
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import Plan

P = ParamSpec("P")


class ReRunMismatch(RuntimeError):
    """A re-run of a simulated campaign derived another observation than the stored one."""


def _engine_write(
    method: Callable[Concatenate[CampaignStore, Session, P], None],
) -> Callable[Concatenate[CampaignStore, P], None]:
    """One of the engine's writes (the `Sink` methods), counted in campaign.engine_writes and
    committed in order with the others held back: an observation at once (durable the moment
    it completes), any other with the next observation or at the end of the engine's call
    (`flush`), whichever comes first; skipped while a re-run re-derives what earlier runs
    committed (`CampaignStore.re_run`)."""

    @functools.wraps(method)
    def write(self: CampaignStore, *args: P.args, **kwargs: P.kwargs) -> None:
        self._writes += 1
        if self._writes <= self._skip:
            if method.__name__ == "observation":
                self._check_re_derived(*args)  # type: ignore[arg-type]
            return
        self._held.append(lambda session: method(self, session, *args, **kwargs))
        if method.__name__ == "observation" or self._session is not None:
            self.flush()

    return write


class CampaignStore:
    """Writes one campaign's acquisition results (implements `acquisition.engine.Sink`)."""

    def __init__(self, sessions: sessionmaker[Session], campaign_id: int) -> None:
        self.lease = take_lease(sessions, campaign_id)  # CampaignBusy: another process runs it
        self.sessions = writer(sessions)
        self.campaign_id = campaign_id
        self._session: Session | None = None
        self._writes = 0  # the engine's writes so far (counted from the campaign's start)
        self._held: list[Callable[[Session], None]] = []  # its writes not yet committed, in order
        self._skip = 0  # of which committed by earlier runs (a re-run skips them)
        self._stored: dict[tuple[int, int, int], tuple[float, int | None, int | None]] = {}
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
        cls,
        sessions: sessionmaker[Session],
        plan: Plan,
        *,
        source: str = "stand",
        labels: Mapping[str, str] | None = None,
    ) -> CampaignStore:
        """A new campaign (status running) with its instrument, `labels` and pending trials."""
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
            campaign = new_campaign(session, header, status="running", source=source, labels=labels)
            virtual = plan.bus.simulated and plan.bus.timing == "virtual"
            if plan.compass.protocol == "iec61162":
                heading = serial_source(plan).info
            else:
                heading = source_info(
                    codec_for(plan),
                    plan.compass.protocol,
                    virtual,
                    plan.stand.protocol,
                    plan.compass.encoder(),
                )
            campaign.heading_source = heading.protocol
            campaign.heading_time_base = heading.time_base
            campaign.heading_resolution_deg = heading.resolution_deg
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
        """A transaction (durable at once, unless inside `deferred()`) that first writes the
        engine's writes held back, so that rows keep the order they were written in."""
        if self._session is not None:
            self._write_held(self._session)
            yield self._session
            return
        with self.sessions.begin() as session:
            self._write_held(session)
            yield session

    def _write_held(self, session: Session) -> None:
        if not self._held:
            return
        held, self._held = self._held, []
        for write in held:
            write(session)
        # Core statements where nothing reads the row back: 3-5x less CPU than the ORM's unit of
        # work (an ORM get + flush per row was most of a transaction's 0.5-2 ms)
        session.connection().execute(
            update(Campaign.__table__)
            .where(Campaign.__table__.c.id == self.campaign_id)
            .values(engine_writes=self._writes)
        )

    def flush(self) -> None:
        """Commit the engine's writes held back (`Sink.flush`: at the end of each engine call)."""
        if self._held:
            with self._tx():
                pass

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
        acknowledgement), each with an event; their measured motion was not recorded. The
        engine's writes of this run count on from the stored ones."""
        self.continue_counting()
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
        self.flush()

    def redo_uncompensated(self) -> None:
        """Trials stopped inside a compensated series, before its end stored the compensation:
        the transient record it needs went with the stopped run, so its observations (taken
        during the transient) can never be compensated. Each such trial fails with that reason
        and gets a new attempt, as a retry does; the stopped attempt keeps what it committed.
        For a resume that restarts the stand (a re-run in virtual time re-derives the record)."""
        with self._tx() as session:
            stopped = session.scalars(
                select(Series)
                .join(Trial, Series.trial_id == Trial.id)
                .where(
                    Trial.campaign_id == self.campaign_id,
                    latest_attempt(),
                    Series.status != "completed",
                    Series.observations.any(),
                )
            ).all()
            for series in stopped:
                if (series.settle_outcome or {}).get("criterion") != "compensated":
                    continue
                trial = series.trial
                trial.status = "failed"
                trial.failure_reason = (
                    f"stopped in compensated series {series.j}: its observations were taken "
                    "during the transient and the record to compensate them went with the "
                    "stopped run"
                )
                self._trial_ids[trial.index] = new_attempt(session, trial).id
                self._series_ids = {
                    key: sid for key, sid in self._series_ids.items() if key[0] != trial.index
                }

    def set_status(self, status: str) -> None:
        with self._tx() as session:
            campaign = session.get_one(Campaign, self.campaign_id)
            campaign.status = status
            if status in ("completed", "failed", "stopped", "paused"):
                campaign.finished_at = datetime.now(UTC)
            else:
                campaign.finished_at = None

    def open_segment(self, path: str, start: str, first_frame: int = 0) -> int:
        """Reference a raw log file before its first frame is written; its seq."""
        with self._tx() as session:
            seq = len(raw_log_segments(session, self.campaign_id)) + 1
            session.add(
                RawLogSegment(
                    campaign_id=self.campaign_id,
                    seq=seq,
                    path=path,
                    start=start,
                    first_frame=first_frame,
                )
            )
        return seq

    def close_segment(
        self,
        seq: int,
        frames: int,
        sha256: str | None,
        ending: str = "closed",
        serial: tuple[int | None, str | None] | None = None,
    ) -> None:
        """The file's frame count and hash, once nothing more will be written to it; `serial`:
        the lines and hash of the serial log beside it (a serial compass's)."""
        with self._tx() as session:
            segment = session.scalars(
                select(RawLogSegment).where(
                    RawLogSegment.campaign_id == self.campaign_id, RawLogSegment.seq == seq
                )
            ).one()
            segment.frames, segment.sha256, segment.ending = frames, sha256, ending
            if serial is not None:
                segment.serial_lines, segment.serial_sha256 = serial

    # ---------------------------------------------------------------------------------- Sink
    def continue_counting(self) -> None:
        """This run's engine continues where the stored ones stopped (a live resume)."""
        with self.sessions() as session:
            self._writes = session.get_one(Campaign, self.campaign_id).engine_writes

    def re_run(self) -> int:
        """This run's engine starts the campaign again from its beginning (a resumed simulation
        in virtual time, which reproduces the stored run exactly): the engine's writes that
        earlier runs committed are skipped, each re-derived observation checked against the
        stored one (`ReRunMismatch`). The number of writes skipped."""
        with self.sessions() as session:
            self._skip = session.get_one(Campaign, self.campaign_id).engine_writes
            self._stored = {
                (index, j, k): (value, start, end)
                for index, j, k, value, start, end in session.execute(
                    select(
                        Trial.index,
                        Series.j,
                        Observation.k,
                        Observation.value_deg,
                        Observation.window_start_ms,
                        Observation.window_end_ms,
                    )
                    .join(Series, Series.trial_id == Trial.id)
                    .join(Observation, Observation.series_id == Series.id)
                    .where(Trial.campaign_id == self.campaign_id, latest_attempt())
                )
            }
        self._writes = 0
        return self._skip

    def _series(self, session: Session, trial: int, j: int) -> Series:
        sid = self._series_ids.get((trial, j))
        if sid is not None:
            return session.get_one(Series, sid)
        series = Series(trial_id=self._trial_ids[trial], j=j, status="pending")
        session.add(series)
        session.flush()
        self._series_ids[(trial, j)] = series.id
        return series

    @_engine_write
    def trial_started(self, session: Session, trial: int) -> None:
        session.get_one(Trial, self._trial_ids[trial]).status = "running"

    @_engine_write
    def series_settling(self, session: Session, trial: int, j: int, t_ms: int) -> None:
        series = self._series(session, trial, j)
        series.status, series.settle_started_ms, series.settle_done_ms = "settling", t_ms, None

    @_engine_write
    def series_settled(
        self, session: Session, trial: int, j: int, t_ms: int, outcome: SettleOutcome
    ) -> None:
        series = self._series(session, trial, j)
        series.status, series.settle_done_ms = "observing", t_ms
        series.settle_estimate_deg = outcome.estimate_deg
        series.settle_outcome = outcome.to_dict()

    @_engine_write
    def observation(self, session: Session, obs: ObservationResult) -> None:
        sid = self._series_ids.get((obs.trial, obs.j))
        session.connection().execute(
            insert(Observation.__table__),
            {
                "series_id": self._series(session, obs.trial, obs.j).id if sid is None else sid,
                "k": obs.k,
                "value_deg": obs.value_deg,
                "window_start_ms": obs.window_start_ms,
                "window_end_ms": obs.window_end_ms,
                "frames_used": obs.frames_used,
                "frames_lost": obs.frames_lost,
                "flags": obs.flags,
            },
        )

    def _check_re_derived(self, obs: ObservationResult) -> None:
        stored = self._stored.get((obs.trial, obs.j, obs.k))
        again = (obs.value_deg, obs.window_start_ms, obs.window_end_ms)
        if stored != again:
            raise ReRunMismatch(
                f"the re-run of the simulation gives trial {obs.trial} series {obs.j} "
                f"observation {obs.k} = {again}, the database holds {stored}: this campaign "
                "cannot be continued by re-running its simulation"
            )

    @_engine_write
    def series_completed(
        self,
        session: Session,
        trial: int,
        j: int,
        compensation: SeriesCompensation | None = None,
        motion: tuple[MeasuredMotion, ...] = (),
    ) -> None:
        series = self._series(session, trial, j)
        series.status = "completed"
        for m in motion:  # (a resumed series' motion replaces the one measured before)
            session.execute(
                delete(MeasuredMotionRow).where(
                    MeasuredMotionRow.series_id == series.id, MeasuredMotionRow.source == m.source
                )
            )
            session.add(MeasuredMotionRow(series_id=series.id, **dataclasses.asdict(m)))
        if compensation is not None:
            _compensate(session, series, compensation)

    @_engine_write
    def series_compensated(
        self, session: Session, trial: int, j: int, compensation: SeriesCompensation
    ) -> None:
        """A completed uncompensated series compensated by a later fit of its record (the
        latest replaces: `acquisition.early_settle.TransientRecord.late_compensations`)."""
        _compensate(session, self._series(session, trial, j), compensation)

    @_engine_write
    def trial_completed(self, session: Session, trial: int, measured: Measured | None) -> None:
        row = session.get_one(Trial, self._trial_ids[trial])
        row.status = "completed"
        if measured is not None:
            row.meas_direction_deg = measured.direction_deg
            row.meas_amplitude_cm = measured.amplitude_cm
            row.meas_period_s = measured.period_s
            row.meas_source = measured.source

    @_engine_write
    def trial_failed(self, session: Session, trial: int, j: int | None, reason: str) -> None:
        row = session.get_one(Trial, self._trial_ids[trial])
        row.status, row.failure_reason = "failed", reason
        if j is not None:
            self._series(session, trial, j).status = "failed"

    def run_event(self, kind: str, severity: str, message: str, t_ms: int | None = None) -> None:
        """An event of the run rather than of the acquisition (raw log, queue, resume): not one
        of the engine's writes, so never re-derived by a re-run."""
        with self._tx() as session:
            self._add_event(session, kind, severity, message, t_ms=t_ms)

    def _add_event(
        self,
        session: Session,
        kind: str,
        severity: str,
        message: str,
        trial: int | None = None,
        j: int | None = None,
        t_ms: int | None = None,
    ) -> None:
        series = None if trial is None or j is None else self._series_ids.get((trial, j))
        session.connection().execute(
            insert(Event.__table__),
            {
                "campaign_id": self.campaign_id,
                "trial_id": None if trial is None else self._trial_ids[trial],
                "series_id": series,
                "stand_time_ms": t_ms,
                "kind": kind,
                "severity": severity,
                "message": message,
            },
        )

    event = _engine_write(_add_event)  # the engine's events (`Sink.event`)


def _compensate(session: Session, series: Series, compensation: SeriesCompensation) -> None:
    """Store a series' compensation: its SE, shared error and each observation's transient."""
    series.compensation_se_deg = compensation.standard_error_deg
    shared = compensation.shared
    series.compensation_shared = None if shared is None else shared.to_dict()
    ks = range(compensation.first_k, compensation.first_k + len(compensation.transient_deg))
    by_k = dict(zip(ks, compensation.transient_deg, strict=True))
    for obs in session.scalars(select(Observation).where(Observation.series_id == series.id)):
        obs.compensation_deg = by_k.get(obs.k)
