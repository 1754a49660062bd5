"""A stored campaign into the analysis and the report: trial inputs from whatever the database
holds (raw observations, series summaries or the paper's per-trial summaries), the analysis
settings from the stored plan, the analysis itself (recorded as an `AnalysisRun`), and every
other fact the report shows, from the database and the raw CAN log.

    analyze_stored(sessions, campaign_id) -> StoredAnalysis
        = record_run(sessions, id, compute_stored(read_campaign(sessions, id)))
    report_inputs(session, campaign_id, database=...) -> ReportInputs
    campaign_report(sessions, campaign_id, database=..., profile=..., generated_at=...) -> Report
    campaign_signal(session, campaign_id) -> SignalSection   (report section 10 alone)
    trial_stand_spans(campaign) -> {trial index: (first, last) stand ms}

An analysis run is recorded once per distinct result: analysing an unchanged campaign again with
the same software reuses the run already stored, so the database (and the report's JSON) does not
change from one report to the next. The database is read in short read transactions, the
analysis computed outside any, and the run recorded in one short write transaction: a campaign
acquiring into the same SQLite file meanwhile only delays the write (the busy timeout).
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand import SOFTWARE_VERSION
from gyrostand.analysis.angles import about
from gyrostand.analysis.campaign import (
    CampaignAnalysis,
    LeftOutTrial,
    analyze_campaign,
    json_safe,
)
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.gls import Series as SeriesKey
from gyrostand.analysis.gls import SharedError
from gyrostand.analysis.gyro_model import KnownConstants
from gyrostand.analysis.measured_motion import PREFERENCE
from gyrostand.analysis.procedures import PROGRESS, ProcedureResults
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.analysis.transient import PLAN_CONTRADICTED
from gyrostand.analysis.trials import SeriesSummary, TrialInput, series_moments
from gyrostand.analysis.typed_json import decode, encode
from gyrostand.db.models import AnalysisRun, Campaign, ProcedureRun, Series, Trial
from gyrostand.db.queries import campaign_constants, current_trials, load_campaign, sign_offs
from gyrostand.db.session import writer
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import PartialPlan, Plan, PlanError, ReportPlan, parse_any_plan
from gyrostand.report import SHIPPED_PROFILES
from gyrostand.report.build import Report, build_report, missing_items
from gyrostand.report.code_digest import analysis_code_sha256
from gyrostand.report.compliance import Profile, load_profile, worst_cases
from gyrostand.report.model import (
    NOT_STATED,
    EventRecord,
    ExcursionCriterion,
    HeadingTrace,
    Identification,
    ObservationRecord,
    PlannedTrial,
    PlanSummary,
    RawLogFile,
    ReadingRecord,
    ReportInputs,
    SeriesRecord,
    Signatures,
    TrialAcquisition,
    TrialRecord,
)
from gyrostand.report.settings import AnalysisSettings, fallback_notes, settings_from_plan
from gyrostand.report.signal import SignalSection, signal_section
from gyrostand.report.signal_record import (
    acceptance_of,
    headings_in,
    still_series_record,
)
from gyrostand.report.signal_record import heading_source as heading_source_of
from gyrostand.report.stored_plan import is_simulated, whole_plan
from gyrostand.report.transient import transient_check
from gyrostand.report.worst_case import WorstCase

STORED_SCHEMA = "gyrostand.stored-analysis/1"  # results_json["stored"]: `record_run`
TRACE_BINS = 600  # per trial: enough for a page-wide plot, small enough for inline SVG


# ------------------------------------------------------------------------- analysis inputs


@dataclass(frozen=True)
class StoredInputs:
    """What the analysis of a stored campaign runs on. ``left_out`` names every trial attempt
    left out and why; ``notes`` say where settings did not come from the plan."""

    trials: tuple[TrialInput, ...]
    settings: AnalysisSettings
    left_out: tuple[LeftOutTrial, ...]
    notes: tuple[str, ...]
    sources: dict[str, Any] = field(default_factory=dict)  # `analysis_sources`
    shared: dict[SeriesKey, SharedError] = field(default_factory=dict)  # `shared_errors`

    def sha256(self) -> str:
        """Hash of everything the analysis depends on: the trials as given to the fit, the
        settings, the trials left out, `sources` (plan, raw logs, series, events) and the code
        that computes it (`analysis_code_sha256`)."""
        document = json_safe(
            {
                "trials": self.trials,
                "settings": self.settings,
                "left_out": self.left_out,
                "sources": self.sources,
                "code": analysis_code_sha256(),
            }
        )
        return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()


def analysis_sources(campaign: Campaign) -> dict[str, Any]:
    """What besides the trial inputs the stored analysis is computed from: the stored plan,
    the raw log segments as recorded and as they check out now (the reading's signal section),
    every series' settle record and observation windows (observation correlations, the
    transient check) and the events (the transient check's runs)."""
    check, _ = _raw_log_check(campaign)
    return {
        "plan_sha256": hashlib.sha256(campaign.plan_toml.encode()).hexdigest(),
        "raw_logs": [(s.sha256, s.frames, s.start, s.ending) for s in campaign.raw_logs],
        "raw_log_check": check,
        "series": [
            (
                t.index,
                t.attempt,
                s.j,
                s.compensation_se_deg,
                s.compensation_shared,
                s.settle_outcome,
                record,
            )
            for t in current_trials(campaign.trials)
            for s, record in zip(t.series, _series_records(t), strict=True)
        ],
        "events": [(e.kind, e.stand_time_ms, e.trial_id, e.series_id) for e in campaign.events],
    }


@dataclass(frozen=True)
class AppliedMotion:
    """A trial's commanded and applied K, A, tau and where the applied A and tau come from:
    "inclinometer", "drive position" or "stand report" (`analysis.measured_motion`, the
    rocking series' measured motion, with the SEs over its cycles or reports), "stated" (an
    import's, or a campaign acquired before schema 0011: the stand's reports, SE unknown), or
    "commanded" (nothing measured)."""

    index: int
    commanded: tuple[float, float, float]
    applied: tuple[float, float, float]
    source: str
    amplitude_se_cm: float | None
    period_se_s: float | None
    n_cycles: int | None

    def describe(self) -> str:
        k, a, tau = self.commanded
        mk, ma, mtau = self.applied
        se = "" if self.amplitude_se_cm is None else f" ± {self.amplitude_se_cm:.2g}"
        se_tau = "" if self.period_se_s is None else f" ± {self.period_se_s:.2g}"
        cycles = "" if self.n_cycles is None else f", {self.n_cycles} cycles"
        return (
            f"trial {self.index}: commanded K {k:g} deg, A {a:g} cm, tau {tau:g} s; applied "
            f"K {mk:g} deg, A {ma:.3f}{se} cm, tau {mtau:.4f}{se_tau} s ({self.source}{cycles})"
        )

    def to_dict(self) -> dict[str, object]:
        return {
            "trial": self.index,
            "commanded": dict(zip(_MOTION_KEYS, self.commanded, strict=True)),
            "applied": dict(zip(_MOTION_KEYS, self.applied, strict=True)),
            "source": self.source,
            "amplitude_se_cm": self.amplitude_se_cm,
            "period_se_s": self.period_se_s,
            "n_cycles": self.n_cycles,
        }


_MOTION_KEYS = ("direction_deg", "amplitude_cm", "period_s")


def applied_motion(trial: Trial) -> AppliedMotion:
    """What the analysis applies for a trial, and its source (`AppliedMotion`)."""
    rocking = [s for s in trial.series if s.j == 2]
    rows = {m.source: m for s in rocking for m in s.motions}
    row = next((rows[name] for name in PREFERENCE if name in rows), None)
    commanded = (trial.cmd_direction_deg, trial.cmd_amplitude_cm, trial.cmd_period_s)
    applied = (trial.direction_deg, trial.amplitude_cm, trial.period_s)
    if row is not None:
        se = (row.amplitude_se_cm, row.period_se_s, row.n_cycles)
        return AppliedMotion(trial.index, commanded, applied, row.source, *se)
    measured = trial.meas_amplitude_cm is not None or trial.meas_period_s is not None
    source = "stated" if measured else "commanded"
    return AppliedMotion(trial.index, commanded, applied, source, None, None, None)


def campaign_motion(campaign: Campaign) -> tuple[AppliedMotion, ...]:
    """The applied motion of every completed trial (its latest attempt) of a loaded campaign."""
    return tuple(
        applied_motion(t) for t in current_trials(campaign.trials) if t.status == "completed"
    )


def applied_conditions(trial: Trial) -> dict[str, object]:
    """A trial's role and its applied K, A, tau (measured, else commanded: `applied_motion`)."""
    return {
        "role": trial.role,
        "direction_deg": trial.direction_deg,
        "amplitude_cm": trial.amplitude_cm,
        "period_s": trial.period_s,
    }


def trial_input(trial: Trial) -> TrialInput | str:
    """The analysis input of one stored trial, or why it cannot be analysed. K, A and tau are
    the applied values (measured, else commanded: `applied_motion`)."""
    if trial.status == "failed":
        return f"trial failed: {trial.failure_reason}"
    if trial.status != "completed":
        return f"not acquired (trial {trial.status})"
    common = {"index": trial.index} | applied_conditions(trial)
    series = {s.j: s for s in trial.series}
    values = {j: tuple(o.corrected_deg for o in s.observations) for j, s in series.items()}
    compensated = any(s.compensation_se_deg is not None for s in series.values())
    if all(len(values.get(j, ())) >= 2 for j in (1, 2)) and not compensated:
        return TrialInput(**common, before_deg=values[1], under_deg=values[2])
    summaries = {j: series_summary(s) for j, s in series.items()}
    if all(summaries.get(j) is not None for j in (1, 2)):
        return TrialInput(**common, before=summaries[1], under=summaries[2])
    if trial.summary_delta_mean_deg is not None:
        return TrialInput(
            **common,
            delta_mean_deg=trial.summary_delta_mean_deg,
            delta_var_deg2=trial.summary_delta_var_deg2,
            n_obs=trial.summary_n,
        )
    return "no observations or summaries stored for both series"


def series_summary(series: Series) -> SeriesSummary | None:
    """Mean (eq 2.1), variance (eq 2.2) and N of a stored series: of its observations, else as
    imported pre-averaged (None: neither). A compensated series' observations are corrected by
    their compensation; the variance of their mean is the compensation's SE^2, s_c^2 (the
    settle point fitted to these same observations, `analysis.transient.compensated_mean_se`;
    stored before issue 34's fix: the settle point's SE alone, which errs ~3 % low), and s_c,
    common to all N of them, is added to the variance as N s_c^2 (eq 2.2's basis for Cochran's
    test and S_e, as before)."""
    if len(series.observations) >= 2:
        values = np.array([o.corrected_deg for o in series.observations])
        mean, var = (float(x) for x in series_moments(values))
        n, s_c = values.size, series.compensation_se_deg
        if s_c is None:
            return SeriesSummary(mean, var, n)
        return SeriesSummary(mean, var + n * s_c**2, n, var_mean_deg2=s_c**2)
    if series.summary_mean_deg is not None:
        return SeriesSummary(
            series.summary_mean_deg, series.summary_variance_deg2, series.summary_n
        )
    return None


def stored_settings(campaign: Campaign) -> tuple[AnalysisSettings, tuple[str, ...]]:
    """Settings from the stored plan (a whole plan, or the partial form an import stores); the
    known constants B from the campaign's own columns. A partial plan without [analysis] or
    [forecast] takes those from the example of Potemkin (1982), and a note says so."""
    try:
        plan = parse_any_plan(campaign.plan_toml)
    except PlanError as exc:
        raise AnalysisError(
            f"campaign {campaign.id}: its stored plan is invalid: " + "; ".join(exc.problems)
        ) from None
    b = campaign_constants(campaign)
    constants = KnownConstants(
        lP_gcm2s2=b["lp_gcm2s2"],
        H1_gcm2s=b["h1_gcm2s"],
        earth_rate_rad_s=b["earth_rate_rad_s"],
        gravity_cm_s2=b["gravity_cm_s2"],
        latitude_deg=b["latitude_deg"],
    )
    return replace(settings_from_plan(plan), constants=constants), fallback_notes(plan)


def trial_inputs(campaign: Campaign) -> tuple[tuple[TrialInput, ...], tuple[LeftOutTrial, ...]]:
    """The analysis inputs of a loaded campaign's trials (their latest attempts), and every
    attempt left out with why: failed, not acquired, or superseded by a retry."""
    latest = {t.index: t.attempt for t in current_trials(campaign.trials)}
    inputs, left_out = [], []
    for trial in campaign.trials:
        newer = latest[trial.index] if trial.attempt < latest[trial.index] else None
        if newer is None:
            found = trial_input(trial)
        else:
            found = f"superseded by attempt {newer} (retry); it failed: {trial.failure_reason}"
        if isinstance(found, str):
            left_out.append(
                LeftOutTrial(trial.index, trial.attempt, trial.role, trial.status, found, newer)
            )
        else:
            inputs.append(found)
    return tuple(inputs), tuple(left_out)


def commanded_motion(campaign: Campaign, trials: Sequence[TrialInput]) -> tuple[TrialInput, ...]:
    """`trials` (from `stored_inputs`) with the commanded K, A, tau instead of the applied ones:
    the fit a campaign would give without its measured motion."""
    by_index = {t.index: t for t in campaign.trials}
    return tuple(
        replace(
            t,
            direction_deg=by_index[t.index].cmd_direction_deg,
            amplitude_cm=by_index[t.index].cmd_amplitude_cm,
            period_s=by_index[t.index].cmd_period_s,
        )
        for t in trials
    )


def shared_errors(campaign: Campaign) -> dict[SeriesKey, SharedError]:
    """Per compensated series (trial index, j) of the completed trials' latest attempts, its
    share in the period and damping error its compensation used (`analysis.gls`)."""
    return {
        (t.index, s.j): SharedError.from_dict(s.compensation_shared)
        for t in current_trials(campaign.trials)
        if t.status == "completed"
        for s in t.series
        if s.compensation_shared is not None and s.compensation_se_deg is not None
    }


def stored_inputs(campaign: Campaign) -> StoredInputs:
    """The analysis inputs of a loaded campaign (see `db.queries.load_campaign`)."""
    trials, left_out = trial_inputs(campaign)
    settings, notes = stored_settings(campaign)
    sources = analysis_sources(campaign)
    return StoredInputs(trials, settings, left_out, notes, sources, shared_errors(campaign))


@dataclass(frozen=True)
class StoredAnalysis:
    """The analysis of a stored campaign, its inputs, the recorded run (None: not recorded
    yet), the signal analysis of its reading (section 10), whose independence check the
    analysis uses, and the trials' heading traces from the same raw log."""

    analysis: CampaignAnalysis
    inputs: StoredInputs
    run_id: int | None
    signal: SignalSection
    traces: dict[int, HeadingTrace | None]  # `campaign_traces`: the report's heading plots
    worst_cases: tuple[WorstCase, ...] = ()  # the forecast's, for the shipped profiles


def read_campaign(sessions: sessionmaker[Session], campaign_id: int) -> Campaign:
    """The campaign as `load_campaign` loads it, with its events and raw log segments, read in
    one short read transaction: what is computed from it afterwards holds no transaction."""
    with sessions() as session:
        campaign = load_campaign(session, campaign_id)
        _ = campaign.events, campaign.raw_logs  # loaded now, not lazily later
        session.commit()  # ends the read (expire_on_commit=False keeps the objects loaded)
    return campaign


def compute_stored(campaign: Campaign, inputs: StoredInputs | None = None) -> StoredAnalysis:
    """Analyse a campaign read by `read_campaign` (AnalysisError for unusable data,
    LogFileError for a raw log that verifies but cannot be read); nothing is recorded."""
    inputs = stored_inputs(campaign) if inputs is None else inputs
    signal = _signal(campaign)
    s = inputs.settings
    analysis = analyze_campaign(
        inputs.trials,
        s.constants,
        q=s.q,
        start=s.start,
        admissible=s.admissible,
        forecast=s.forecast,
        independence=signal.independence(),
        inflation=signal.inflation(),
        shared=inputs.shared,
    )
    analysis = replace(analysis, left_out=inputs.left_out)
    missing = [t for t in inputs.left_out if t.superseded_by is None]
    if missing:  # first: a reader must know the fit rests on fewer trials than planned
        lost = [f"trial {t.index} ({t.role}): {t.reason}" for t in missing]
        analysis = replace(
            analysis,
            warnings=(
                f"not analysed: {'; '.join(lost)}; the fit uses {len(analysis.fit_indices)} fit "
                f"trials ({analysis.fit.dof} residual degrees of freedom)",
                *analysis.warnings,
            ),
        )
    unshared = _compensated_unshared(campaign, analysis)
    if unshared:
        analysis = replace(analysis, warnings=(*analysis.warnings, unshared))
    check = transient_check(campaign, whole_plan(campaign))
    if not isinstance(check, str):
        warnings = analysis.warnings + check.warnings(analysis.cochran.s_e)
        analysis = replace(analysis, transient=check, warnings=warnings)
    contradicted = [e.message for e in campaign.events if e.kind == PLAN_CONTRADICTED]
    if contradicted:  # told while the campaign ran; the settle criteria used the record's values
        analysis = replace(analysis, warnings=(*contradicted, *analysis.warnings))
    worst = dict.fromkeys(
        w for name in SHIPPED_PROFILES for w in worst_cases(load_profile(name), analysis)
    )
    return StoredAnalysis(analysis, inputs, None, signal, campaign_traces(campaign), tuple(worst))


def _compensated_unshared(campaign: Campaign, analysis: CampaignAnalysis) -> str | None:
    """The warning for fit trials with a compensated series whose share in the period and
    damping error is not stored (acquired before schema 0023, or imported): their means are
    then fitted as independent, which they are not."""
    fitted = set(analysis.fit_indices)
    missing = sorted(
        (t.index, s.j)
        for t in current_trials(campaign.trials)
        if t.index in fitted
        for s in t.series
        if s.compensation_se_deg is not None and s.compensation_shared is None
    )
    if not missing:
        return None
    where = ", ".join(f"trial {i} series {j}" for i, j in missing)
    return (
        f"{where}: compensated without its share in the period and damping error stored "
        "(acquired before schema 0023, or imported): C and T are fitted as if the trial means "
        "were independent, and their SE and intervals may be too narrow"
    )


def record_run(
    sessions: sessionmaker[Session], campaign_id: int, stored: StoredAnalysis
) -> StoredAnalysis:
    """Record the analysis run in one short write transaction (on SQLite BEGIN IMMEDIATE: it
    waits the store's busy timeout for a campaign acquiring into the same file); an unchanged
    result of the same inputs and software reuses the run already stored, and a run rebuilt
    from its record (`run_id` set) is not recorded again. The run's results are the analysis's
    JSON document with, under "stored", the typed analysis and signal section to rebuild."""
    if stored.run_id is not None:
        return stored
    results = stored.analysis.to_dict() | {
        "stored": {
            "schema": STORED_SCHEMA,
            "analysis": encode(stored.analysis),
            "signal": encode(stored.signal),
            "traces": encode(stored.traces),
            "worst_cases": encode(stored.worst_cases),
        }
    }
    digest, version = stored.inputs.sha256(), SOFTWARE_VERSION
    with writer(sessions).begin() as session:
        run = session.scalars(
            select(AnalysisRun)
            .where(
                AnalysisRun.campaign_id == campaign_id,
                AnalysisRun.inputs_hash == digest,
                AnalysisRun.software_version == version,
            )
            .order_by(AnalysisRun.id.desc())
        ).first()
        if run is None or run.results_json != results:
            run = AnalysisRun(
                campaign_id=campaign_id,
                inputs_hash=digest,
                results_json=results,
                software_version=version,
            )
            session.add(run)
            session.flush()
        return replace(stored, run_id=run.id)


def stored_analysis(sessions: sessionmaker[Session], campaign_id: int) -> StoredAnalysis:
    """The analysis of a stored campaign: rebuilt from its latest recorded run whose inputs
    hash (`StoredInputs.sha256`) and software version match the campaign as it is now (then
    `run_id` is set), else computed and not recorded yet (`run_id` None). Errors as
    `compute_stored`."""
    campaign = read_campaign(sessions, campaign_id)
    inputs = stored_inputs(campaign)
    with sessions() as session:
        run = session.scalars(
            select(AnalysisRun)
            .where(
                AnalysisRun.campaign_id == campaign_id,
                AnalysisRun.inputs_hash == inputs.sha256(),
                AnalysisRun.software_version == SOFTWARE_VERSION,
            )
            .order_by(AnalysisRun.id.desc())
        ).first()
        rebuilt = None if run is None else _rebuilt(run, inputs)
    return compute_stored(campaign, inputs) if rebuilt is None else rebuilt


def _rebuilt(run: AnalysisRun, inputs: StoredInputs) -> StoredAnalysis | None:
    """The typed analysis of a recorded run (None: recorded without it, or by another schema)."""
    typed = run.results_json.get("stored")
    if not isinstance(typed, dict) or typed.get("schema") != STORED_SCHEMA:
        return None
    try:
        analysis = decode(CampaignAnalysis, typed["analysis"])
        signal = decode(SignalSection, typed["signal"])
        traces = decode(dict[int, HeadingTrace | None], typed["traces"])
        worst = decode(tuple[WorstCase, ...], typed["worst_cases"])
    except (TypeError, KeyError, ValueError):
        return None
    return StoredAnalysis(analysis, inputs, run.id, signal, traces, worst)


def analyze_stored(sessions: sessionmaker[Session], campaign_id: int) -> StoredAnalysis:
    """The analysis of a stored campaign, recorded (`stored_analysis`, then `record_run`):
    AnalysisError for unusable data, CampaignNotFound for a wrong id, LogFileError for a raw
    log that verifies but cannot be read; a read, any computation outside a transaction, then
    one short write when it was computed."""
    return record_run(sessions, campaign_id, stored_analysis(sessions, campaign_id))


# -------------------------------------------------------------------------- report inputs


def heading_source(campaign: Campaign) -> str:
    """How the compass's headings came: its protocol, their resolution and time base."""
    if campaign.heading_source is None:
        return "not stated (measurements imported from a file)"
    resolution = campaign.heading_resolution_deg
    step = "not recorded" if resolution is None else f"{resolution:.2g} deg"
    return (
        f"{campaign.heading_source}, heading resolution {step}; time base: "
        f"{campaign.heading_time_base or 'not recorded'}"
    )


def _when(value: datetime | None) -> str | None:
    return None if value is None else value.isoformat(sep=" ", timespec="seconds")


RESTARTED = (
    "verified, not read: a resume restarted the stand, so stand times start again in its raw log"
)


def _raw_log_check(campaign: Campaign) -> tuple[str, list[Path]]:
    """How the recorded raw log segments check out, and the logs to read as one stream of the
    campaign: all of them, unless a resume restarted the stand, whose stand times then start
    again in its log (a trial's stand-time span would take frames of another run)."""
    segments = [s for s in campaign.raw_logs if s.frames or s.ending != "killed"]  # (nothing)
    if not segments:
        return "no raw log", []
    for s in segments:
        path = Path(s.path)
        if not path.is_file():
            return "file not found" + (f" ({path.name})" if len(segments) > 1 else ""), []
        stat = path.stat()
        actual = _sha256_of(str(path), stat.st_size, stat.st_mtime_ns)
        if s.sha256 is None:
            return f"unverified: no SHA-256 recorded for {path.name}", []
        if actual != s.sha256:
            return f"MISMATCH: the SHA-256 of {path.name} is {actual}", []
    if any(s.start == "restarted" for s in segments):
        return RESTARTED, []
    return "verified", [Path(s.path) for s in segments]


@functools.lru_cache(maxsize=16)
def _sha256_of(path: str, size: int, mtime_ns: int) -> str:
    """A raw log's SHA-256, hashed once per process while the file is unchanged (its size and
    modification time): the inputs hash, the signal section and the report all check it."""
    from gyrostand.frames.logfile import sha256_of  # (python-can: not for the hash alone)

    return sha256_of(Path(path))


def _lab_items(campaign: Campaign, number: str | None) -> dict[str, Any]:
    """The identification items of the stored plan's [report] table, whole or partial
    (`Identification`); for a simulated stand, what does not apply says so."""
    try:
        plan: Plan | PartialPlan | None = parse_any_plan(campaign.plan_toml)
    except PlanError:
        plan = None
    items = ReportPlan() if plan is None else plan.report
    simulated = is_simulated(campaign, plan)
    na = "not applicable: simulated instrument and stand" if simulated else NOT_STATED
    maker = None if plan is None else plan.instrument.manufacturer
    started, finished = _when(campaign.started_at), _when(campaign.finished_at)
    dates = items.dates or NOT_STATED
    if started is not None:  # the campaign's own record comes first
        dates = f"{started} to {finished or 'not finished'} (UTC)"
    return {
        "simulated": simulated,
        "manufacturer": maker or ("gyrostand simulator" if simulated else NOT_STATED),
        "test_dates": dates,
        "report_number": number or items.number,
        "laboratory": items.laboratory or NOT_STATED,
        "customer": items.customer or NOT_STATED,
        "stand_identity": items.stand or ("gyrostand simulated stand" if simulated else NOT_STATED),
        "stand_calibration": items.stand_calibration or na,
        "reference_heading": items.reference_heading
        or (
            f"the simulator's true heading {plan.bus.simulator.compass.heading_deg:g} deg "
            "(exact; [bus.simulator.compass] heading_deg), not recorded with the observations"
            if simulated and isinstance(plan, Plan)
            else NOT_STATED
        ),
        "environment": items.environment or na,
    }


def _stand(campaign: Campaign, plan: Plan | None) -> str:
    if campaign.source == "import" or plan is None:
        return "none: measurements imported from a file (see the import event)"
    bus = plan.bus
    timing = (
        "virtual time (stand time follows the acquisition: repeatable for a seed)"
        if bus.timing == "virtual"
        else f"real time x{bus.speedup:g}"
    )
    if bus.simulated:
        where = (
            f"simulated gyrocompass and roll stand on a virtual CAN bus (a software model in "
            f"place of the hardware), seed {bus.seed}, {timing}"
        )
    else:
        where = (
            f"python-can interface {bus.interface or '(from python-can configuration)'}, "
            f"channel {bus.channel or '(default)'}"
            + (f", {bus.bitrate} bit/s" if bus.bitrate else "")
            + (
                f", simulated stand (gyrostand simulate) in {timing}"
                if bus.timing == "virtual"
                else ""
            )
        )
    return (
        f"offline replay of the raw log; recorded on: {where}"
        if campaign.source == "replay"
        else where
    )


def _plan_summary(campaign: Campaign, plan: Plan | None, notes: tuple[str, ...]) -> PlanSummary:
    if plan is not None:
        trials = tuple(
            PlannedTrial(t.index, t.role, t.direction_deg, t.amplitude_cm, t.period_s)
            for t in plan.trials
        )
        o, st = plan.observation, plan.settle
        windows = (o.still_window_s, o.rocking_window_periods, o.spacing_s)
        settle: str | None = st.describe()
    else:
        trials = tuple(
            PlannedTrial(t.index, t.role, t.cmd_direction_deg, t.cmd_amplitude_cm, t.cmd_period_s)
            for t in current_trials(campaign.trials)
        )
        windows, settle = (None, None, None), None
    return PlanSummary(
        n_obs=campaign.n_obs,
        trials=trials,
        still_window_s=windows[0],
        rocking_window_periods=windows[1],
        spacing_s=windows[2],
        settle_criterion=settle,
        notes=notes,
        plan_toml=campaign.plan_toml,
    )


def _trial_acquisition(trial: Trial, analysed: bool) -> TrialAcquisition:
    by_j = {s.j: s.observations for s in trial.series}
    observations = [o for s in trial.series for o in s.observations]
    used = [o.frames_used for o in observations if o.frames_used is not None]
    lost = [o.frames_lost for o in observations if o.frames_lost is not None]
    motion = applied_motion(trial)
    return TrialAcquisition(
        index=trial.index,
        role=trial.role,
        status=trial.status,
        failure_reason=trial.failure_reason,
        cmd_direction_deg=trial.cmd_direction_deg,
        cmd_amplitude_cm=trial.cmd_amplitude_cm,
        cmd_period_s=trial.cmd_period_s,
        meas_direction_deg=trial.meas_direction_deg,
        meas_amplitude_cm=trial.meas_amplitude_cm,
        meas_period_s=trial.meas_period_s,
        observations_before=len(by_j.get(1, ())),
        observations_under=len(by_j.get(2, ())),
        frames_used=sum(used) if used else None,
        frames_lost=sum(lost) if lost else None,
        flagged_observations=sum(bool(o.flags) for o in observations),
        analysed=analysed,
        attempt=trial.attempt,
        motion_source=motion.source,
        meas_amplitude_se_cm=motion.amplitude_se_cm,
        meas_period_se_s=motion.period_se_s,
    )


def _events(campaign: Campaign) -> tuple[EventRecord, ...]:
    trial_index = {t.id: t.index for t in campaign.trials}
    attempts = Counter(t.index for t in campaign.trials)
    retried = {t.id: t.attempt for t in campaign.trials if attempts[t.index] > 1}
    series_j = {s.id: s.j for t in campaign.trials for s in t.series}
    return tuple(
        EventRecord(
            stand_time_ms=e.stand_time_ms,
            wall_time=_when(e.wall_time) or "",
            trial_index=None if e.trial_id is None else trial_index.get(e.trial_id),
            trial_attempt=None if e.trial_id is None else retried.get(e.trial_id),
            series_j=None if e.series_id is None else series_j.get(e.series_id),
            kind=e.kind,
            severity=e.severity,
            message=e.message,
        )
        for e in campaign.events
    )


def _series_records(trial: Trial) -> tuple[SeriesRecord, ...]:
    return tuple(
        SeriesRecord(
            j=s.j,
            settle_started_ms=s.settle_started_ms,
            settle_done_ms=s.settle_done_ms,
            settle_estimate_deg=s.settle_estimate_deg,
            observations=tuple(
                ObservationRecord(
                    o.k, o.value_deg, o.window_start_ms, o.window_end_ms, o.compensation_deg
                )
                for o in s.observations
            ),
            settle=None if s.settle_outcome is None else SettleOutcome.from_dict(s.settle_outcome),
        )
        for s in trial.series
    )


def _stand_span_ms(series: tuple[SeriesRecord, ...], events: list[int]) -> tuple[int, int] | None:
    """The stand-time span of a trial: its settles, windows and events."""
    times = list(events)
    for s in series:
        times += [t for t in (s.settle_started_ms, s.settle_done_ms) if t is not None]
        for o in s.observations:
            times += [t for t in (o.window_start_ms, o.window_end_ms) if t is not None]
    return (min(times), max(times)) if times else None


def trial_stand_spans(campaign: Campaign) -> dict[int, tuple[int, int]]:
    """Per trial index (its latest attempt) the stand-time span [first, last] in ms of its
    settles, observation windows and events: the stand time the trial took."""
    current = current_trials(campaign.trials)
    event_times: dict[int, list[int]] = {t.index: [] for t in current}
    by_id = {t.id: t.index for t in current}
    for e in campaign.events:
        if e.trial_id in by_id and e.stand_time_ms is not None:
            event_times[by_id[e.trial_id]].append(e.stand_time_ms)
    return {
        t.index: span
        for t in current
        if (span := _stand_span_ms(_series_records(t), event_times[t.index])) is not None
    }


def _binned(
    span_ms: tuple[int, int], t_ms: np.ndarray, heading_deg: np.ndarray, bins: int
) -> HeadingTrace | None:
    """One trial's heading frames in `bins` bins of its span: per bin the mean, min and max.
    Headings are taken about the trial's first one (`about`), so a record crossing 0/360 deg
    stays continuous (as the engine does)."""
    if not t_ms.size:
        return None
    t, h = t_ms.astype(float), about(float(heading_deg[0]), heading_deg)
    t0, t1 = span_ms
    edges = np.linspace(t0, max(t1, t0 + 1), bins + 1)
    b = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, bins - 1)
    count = np.bincount(b, minlength=bins)
    low, high = np.full(bins, np.inf), np.full(bins, -np.inf)
    np.minimum.at(low, b, h)
    np.maximum.at(high, b, h)
    keep = count > 0
    n = count[keep]
    return HeadingTrace(
        t_ms=np.bincount(b, t, bins)[keep] / n,
        mean_deg=np.bincount(b, h, bins)[keep] / n,
        min_deg=low[keep],
        max_deg=high[keep],
        frames=int(n.sum()),
    )


