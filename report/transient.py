"""The compass's transient in a stored campaign, whatever settle criterion the plan used: the
transient model (Bezvesilna & Gura eqs 1-3, across the stand's steps: `analysis.transient`)
fitted to every series' settle record and observations, and what it leaves in each series mean.

Series follow one another in trial order, each starting at the start/stop that moved the
compass's equilibrium (its stored ``step_ms``). The state carries over from the series before
only when both ran in one run of the stand clock (first attempts, in order, times increasing);
otherwise the series starts from an unknown state. The period and damping ratio are the plan's
(instrument data); the record's own estimates are reported beside them, with a warning when they
contradict the plan's (`analysis.transient.contradicts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.angles import about
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.analysis.transient import (
    Segments,
    SeriesTransient,
    TransientCheck,
    TransientFit,
    Windows,
    contradicts,
    fit_transient,
    fit_transient_free,
)
from gyrostand.db.models import Campaign, Series
from gyrostand.db.queries import RUN_START, current_trials
from gyrostand.plan.model import Plan


@dataclass(frozen=True)
class _Segment:
    trial: int
    j: int
    start_ms: int
    free: bool
    windows: list[tuple[float, float, float]]  # start ms, end ms, heading deg (time order)
    observed: list[tuple[float, float]]  # the observation windows (ms)
    compensation_deg: float | None  # mean compensation of a compensated series


def _segments(campaign: Campaign) -> list[_Segment]:
    """The series in the order they were acquired (series rows are made as a series starts), on
    one campaign time: a run whose stand clock restarted (a power-cycled stand controller, or a
    database from before the simulated stand's clock went on across runs) is placed after the
    run before it (`_placed`)."""
    runs = sorted(
        e.stand_time_ms
        for e in campaign.events
        if e.kind == RUN_START and e.stand_time_ms is not None
    )
    attempts = {t.id: t for t in current_trials(campaign.trials)}
    series = sorted((s for t in attempts.values() for s in t.series), key=lambda s: s.id)
    out: list[_Segment] = []
    previous: tuple[int, int] | None = None  # (trial attempt, end ms) of the last series
    offset = 0  # campaign time - stand time of the run being placed
    for s in series:
        trial = attempts[s.trial_id]
        raw = _segment(trial.index, trial.attempt, s, previous, offset, runs)
        if raw is None:
            continue
        if previous is not None and raw.windows[0][0] < previous[1]:  # the clock went back
            offset = previous[1] - (raw.windows[0][0] - offset)
            raw = _segment(trial.index, trial.attempt, s, None, offset, runs)
            assert raw is not None
        out.append(raw)
        previous = (trial.attempt, int(max(w[1] for w in raw.windows)))
    return out


def _segment(
    index: int,
    attempt: int,
    s: Series,
    previous: tuple[int, int] | None,
    offset: int,
    runs: list[int],
) -> _Segment | None:
    """Series `s` in campaign time (its stand times + `offset`), chained to the series before
    (`previous`: its attempt and end) when both ran in one run of the stand: first attempts,
    times increasing, and no run started in between (`runs`: run starts, stand ms)."""
    outcome = None if s.settle_outcome is None else SettleOutcome.from_dict(s.settle_outcome)
    blocks = [] if outcome is None else [tuple(map(float, b)) for b in outcome.blocks]
    timed = [o for o in s.observations if o.window_start_ms is not None]
    observed = [(float(o.window_start_ms), float(o.window_end_ms)) for o in timed]
    windows = blocks + [(a, b, o.value_deg) for (a, b), o in zip(observed, timed, strict=True)]
    if not windows:
        return None
    windows.sort(key=lambda w: w[0])
    step = None if outcome is None else outcome.step_ms
    chained = (
        previous is not None
        and step is not None
        and attempt == previous[0] == 1
        and previous[1] <= step + offset <= windows[0][0] + offset
        and not any(previous[1] < t + offset <= windows[0][0] + offset for t in runs)
    )
    comp = [o.compensation_deg for o in timed if o.compensation_deg is not None]
    return _Segment(
        trial=index,
        j=s.j,
        start_ms=(step if chained and step is not None else int(windows[0][0])) + offset,
        free=not chained,
        windows=[(a + offset, b + offset, v) for a, b, v in windows],
        observed=[(a + offset, b + offset) for a, b in observed],
        compensation_deg=float(np.mean(comp)) if comp else None,
    )


def transient_check(campaign: Campaign, plan: Plan | None) -> TransientCheck | str:
    """The transient left in each series of a stored campaign, or why it is not assessed."""
    model = None if plan is None else plan.settle.transient_model
    if model is None:
        return (
            "not assessed: the plan gives no transient model of the compass ([settle] "
            "undamped_period_s and damping_ratio)"
        )
    segments = _segments(campaign)
    if not segments:
        return "not assessed: no series recorded its settle blocks or observation windows"
    rows = [
        (k, (a + b) / 2000, (b - a) / 1000, value)
        for k, s in enumerate(segments)
        for a, b, value in s.windows
    ]
    rows.sort(key=lambda r: (r[0], r[1]))
    branch = rows[0][3]
    rows = [(k, t, w, float(about(branch, v))) for k, t, w, v in rows]
    seg = Segments(tuple(s.start_ms / 1000 for s in segments), tuple(s.free for s in segments))
    data = Windows.of(rows)
    try:
        fit = fit_transient(model, seg, data)
    except AnalysisError as exc:
        return f"not assessed: the transient model cannot be fitted to the record ({exc})"
    try:
        record: TransientFit | None = fit_transient_free(model, seg, data)
    except AnalysisError:
        record = None
    series = []
    for k, s in enumerate(segments):
        if not s.observed:
            continue
        ms = np.array(s.observed)
        left, se = fit.mean_transient(k, ms.mean(axis=1) / 1000, (ms[:, 1] - ms[:, 0]) / 1000)
        if s.compensation_deg is not None:
            left -= s.compensation_deg
        comp_se = fit.settle_point(k)[1] if s.compensation_deg is not None else None
        series.append(SeriesTransient(s.trial, s.j, comp_se, left, se))
    return TransientCheck(
        undamped_period_s=fit.model.undamped_period_s,
        damping_ratio=fit.model.damping_ratio,
        plan_contradicted=record is not None and contradicts(record, model),
        record_period_s=None if record is None else record.model.undamped_period_s,
        record_period_se_s=None if record is None else record.period_se_s,
        record_damping_ratio=None if record is None else record.model.damping_ratio,
        record_damping_ratio_se=None if record is None else record.damping_ratio_se,
        residual_sd_deg=fit.residual_sd_deg,
        series=tuple(series),
    )
