"""The report's inputs as plain frozen dataclasses: what the campaign was (identification, plan),
how it was acquired (per-trial commanded vs measured motion, frame counts, every event) and the
heading record the plots show. `report.stored` fills them from the database and the raw CAN
log; the renderers never see the database.

Times: stand times in milliseconds of the stand's clock (``*_ms``), wall times as ISO 8601 text.
"""

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.campaign import LeftOutTrial
from gyrostand.analysis.procedures import ProcedureResults
from gyrostand.analysis.settle import SettleOutcome

NOT_STATED = "not stated"  # an identification item the plan does not give


@dataclass(frozen=True)
class RawLogFile:
    """One raw CAN log file of the campaign (a segment: the first run's, or a resume's)."""

    path: str
    sha256: str | None
    frames: int | None
    start: str  # new | continued (one stream with the earlier ones) | restarted
    ending: str | None  # closed | killed (left open by a killed run) | None (being written)


@dataclass(frozen=True)
class Identification:
    """Section 1: who, what, where, with which software, from which records."""

    campaign_id: int
    instrument_model: str
    instrument_serial: str
    manufacturer: str  # the plan's [instrument] manufacturer, "not stated" when it gives none
    operator: str
    source: str  # "stand", "import" or "replay"
    status: str
    created_at: str | None
    started_at: str | None
    finished_at: str | None
    latitude_deg: float
    stand: str  # the stand (or the imported file) the data came from
    acquisition_software: str  # the software version stored with the campaign
    heading_source: str  # the compass's protocol, resolution and time base, one line
    analysis_software: str  # the software that produced this analysis and report
    analysis_run: int | None  # id of the AnalysisRun row holding these results
    inputs_sha256: str | None  # hash of the analysed inputs (None: not analysed)
    database: str
    plan_sha256: str
    raw_logs: tuple[RawLogFile, ...]  # the campaign's raw log segments, in order
    raw_log_check: str  # "verified", "MISMATCH (...)", "file not found", "no raw log"
    simulated: bool  # the instrument was the simulator: every page says so
    report_number: str | None  # None: not stated (the report says so on every page)
    laboratory: str  # the plan's [report] items, "not stated" when it gives none
    customer: str
    stand_identity: str
    stand_calibration: str
    reference_heading: str
    environment: str
    test_dates: str  # when the trials were made: the campaign's start and end, or the plan's


@dataclass(frozen=True)
class PlannedTrial:
    """One row of the design: K (deg), A (cm), tau (s), role."""

    index: int
    role: str
    direction_deg: float
    amplitude_cm: float
    period_s: float


@dataclass(frozen=True)
class PlanSummary:
    """Section 2. Acquisition settings are None when the plan gives none (imported data)."""

    n_obs: int
    trials: tuple[PlannedTrial, ...]
    still_window_s: float | None
    rocking_window_periods: int | None
    spacing_s: float | None
    settle_criterion: str | None  # `plan.model.SettlePlan.describe`
    notes: tuple[str, ...]  # e.g. which settings were taken from the seed-000 example
    plan_toml: str


@dataclass(frozen=True)
class TrialAcquisition:
    """Section 3, one trial: commanded vs measured motion, what was stored, what went
    wrong. Frame counts are None when the observations carry none (manual readings)."""

    index: int
    role: str
    status: str
    failure_reason: str | None
    cmd_direction_deg: float
    cmd_amplitude_cm: float
    cmd_period_s: float
    meas_direction_deg: float | None
    meas_amplitude_cm: float | None
    meas_period_s: float | None
    observations_before: int
    observations_under: int
    frames_used: int | None
    frames_lost: int | None
    flagged_observations: int
    analysed: bool  # False: left out of the analysis (failed or incomplete)
    attempt: int = 1  # the trial's latest attempt (2, 3, ...: retried)
    motion_source: str = "commanded"  # whose A and tau the analysis applies (`AppliedMotion`)
    meas_amplitude_se_cm: float | None = None
    meas_period_se_s: float | None = None


@dataclass(frozen=True)
class EventRecord:
    """One acquisition event as stored."""

    stand_time_ms: int | None
    wall_time: str
    trial_index: int | None
    series_j: int | None
    kind: str
    severity: str
    message: str
    trial_attempt: int | None = None  # which attempt, when the trial was retried