def heading_traces(
    logs: Sequence[Path], plan: Plan, spans: dict[int, tuple[int, int]], bins: int = TRACE_BINS
) -> dict[int, HeadingTrace | None]:
    """Binned valid heading frames of each trial's stand-time span [start, end], from the raw
    log (`headings_in`)."""
    closed = {index: (t0, np.nextafter(t1, np.inf)) for index, (t0, t1) in spans.items()}
    found = headings_in(logs, codec_for(plan), closed, heading_source_of(plan))
    return {index: _binned(spans[index], *found[index], bins) for index in spans}


def campaign_traces(campaign: Campaign) -> dict[int, HeadingTrace | None]:
    """Per trial index its binned heading trace from the raw log (`heading_traces`); empty
    without a usable raw log or a whole plan."""
    _, logs = _raw_log_check(campaign)
    plan, spans = whole_plan(campaign), trial_stand_spans(campaign)
    return heading_traces(logs, plan, spans) if logs and plan is not None and spans else {}


def _records(
    campaign: Campaign,
    traces: dict[int, HeadingTrace | None],
    check: str,
) -> tuple[tuple[TrialRecord, ...], str]:
    """Per trial its series and (`campaign_traces`) its heading trace; and how the plots were
    made."""
    current = current_trials(campaign.trials)
    series = {t.index: _series_records(t) for t in current}
    has_observations = any(s.observations for rows in series.values() for s in rows)
    if traces:
        frames = sum(t.frames for t in traces.values() if t is not None)
        note = (
            f"Heading from the raw CAN log ({frames} valid heading frames within the trials), "
            f"in up to {TRACE_BINS} time bins per trial: grey band min-max, line the bin mean. "
            "Shaded: observation windows (blue still, orange rocking) with each observation's "
            "value as a bar; dashed lines and triangles: where and at what heading each series "
            "settled. Under each trial, one panel per series on a time axis of its own zooms on "
            "its observation windows (numbered k), a minute or so each in a trial of hours."
        )
    elif has_observations:
        reason = {
            "no raw log": "The campaign has no raw CAN log",
            RESTARTED: "The raw CAN logs are not read for the plots (a resume restarted the "
            "stand, whose stand times start again in its log)",
        }.get(check, f"The raw CAN log cannot be used ({check})")
        note = f"{reason}: the plots show the stored observations over their windows."
    else:
        note = (
            "No heading observations are stored (the data were imported as per-trial "
            "summaries): there is no heading record to plot."
        )
    records = tuple(TrialRecord(index, rows, traces.get(index)) for index, rows in series.items())
    return records, note


