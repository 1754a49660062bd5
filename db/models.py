"""The ORM schema (SQLAlchemy 2 typed declarative): instrument, campaign and its labels, trial,
series, observation, acquisition event, analysis run.

Units are in the column names. Stand times (`*_ms`) are milliseconds of the stand's clock, wall
times are UTC. CHECK, UNIQUE and FOREIGN KEY constraints make impossible states unstorable; every
constraint is named (see `NAMING`) so Alembic can alter it later, also on SQLite.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

CAMPAIGN_STATUSES = ("planned", "running", "paused", "completed", "failed", "stopped")
CAMPAIGN_SOURCES = ("stand", "import", "replay")
TRIAL_ROLES = ("fit", "control")
TRIAL_STATUSES = ("pending", "running", "completed", "failed")
SERIES_J = (1, 2)  # seed 000 eq 2.1: j = 1 before rocking, j = 2 while rocking
SERIES_STATUSES = ("pending", "settling", "observing", "completed", "failed")
EVENT_SEVERITIES = ("info", "warning", "error")
SEGMENT_STARTS = ("new", "continued", "restarted")
SEGMENT_ENDINGS = ("closed", "killed")
MOTION_SOURCES = ("inclinometer", "drive position", "stand report")  # measured_motion.PREFERENCE

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utc_now() -> datetime:
    """The current wall time in UTC (the default of every `*_at` column)."""
    return datetime.now(UTC)


def one_of(column: str, values: tuple[Any, ...]) -> str:
    """SQL for `column IN (values...)`, for a CHECK constraint."""
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


def nonnegative_or_null(column: str) -> str:
    return f"{column} IS NULL OR {column} >= 0"


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)


class Instrument(Base):
    """A gyrocompass under test and its known constants (B in seed 000 eq 1.1)."""

    __tablename__ = "instrument"

    id: Mapped[int] = mapped_column(primary_key=True)
    model: Mapped[str] = mapped_column(String(200))
    serial: Mapped[str] = mapped_column(String(200))
    constants_json: Mapped[dict[str, float]] = mapped_column(JSON)
    """e.g. {"lp_gcm2s2": 6.57e6, "h1_gcm2s": 1.55e8}"""

    campaigns: Mapped[list[Campaign]] = relationship(back_populates="instrument")


class Campaign(Base):
    """One test campaign: a plan run on the stand, imported from a file, or replayed from a log."""

    __tablename__ = "campaign"
    __table_args__ = (
        CheckConstraint(one_of("status", CAMPAIGN_STATUSES), name="status"),
        CheckConstraint(one_of("source", CAMPAIGN_SOURCES), name="source"),
        CheckConstraint("n_obs >= 2", name="n_obs"),
        CheckConstraint("latitude_deg > -90 AND latitude_deg < 90", name="latitude"),
        CheckConstraint("earth_rate_rad_s > 0", name="earth_rate"),
        CheckConstraint("gravity_cm_s2 > 0", name="gravity"),
        CheckConstraint("length(plan_hash) = 64", name="plan_hash"),
        CheckConstraint("engine_writes >= 0", name="engine_writes"),
        CheckConstraint(
            "finished_at IS NULL OR started_at IS NULL OR finished_at >= started_at",
            name="finished_after_start",
        ),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    instrument_id: Mapped[int] = mapped_column(ForeignKey("instrument.id"), index=True)
    plan_toml: Mapped[str] = mapped_column(Text)
    """The plan exactly as submitted."""
    plan_hash: Mapped[str] = mapped_column(String(64))
    """SHA-256 (hex) of `plan_toml`."""
    operator: Mapped[str] = mapped_column(String(200))
    latitude_deg: Mapped[float] = mapped_column(Float)
    earth_rate_rad_s: Mapped[float] = mapped_column(Float, default=7.3e-5)  # seed 000 example
    gravity_cm_s2: Mapped[float] = mapped_column(Float, default=981.0)
    n_obs: Mapped[int] = mapped_column(Integer)
    """N: observations per series (seed 000 eq 2.1)."""
    status: Mapped[str] = mapped_column(String(16), default="planned")
    source: Mapped[str] = mapped_column(String(16), default="stand")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)
    started_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    software_version: Mapped[str] = mapped_column(String(64))
    engine_writes: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    """How many of the acquisition engine's writes are committed (a resumed simulation in virtual
    time re-runs from the start and skips these: `acquisition.catchup`)."""
    heading_source: Mapped[str | None] = mapped_column(String(16))
    """The compass's protocol ([compass] protocol: gyrostand, dbc, nmea2000, ...); None for
    imported measurements."""
    heading_time_base: Mapped[str | None] = mapped_column(Text)
    """How its headings were timed (the stand clock they carry, or their reception time put on
    the stand clock, and how)."""
    heading_resolution_deg: Mapped[float | None] = mapped_column(Float)
    """One step of the transmitted heading, deg (None: not recorded, before schema 0010)."""

    instrument: Mapped[Instrument] = relationship(back_populates="campaigns")
    trials: Mapped[list[Trial]] = relationship(
        back_populates="campaign",
        order_by="(Trial.index, Trial.attempt)",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )
    events: Mapped[list[Event]] = relationship(
        back_populates="campaign",
        order_by="Event.id",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )
    analysis_runs: Mapped[list[AnalysisRun]] = relationship(
        back_populates="campaign",
        order_by="AnalysisRun.id",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )
    raw_logs: Mapped[list[RawLogSegment]] = relationship(
        back_populates="campaign",
        order_by="RawLogSegment.seq",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )
    labels: Mapped[list[CampaignLabel]] = relationship(
        back_populates="campaign",
        order_by="CampaignLabel.key",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )


class CampaignLabel(Base):
    """A label of a campaign, key = value: the factory that made the unit, its production lot,
    the stand that tested it; the factors fleet statistics group campaigns by."""

    __tablename__ = "campaign_label"
    __table_args__ = (
        UniqueConstraint("campaign_id", "key"),
        CheckConstraint("length(key) >= 1", name="key"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    key: Mapped[str] = mapped_column(String(64))
    value: Mapped[str] = mapped_column(String(200))

    campaign: Mapped[Campaign] = relationship(back_populates="labels")


class Trial(Base):
    """Experiment i of a campaign: one rocking condition K, A, tau (seed 000 eq 1.1), in one
    attempt: retrying a failed trial adds a row with the same index and the next attempt; the
    latest attempt is "trial i" (`db.queries.latest_attempt`), earlier ones keep their data.

    `cmd_*` is what was commanded (or, for imports, what the file states); `meas_*` what the
    stand did, as measured (`meas_source`). `summary_*` hold the per-trial values of the
    paper's table when they were imported pre-averaged: <delta_i> (eq 2.1 difference),
    S^2{<delta_i>} (eq 2.3), N."""

    __tablename__ = "trial"
    __table_args__ = (
        UniqueConstraint("campaign_id", "index", "attempt"),
        CheckConstraint('"index" >= 1', name="index"),
        CheckConstraint("attempt >= 1", name="attempt"),
        CheckConstraint(one_of("role", TRIAL_ROLES), name="role"),
        CheckConstraint(one_of("status", TRIAL_STATUSES), name="status"),
        CheckConstraint(
            "status != 'failed' OR failure_reason IS NOT NULL", name="failed_has_reason"
        ),
        CheckConstraint("cmd_direction_deg >= 0 AND cmd_direction_deg < 360", name="cmd_direction"),
        CheckConstraint("cmd_amplitude_cm >= 0", name="cmd_amplitude"),
        CheckConstraint("cmd_period_s > 0", name="cmd_period"),
        CheckConstraint(nonnegative_or_null("meas_amplitude_cm"), name="meas_amplitude"),
        CheckConstraint("meas_period_s IS NULL OR meas_period_s > 0", name="meas_period"),
        CheckConstraint(nonnegative_or_null("summary_delta_var_deg2"), name="summary_var"),
        CheckConstraint("summary_n IS NULL OR summary_n >= 2", name="summary_n"),
        CheckConstraint(nonnegative_or_null("compensation_se_deg"), name="compensation_se"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    index: Mapped[int] = mapped_column("index", Integer)
    """i, 1-based."""
    attempt: Mapped[int] = mapped_column(Integer, default=1, server_default="1")
    """1 for the first attempt at trial i, then 2, 3, ... for each retry."""
    role: Mapped[str] = mapped_column(String(16))
    cmd_direction_deg: Mapped[float] = mapped_column(Float)
    cmd_amplitude_cm: Mapped[float] = mapped_column(Float)
    cmd_period_s: Mapped[float] = mapped_column(Float)
    meas_direction_deg: Mapped[float | None] = mapped_column(Float)
    meas_amplitude_cm: Mapped[float | None] = mapped_column(Float)
    meas_period_s: Mapped[float | None] = mapped_column(Float)
    meas_source: Mapped[str | None] = mapped_column(String(32))
    """Where meas_* come from: "stand report" (the stand controller's own motion reports) or
    "drive position" (a CiA 402 drive's actual position, fitted per period by gyrostand)."""
    status: Mapped[str] = mapped_column(String(16), default="pending")
    failure_reason: Mapped[str | None] = mapped_column(Text)
    summary_delta_mean_deg: Mapped[float | None] = mapped_column(Float)
    summary_delta_var_deg2: Mapped[float | None] = mapped_column(Float)
    summary_n: Mapped[int | None] = mapped_column(Integer)

    campaign: Mapped[Campaign] = relationship(back_populates="trials")
    series: Mapped[list[Series]] = relationship(
        back_populates="trial",
        order_by="Series.j",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )

    @property
    def direction_deg(self) -> float:
        """K actually applied: the stand's measurement when there is one, else the command."""
        return (
            self.cmd_direction_deg if self.meas_direction_deg is None else self.meas_direction_deg
        )

    @property
    def amplitude_cm(self) -> float:
        """A actually applied (measured, else commanded)."""
        return self.cmd_amplitude_cm if self.meas_amplitude_cm is None else self.meas_amplitude_cm

    @property
    def period_s(self) -> float:
        """tau actually applied (measured, else commanded)."""
        return self.cmd_period_s if self.meas_period_s is None else self.meas_period_s


class Series(Base):
    """Series j of trial i: N observations before (j = 1) or during (j = 2) rocking.

    `summary_*` hold an imported pre-averaged series: <delta_ji> (seed 000 eq 2.1),
    S^2{<delta_ji>} (eq 2.2) and N."""

    __tablename__ = "series"
    __table_args__ = (
        UniqueConstraint("trial_id", "j"),
        CheckConstraint(one_of("j", SERIES_J), name="j"),
        CheckConstraint(one_of("status", SERIES_STATUSES), name="status"),
        CheckConstraint(
            "settle_done_ms IS NULL OR settle_started_ms IS NULL"
            " OR settle_done_ms >= settle_started_ms",
            name="settle_order",
        ),
        CheckConstraint(nonnegative_or_null("summary_variance_deg2"), name="summary_variance"),
        CheckConstraint("summary_n IS NULL OR summary_n >= 2", name="summary_n"),
        CheckConstraint(nonnegative_or_null("compensation_se_deg"), name="compensation_se"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    trial_id: Mapped[int] = mapped_column(ForeignKey("trial.id", ondelete="CASCADE"))
    j: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16), default="pending")
    settle_started_ms: Mapped[int | None] = mapped_column(BigInteger)
    settle_done_ms: Mapped[int | None] = mapped_column(BigInteger)
    settle_estimate_deg: Mapped[float | None] = mapped_column(Float)
    # how it settled (analysis.settle.SettleOutcome as a dict; None: not settled or imported)
    settle_outcome: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    summary_mean_deg: Mapped[float | None] = mapped_column(Float)
    summary_variance_deg2: Mapped[float | None] = mapped_column(Float)
    summary_n: Mapped[int | None] = mapped_column(Integer)
    compensation_se_deg: Mapped[float | None] = mapped_column(Float)
    """Compensated series: the SE of the mean of its compensated observations (the settle point
    fitted to them plus their mean residual, `analysis.transient.compensated_mean_se`; stored
    before issue 34's fix: the settle point's SE)."""
    compensation_shared: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    """Compensated series: its share in the period and damping error the compensation used
    (`analysis.gls.SharedError.to_dict`); NULL: not compensated, or stored before schema 0023."""

    trial: Mapped[Trial] = relationship(back_populates="series")
    observations: Mapped[list[Observation]] = relationship(
        back_populates="series",
        order_by="Observation.k",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )
    motions: Mapped[list[MeasuredMotionRow]] = relationship(
        back_populates="series",
        order_by="MeasuredMotionRow.id",
        cascade="all, delete-orphan",
        passive_deletes=True,
    )


class MeasuredMotionRow(Base):
    """The motion the stand really made during a rocking series, per measuring source
    (`analysis.measured_motion`): Potemkin 1982 model 1.1's A (cm) and tau (s), K where the
    source knows it, the phase, their scatter over the fitted cycles (or the stand's reports),
    and how many. Written with the series' completion."""

    __tablename__ = "measured_motion"
    __table_args__ = (
        UniqueConstraint("series_id", "source"),
        CheckConstraint(one_of("source", MOTION_SOURCES), name="source"),
        CheckConstraint("amplitude_cm >= 0", name="amplitude"),
        CheckConstraint("period_s > 0", name="period"),
        CheckConstraint("n_samples >= 1", name="n_samples"),
        CheckConstraint("n_cycles IS NULL OR n_cycles >= 1", name="n_cycles"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    series_id: Mapped[int] = mapped_column(ForeignKey("series.id", ondelete="CASCADE"))
    source: Mapped[str] = mapped_column(String(32))
    amplitude_cm: Mapped[float] = mapped_column(Float)
    amplitude_se_cm: Mapped[float] = mapped_column(Float)
    amplitude_sd_cm: Mapped[float] = mapped_column(Float)
    period_s: Mapped[float] = mapped_column(Float)
    period_se_s: Mapped[float] = mapped_column(Float)
    period_sd_s: Mapped[float] = mapped_column(Float)
    direction_deg: Mapped[float | None] = mapped_column(Float)
    phase_deg: Mapped[float | None] = mapped_column(Float)
    """Of sin at the first fitted cycle's start (`first_cycle_ms`); NULL for reports."""
    phase_sd_deg: Mapped[float | None] = mapped_column(Float)
    first_cycle_ms: Mapped[int | None] = mapped_column(BigInteger)
    n_cycles: Mapped[int | None] = mapped_column(Integer)
    """Cycles fitted (NULL: the stand's reports, averaged)."""
    n_samples: Mapped[int] = mapped_column(Integer)

    series: Mapped[Series] = relationship(back_populates="motions")


class Observation(Base):
    """Observation k of a series: the mean heading over one window (delta_jik, seed 000 eq 2.1).

    Window bounds and frame counts are NULL for imported manual readings."""

    __tablename__ = "observation"
    __table_args__ = (
        UniqueConstraint("series_id", "k"),
        CheckConstraint("k >= 1", name="k"),
        CheckConstraint(
            "window_end_ms IS NULL OR window_start_ms IS NULL OR window_end_ms >= window_start_ms",
            name="window_order",
        ),
        CheckConstraint(nonnegative_or_null("frames_used"), name="frames_used"),
        CheckConstraint(nonnegative_or_null("frames_lost"), name="frames_lost"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    series_id: Mapped[int] = mapped_column(ForeignKey("series.id", ondelete="CASCADE"))
    k: Mapped[int] = mapped_column(Integer)
    value_deg: Mapped[float] = mapped_column(Float)
    window_start_ms: Mapped[int | None] = mapped_column(BigInteger)
    window_end_ms: Mapped[int | None] = mapped_column(BigInteger)
    frames_used: Mapped[int | None] = mapped_column(Integer)
    frames_lost: Mapped[int | None] = mapped_column(Integer)
    flags: Mapped[str] = mapped_column(String(200), default="")
    """Comma-separated anomaly flags (empty when clean)."""
    compensation_deg: Mapped[float | None] = mapped_column(Float)
    """The fitted transient over the window (compensated series; NULL: not compensated)."""

    @property
    def corrected_deg(self) -> float:
        """The reading the analysis uses: value_deg minus the compensation, if any."""
        return self.value_deg - (self.compensation_deg or 0.0)

    series: Mapped[Series] = relationship(back_populates="observations")


class Event(Base):
    """An acquisition event: fault, warning, operator action, import."""

    __tablename__ = "event"
    __table_args__ = (CheckConstraint(one_of("severity", EVENT_SEVERITIES), name="severity"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(
        ForeignKey("campaign.id", ondelete="CASCADE"), index=True
    )
    trial_id: Mapped[int | None] = mapped_column(ForeignKey("trial.id", ondelete="CASCADE"))
    series_id: Mapped[int | None] = mapped_column(ForeignKey("series.id", ondelete="CASCADE"))
    stand_time_ms: Mapped[int | None] = mapped_column(BigInteger)
    wall_time: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)
    kind: Mapped[str] = mapped_column(String(64))
    severity: Mapped[str] = mapped_column(String(16))
    message: Mapped[str] = mapped_column(Text)

    campaign: Mapped[Campaign] = relationship(back_populates="events")


class RawLogSegment(Base):
    """One raw CAN log file of a campaign: the first run's (seq 1), then one per resume.

    `start`: "new" (the first run, or a replayed log), "continued" (a resumed simulation in
    virtual time: its frames continue the earlier segments' stream exactly, from stream position
    `first_frame`), "restarted" (a resume that started the stand again at the first incomplete
    series). `sha256` and `frames` are set when the run closes the file with every frame of the
    run in it ("closed"), or, for a log that ends before its run did ("killed": left open by a
    killed run, found by a later resume; or a write that failed, e.g. on a full disk, which stops
    the run), with the frames readable up to its last complete block. A serial compass's
    sentences are in a log beside it (its name with `.nmea`, IEC 61162-450 TAG blocks):
    `serial_lines` and `serial_sha256` when closed as `frames` and `sha256` are."""

    __tablename__ = "raw_log_segment"
    __table_args__ = (
        UniqueConstraint("campaign_id", "seq"),
        CheckConstraint("seq >= 1", name="seq"),
        CheckConstraint(one_of("start", SEGMENT_STARTS), name="start"),
        CheckConstraint("ending IS NULL OR " + one_of("ending", SEGMENT_ENDINGS), name="ending"),
        CheckConstraint("first_frame >= 0", name="first_frame"),
        CheckConstraint(nonnegative_or_null("frames"), name="frames"),
        CheckConstraint("sha256 IS NULL OR length(sha256) = 64", name="sha256"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaign.id", ondelete="CASCADE"))
    seq: Mapped[int] = mapped_column(Integer)
    path: Mapped[str] = mapped_column(Text)
    start: Mapped[str] = mapped_column(String(16))
    first_frame: Mapped[int] = mapped_column(BigInteger, default=0)
    frames: Mapped[int | None] = mapped_column(BigInteger)
    sha256: Mapped[str | None] = mapped_column(String(64))
    ending: Mapped[str | None] = mapped_column(String(16))
    serial_lines: Mapped[int | None] = mapped_column(BigInteger)
    serial_sha256: Mapped[str | None] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)

    campaign: Mapped[Campaign] = relationship(back_populates="raw_logs")


class AnalysisRun(Base):
    """One analysis of a campaign: which inputs (hash), what came out (JSON), by which code."""

    __tablename__ = "analysis_run"
    __table_args__ = (CheckConstraint("length(inputs_hash) = 64", name="inputs_hash"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(
        ForeignKey("campaign.id", ondelete="CASCADE"), index=True
    )
    inputs_hash: Mapped[str] = mapped_column(String(64))
    """SHA-256 (hex) of the analysed inputs."""
    results_json: Mapped[dict[str, Any]] = mapped_column(JSON)
    software_version: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)

    campaign: Mapped[Campaign] = relationship(back_populates="analysis_runs")


SIGN_OFF_ROLES = ("tested_by", "checked_by")


PROCEDURES_RAW_LOG = "raw_log"
"""The key of the procedures' raw log in `ProcedureRun.results_json` ({"path": ...}, with its
frames and SHA-256 once the procedures are done): from when the log is opened, so that a
campaign stopped before its trials began still names it (`db.removal`)."""


class ProcedureRun(Base):
    """The results of the standard's own procedures of a campaign (settling, settle point,
    repeatability, rolling: `analysis.procedures.ProcedureResults` as JSON), one per campaign."""

    __tablename__ = "procedure_run"

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(
        ForeignKey("campaign.id", ondelete="CASCADE"), unique=True
    )
    results_json: Mapped[dict[str, Any]] = mapped_column(JSON)
    software_version: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)


class SignOff(Base):
    """A signature on a campaign's report: who tested it, who checked it (ISO/IEC 17025, 7.8.2),
    entered at the operator station. One per role; the checker is not the tester."""

    __tablename__ = "sign_off"
    __table_args__ = (
        UniqueConstraint("campaign_id", "role"),
        CheckConstraint(one_of("role", SIGN_OFF_ROLES), name="role"),
        CheckConstraint("length(name) > 0", name="name"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(
        ForeignKey("campaign.id", ondelete="CASCADE"), index=True
    )
    role: Mapped[str] = mapped_column(String(16))
    name: Mapped[str] = mapped_column(String(200))
    signed_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)


class CampaignOrigin(Base):
    """Where a merged campaign comes from (`gyrostand db merge`): the database it was recorded
    in (`db.merge.database_identity`), its id there, the SHA-256 of its content when merged
    (`db.merge.content_sha256`), from which file or URL, when and by which software."""

    __tablename__ = "campaign_origin"
    __table_args__ = (
        UniqueConstraint("source_database", "source_campaign_id"),
        CheckConstraint("length(content_sha256) = 64", name="content_sha256"),
        CheckConstraint("source_campaign_id >= 1", name="source_campaign_id"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(
        ForeignKey("campaign.id", ondelete="CASCADE"), unique=True
    )
    source_database: Mapped[str] = mapped_column(String(36))
    source_campaign_id: Mapped[int] = mapped_column(Integer)
    content_sha256: Mapped[str] = mapped_column(String(64))
    merged_from: Mapped[str] = mapped_column(Text)
    merged_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)
    software_version: Mapped[str] = mapped_column(String(64))


class CampaignRemoval(Base):
    """A campaign removed from the database (`gyrostand campaign remove`), kept as provenance:
    its id here, the SHA-256 of its content (`db.merge.content_sha256`: the same as a copy
    kept elsewhere), what it was (`record`: instrument, status, source, operator, dates,
    plan hash, labels, origin, raw logs with their SHA-256), who removed it, when, why, by
    which software, and what became of its raw log files (`raw_logs`: kept or deleted)."""

    __tablename__ = "campaign_removal"
    __table_args__ = (
        CheckConstraint("length(content_sha256) = 64", name="content_sha256"),
        CheckConstraint("length(removed_by) > 0", name="removed_by"),
        CheckConstraint(one_of("raw_logs", ("kept", "deleted", "none")), name="raw_logs"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    campaign_id: Mapped[int] = mapped_column(Integer, index=True)
    content_sha256: Mapped[str] = mapped_column(String(64))
    record: Mapped[dict[str, Any]] = mapped_column(JSON)
    removed_by: Mapped[str] = mapped_column(String(200))
    reason: Mapped[str | None] = mapped_column(Text)
    raw_logs: Mapped[str] = mapped_column(String(16))
    removed_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utc_now)
    software_version: Mapped[str] = mapped_column(String(64))