@dataclass(frozen=True)
class ObservationRecord:
    """delta_jik of seed 000 eq 2.1 as stored: the mean heading over one window, and the
    transient subtracted from it (compensated series; None: not compensated)."""

    k: int
    value_deg: float
    window_start_ms: int | None
    window_end_ms: int | None
    compensation_deg: float | None = None

    @property
    def corrected_deg(self) -> float:
        """The reading the analysis uses (`db.models.Observation.corrected_deg`)."""
        return self.value_deg - (self.compensation_deg or 0.0)


@dataclass(frozen=True)
class SeriesRecord:
    """Series j of a trial: settle start/end (stand ms), settle estimate and observations;
    ``settle`` None when no settle criterion is recorded (e.g. imported data)."""

    j: int
    settle_started_ms: int | None
    settle_done_ms: int | None
    settle_estimate_deg: float | None
    observations: tuple[ObservationRecord, ...]
    settle: SettleOutcome | None = None


@dataclass(frozen=True)
class HeadingTrace:
    """The compass heading of one trial from the raw CAN log, reduced to bins for plotting:
    per bin its centre time (stand ms), mean, min and max heading (deg, unwrapped)."""

    t_ms: np.ndarray
    mean_deg: np.ndarray
    min_deg: np.ndarray
    max_deg: np.ndarray
    frames: int  # valid heading frames behind the bins


@dataclass(frozen=True)
class TrialRecord:
    """What the heading plot of one trial shows: the series (windows, settle points) and, when
    the campaign has a raw CAN log covering the trial, the heading trace."""

    index: int
    series: tuple[SeriesRecord, ...]
    trace: HeadingTrace | None


@dataclass(frozen=True)
class ReadingRecord:
    """A stretch of the compass reading for the noise analysis (section 10), resampled on a
    uniform grid: ``reading_deg`` (unwrapped, trend kept) every ``dt_s`` from stand time
    ``start_ms``; ``frames`` valid heading frames behind it, ``filled`` grid points that had no
    frame and were interpolated linearly; ``others``: further stretches of the same stationary
    reading on the same grid interval (a campaign's other still series), which the correlation
    function pools (`analysis.noise.correlation_function`)."""

    source: str  # which stretch, e.g. "trial 2, still series (j = 1): first to last window"
    start_ms: float
    dt_s: float
    reading_deg: np.ndarray
    frames: int
    filled: int
    others: tuple[np.ndarray, ...] = ()

    @property
    def duration_s(self) -> float:
        return (self.reading_deg.size - 1) * self.dt_s


@dataclass(frozen=True)
class ExcursionCriterion:
    """The plan's [acceptance] table: the reading must stay within +-``tolerance_deg`` of its
    mean for ``duration_s`` with P(at least one excursion) <= ``max_risk``."""

    tolerance_deg: float
    duration_s: float
    max_risk: float


@dataclass(frozen=True)
class Signatures:
    """The signature block: lines to sign by hand. ``recorded_operator`` is who ran the
    campaign as the database records it (shown beside, never as a signature); ``tested_by``
    and ``checked_by`` (name, UTC date) were signed off at the operator station (None: not)."""

    recorded_operator: str
    tested_by: tuple[str, str] | None = None
    checked_by: tuple[str, str] | None = None


@dataclass(frozen=True)
class ReportInputs:
    """Everything the report shows that is not a result of the analysis."""

    identification: Identification
    plan: PlanSummary
    acquisition: tuple[TrialAcquisition, ...]
    events: tuple[EventRecord, ...]
    records: tuple[TrialRecord, ...]
    raw_log_note: str  # how the heading plots were made (raw log, observations only, nothing)
    signatures: Signatures
    reading: ReadingRecord | None = None  # the stationary record of section 10
    reading_note: str = "No reading record was given."  # where it came from, or why none
    acceptance: ExcursionCriterion | None = None  # None: the plan asks for no acceptance
    left_out: tuple[LeftOutTrial, ...] = ()  # trial attempts the analysis does not use, and why
    procedures: ProcedureResults | None = None  # the standard's own tests (None: not run)