def _reading(
    plan: Plan | None, logs: Sequence[Path], check: str, records: tuple[TrialRecord, ...]
) -> tuple[ReadingRecord | None, str, ExcursionCriterion | None]:
    """The stationary record of section 10 (from the raw log when it verifies), a note on it,
    and the plan's acceptance by excursions."""
    acceptance = acceptance_of(plan)
    if plan is None:
        return (
            None,
            "No raw reading: the data were imported (no stand, no raw CAN log).",
            acceptance,
        )
    if not logs:
        return None, f"No usable raw CAN log ({check}): no reading record.", acceptance
    source = heading_source_of(plan)
    reading, note = still_series_record(logs, codec_for(plan), records, source)
    return reading, note, acceptance


def campaign_signal(session: Session, campaign_id: int) -> SignalSection:
    """Section 10 of a stored campaign's report alone (no analysis run, no heading traces)."""
    return _signal(load_campaign(session, campaign_id))


def _signal(campaign: Campaign) -> SignalSection:
    check, logs = _raw_log_check(campaign)
    plan = whole_plan(campaign)
    records = tuple(
        TrialRecord(t.index, _series_records(t), None) for t in current_trials(campaign.trials)
    )
    reading, note, acceptance = _reading(plan, logs, check, records)
    return signal_section(reading, note, records, acceptance)


def report_inputs(
    session: Session,
    campaign_id: int,
    stored: StoredAnalysis | None,
    *,
    database: str,
    report_number: str | None = None,
) -> ReportInputs:
    """Everything the report shows besides the analysis results: identification, plan,
    acquisition summary, every event, the heading records and the stationary reading record
    (from the raw log when it verifies), the plan's acceptance by excursions."""
    campaign = load_campaign(session, campaign_id)
    _, left_out = trial_inputs(campaign)
    unused = {(t.index, t.attempt) for t in left_out}
    plan = whole_plan(campaign)
    check, logs = _raw_log_check(campaign)
    traces = campaign_traces(campaign) if stored is None else stored.traces
    records, note = _records(campaign, traces, check)
    if stored is None:
        reading, reading_note, acceptance = _reading(plan, logs, check, records)
    else:  # the record the analysis's signal section was made from: not read again
        reading, reading_note = stored.signal.record, stored.signal.record_note
        acceptance = acceptance_of(plan)
    ident = Identification(
        campaign_id=campaign.id,
        instrument_model=campaign.instrument.model,
        instrument_serial=campaign.instrument.serial,
        operator=campaign.operator,
        source=campaign.source,
        status=campaign.status,
        created_at=_when(campaign.created_at),
        started_at=_when(campaign.started_at),
        finished_at=_when(campaign.finished_at),
        latitude_deg=campaign.latitude_deg,
        stand=_stand(campaign, plan),
        acquisition_software=campaign.software_version,
        heading_source=heading_source(campaign),
        analysis_software=SOFTWARE_VERSION,
        analysis_run=None if stored is None else stored.run_id,
        inputs_sha256=None if stored is None else stored.inputs.sha256(),
        database=database,
        plan_sha256=campaign.plan_hash,
        raw_logs=tuple(
            RawLogFile(s.path, s.sha256, s.frames, s.start, s.ending) for s in campaign.raw_logs
        ),
        raw_log_check=check,
        **_lab_items(campaign, report_number),
    )
    return ReportInputs(
        identification=ident,
        plan=_plan_summary(campaign, plan, () if stored is None else stored.inputs.notes),
        acquisition=tuple(
            _trial_acquisition(t, stored is not None and (t.index, t.attempt) not in unused)
            for t in current_trials(campaign.trials)
        ),
        left_out=left_out,
        events=_events(campaign),
        records=records,
        raw_log_note=note,
        signatures=_signatures(session, campaign),
        reading=reading,
        reading_note=reading_note,
        acceptance=acceptance,
        procedures=stored_procedures(session, campaign.id),
    )


def stored_procedures(session: Session, campaign_id: int) -> ProcedureResults | None:
    """The campaign's stored results of the standard's procedures (None: none were run)."""
    record = session.scalar(
        select(ProcedureRun.results_json).where(ProcedureRun.campaign_id == campaign_id)
    )
    if record is None or PROGRESS in record:  # not run, or interrupted part-way
        return None
    return ProcedureResults.from_dict(record)


def _signatures(session: Session, campaign: Campaign) -> Signatures:
    """The signature block: the recorded operator and the station's sign-offs."""
    signed = {
        role: (s.name, s.signed_at.strftime("%Y-%m-%d"))
        for role, s in sign_offs(session, campaign.id).items()
    }
    return Signatures(campaign.operator, signed.get("tested_by"), signed.get("checked_by"))


class NotFinal(Exception):
    """`campaign_report(final=True)` of a report that can only be a DRAFT: the missing items."""

    def __init__(self, missing: tuple[str, ...]) -> None:
        super().__init__(", ".join(missing))
        self.missing = missing


def campaign_report(
    sessions: sessionmaker[Session],
    campaign_id: int,
    *,
    database: str,
    profile: Profile,
    generated_at: str,
    report_number: str | None = None,
    final: bool = False,
) -> Report:
    """The stored campaign's analysis (`stored_analysis`: its recorded run when the inputs are
    unchanged, else computed and recorded: reads, the computation outside any transaction,
    then one short write) and its report. A campaign that cannot be
    analysed (e.g. every trial failed) still gets its report: plan, acquisition and events,
    with the reason in place of the results. ``final``: NotFinal, nothing recorded, when the
    report lacks an item of ISO/IEC 17025 7.8.2."""
    try:
        stored: StoredAnalysis | None = stored_analysis(sessions, campaign_id)
    except AnalysisError as exc:
        stored, reason = None, str(exc)
    with sessions() as session:
        inputs = report_inputs(
            session, campaign_id, stored, database=database, report_number=report_number
        )
    if final and (missing := missing_items(inputs)):
        raise NotFinal(missing)
    if stored is None:
        return build_report(inputs, reason, profile, generated_at=generated_at)
    stored = record_run(sessions, campaign_id, stored)
    ident = replace(inputs.identification, analysis_run=stored.run_id)
    return build_report(
        replace(inputs, identification=ident),
        stored.analysis,
        profile,
        generated_at=generated_at,
        signal=stored.signal,
        worst_cases=stored.worst_cases,
    )
