"""When a series may start observing: the band criterion, or the compass's transient model
(seed 003, Bezvesilna & Gura) fitted online, across the stand's steps (`analysis.transient`).

Record. The engine keeps every window mean since it started: settle blocks (each as long as an
observation window, i.e. whole rocking periods while rocking, so a block mean cancels the
reading's components at the rocking frequency p and 2p and averages the sensor's correlated
noise) and observations, and the stand time of each start/stop acknowledgement (a step of the
compass's equilibrium). The series' settle point R_j is fitted with the state carried over from
the series before (the element does not jump at a step), so only R_j is new: this is what makes
an estimate good after ~20 minutes of an 84-minute compass rather than ~40.

Rule. With tol = tolerance_fraction x the plan's expected S{<delta>}_e (Potemkin 1982, eq 2.6),
the series observes from the end of the first block at which

1. R_j has a standard error <= tol, and
2. the last `stable_estimates` estimates of R_j lie within tol of each other (max - min), and
3. method "estimate": the transient predicted over the N observation windows to come, plus
   2 standard errors, stays within transient_fraction x S_e: so the transient left in each
   observation is bounded by a stated fraction of S_e. Method "compensated" skips 3: each
   observation is compensated instead (the fitted transient over its window is subtracted at
   the end of the series, `compensation`), and R_j's standard error is the compensation's.
   Only a series whose state is carried over is compensated: the first one of a run (state
   unknown, a 3-parameter fit of a short record: its SE comes out low) waits for 3.
   What 3 leaves is not noise: with damping 0.7 the rule is met in the overshoot, so the
   transient left has the overshoot's sign in every series (the paper campaign, 200 draws:
   0.3 % of the step, -0.0004 deg in trial 1's rocking series, 0.1 SE of a trial mean;
   `validation/trial_one.py`).

The band criterion is only evaluated to record the time saved: measured when it held before,
else predicted from the fitted transient. A transient the model does not describe (wrong period
or damping in the plan) keeps the standard error up and ends in the settle timeout. omega0 and
the damping come from the plan (instrument data) until the record contradicts them: as each
series starts, once the record spans a precession period, the period and damping ratio are
estimated from it (`identify`); when they are well determined and more than 3 SE from the
plan's, the record's are used from there on and a "plan contradicted" event says so. A
compensated criterion compensates only once the record has determined them (confirming the
plan's or replacing them): until then a series waits for the bound, as "estimate" does, since
a compensation with a wrong period is biased and a short compensated record cannot tell. The
compensation itself, at the series' end, takes the period and damping the whole record gives
then (not the plan's, even when the record does not contradict them at 3 SE: a damping 0.05
off goes unnoticed for hours and biased the compensated means by 1-4 SE), and their uncertainty
enters its SE (`fit_transient_free`'s joint covariance). The analysis re-estimates them from the
whole record too (`report.transient`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from gyrostand.analysis.angles import about, wrap180
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.analysis.transient import (
    Segments,
    TransientFit,
    TransientModel,
    Windows,
    compensated_covariances,
    compensated_mean_se,
    contradicts,
    design,
    fit_transient,
    fit_transient_free,
    well_determined,
)
from gyrostand.plan.model import EstimatePlan, SettlePlan

Named = tuple[tuple[tuple[int, int], float], ...]  # ((trial index, j), value) per series
MIN_BLOCKS = 6  # window means of the series before its first estimate
KEEP_SEGMENTS = 4  # the record fitted: this series and the three before (older ones add little)


def _drift(means: Sequence[float]) -> float:
    """Least-squares trend of equally spaced window means, times the span they cover: how far
    a transient not yet over still moves the reading during the hold time."""
    if len(means) < 3:
        return 0.0
    x = np.arange(len(means), dtype=float)
    slope = np.polyfit(x, np.asarray(means), 1)[0]
    return float(slope * len(means))


def band_settled(means_deg: Sequence[float], settle: SettlePlan) -> bool:
    """The band criterion on the window means of the hold time: all within +-band_deg of their
    mean, and their trend moves the reading by at most drift_deg."""
    centre = sum(means_deg) / len(means_deg)
    spread = max(abs(m - centre) for m in means_deg)
    return spread <= settle.band_deg and abs(_drift(means_deg)) <= settle.drift_deg


def hold_blocks(settle: SettlePlan, width_s: float) -> int:
    """How many window means the band criterion looks at."""
    return max(1, math.ceil(settle.hold_s / width_s))


@dataclass
class _Segment:
    step_s: float  # stand second the equilibrium moved
    free: bool  # its state at the step is not known from the record before it
    rows: list[tuple[float, float, float]] = field(default_factory=list)  # mid, width, deg


class TransientRecord:
    """Window means (stand seconds, headings) and the steps of the equilibrium since the engine
    started, and which are the observations of each uncompensated series (`observed`); the
    last KEEP_SEGMENTS segments are fitted on every block (so the work per block stays bounded
    over a campaign), the whole record once per series to identify the period and damping
    (`identify`)."""

    def __init__(self) -> None:
        self._segments: list[_Segment] = []
        self._branch: float | None = None
        # the kept segments' windows and their design at the last fit: a block's fit extends
        # them by its new windows (the same numbers as building them anew, 0.8 -> 0.25 ms a
        # fit of ~500 windows; bench_ingest, issue 37)
        self._kept: tuple[Segments, Windows] | None = None
        self._design: tuple[TransientModel, Segments, np.ndarray] | None = None
        # the uncompensated series' observation windows (middles, s): `observed`
        self._observed: dict[tuple[int, int], np.ndarray] = {}

    @property
    def chained(self) -> bool:
        """The current segment's state at its step follows from the record before it."""
        return bool(self._segments) and not self._segments[-1].free

    def step(self, t_s: float) -> None:
        """The equilibrium may move at stand second t_s (a start or stop took effect). A
        segment that got no window mean is dropped and its successor starts free."""
        empty = bool(self._segments) and not self._segments[-1].rows
        if empty:
            self._segments.pop()
        self._segments.append(_Segment(t_s, free=empty or not self._segments))

    def add(self, start_s: float, end_s: float, heading_deg: float) -> None:
        """A window mean over [start_s, end_s); a window before any step starts a segment."""
        if not self._segments:
            self.step(start_s)
        if self._branch is None:
            self._branch = heading_deg
        value = float(about(self._branch, heading_deg))
        self._segments[-1].rows.append(((start_s + end_s) / 2, end_s - start_s, value))

    def fit(self, model: TransientModel, free: bool = False) -> tuple[TransientFit, int] | None:
        """The fit of the kept segments and the current segment's index in it; None while it
        cannot be fitted (too short, degenerate). ``free``: the period and damping ratio are
        estimated too, from ``model``'s (`fit_transient_free`)."""
        seg, data = self._data(self._segments) if free else self._kept_data()
        try:
            if free:
                fit = fit_transient_free(model, seg, data)
            else:
                fit = fit_transient(model, seg, data, self._rows(model, seg, data))
        except AnalysisError:
            return None
        return fit, len(seg.step_s) - 1

    def _kept_data(self) -> tuple[Segments, Windows]:
        """`_data` of the last KEEP_SEGMENTS segments, extended from the last call's when only
        windows were added since (to the last segment: the only one `add` appends to)."""
        kept = self._segments[-KEEP_SEGMENTS:]
        seg = Segments(tuple(s.step_s for s in kept), (True, *(s.free for s in kept[1:])))
        if self._kept is None or self._kept[0] != seg:
            self._kept = self._data(kept)
            return self._kept
        data, rows = self._kept[1], kept[-1].rows
        new = len(rows) - (len(data.segment) - sum(len(s.rows) for s in kept[:-1]))
        if new:
            more = Windows.of([(len(kept) - 1, *row) for row in rows[-new:]])
            data = Windows(
                np.concatenate((data.segment, more.segment)),
                np.concatenate((data.mid_s, more.mid_s)),
                np.concatenate((data.width_s, more.width_s)),
                np.concatenate((data.value_deg, more.value_deg)),
            )
            self._kept = seg, data
        return self._kept

    def _rows(self, model: TransientModel, seg: Segments, data: Windows) -> np.ndarray:
        """`design` of the kept windows (`_kept_data`): the last call's rows extended by those
        of the new windows when the model and segments are the same (a row depends on its own
        window only)."""
        rows = np.empty((0, seg.n_params))
        if self._design is not None and self._design[:2] == (model, seg):
            rows = self._design[2]
        done = len(rows)
        if done < len(data.segment):
            new = design(model, seg, data.segment[done:], data.mid_s[done:], data.width_s[done:])
            rows = np.concatenate((rows, new))
            self._design = model, seg, rows
        return rows

    @staticmethod
    def _data(kept: list[_Segment]) -> tuple[Segments, Windows]:
        rows = [(k, *row) for k, s in enumerate(kept) for row in s.rows]
        seg = Segments(tuple(s.step_s for s in kept), (True, *(s.free for s in kept[1:])))
        return seg, Windows.of(rows)

    def compensation_se(
        self,
        fit: TransientFit,
        t_s: np.ndarray,
        width_s: np.ndarray,
        correlation_time_s: float | None = None,
    ) -> float:
        """SE of the current series' compensated mean, ``fit`` the free fit of the whole record
        (`fit(free=True)`), its observation windows at ``t_s`` and the reading's correlation
        time (`compensated_mean_se`)."""
        seg, data = self._data(self._segments)
        j = len(seg.step_s) - 1
        return compensated_mean_se(fit, data, j, t_s, width_s, correlation_time_s)

    def observed(self, series: tuple[int, int], windows_s: np.ndarray) -> None:
        """Series (trial index, j) ended uncompensated; ``windows_s`` (n, 2): the [start, end)
        stand seconds of its observation windows in this record (a series resumed after a
        restart has the others in another run's: independent of this one). Every later
        compensation stores its covariance with the series' plain mean
        (`earlier_covariances`)."""
        self._observed[series] = np.asarray(windows_s, dtype=float).reshape(-1, 2)

    def forget(self, trial: int) -> None:
        """Trial ``trial`` failed: what its series observed here is not what the analysis
        will use (nothing, or a retry's attempt, acquired in a later run)."""
        self._observed = {key: w for key, w in self._observed.items() if key[0] != trial}

    def earlier_covariances(
        self,
        fit: TransientFit,
        t_s: np.ndarray,
        width_s: np.ndarray,
        n_obs: int,
        correlation_time_s: float | None = None,
    ) -> Named:
        """Cov of the current series' compensated mean (`compensation_se`) with the plain mean
        (of ``n_obs`` observations) of each uncompensated series in this record (`observed`),
        named (trial index, j), in the order they ended (`compensated_covariances`)."""
        seg, data = self._data(self._segments)
        j = len(seg.step_s) - 1
        keys = list(self._observed)
        mids = [self._observed[key].mean(axis=1) for key in keys]
        cov = compensated_covariances(fit, data, j, t_s, width_s, mids, n_obs, correlation_time_s)
        return tuple(zip(keys, cov, strict=True))

    def sensitivity(
        self, model: TransientModel, t_s: np.ndarray, width_s: np.ndarray
    ) -> tuple[float, float, float]:
        """d/d(period s, damping ratio) of the current series' transient averaged over its
        observation windows, the whole record refitted at each (central differences, steps of
        1e-4 as `analysis.transient`'s): what a compensation's mean owes its period and damping
        (`analysis.gls`); and the covariance of its settle point with the previous series' at
        ``model``'s period and damping (the state carried over the step couples them; 0 when
        the series starts free)."""
        j = len(self._data(self._segments)[0].step_s) - 1
        return self._sensitivities(model, [(j, t_s, width_s)])[0]

    def _sensitivities(
        self, model: TransientModel, targets: Sequence[tuple[int, np.ndarray, np.ndarray]]
    ) -> list[tuple[float, float, float]]:
        """`sensitivity` of the windows (t_s, width_s) of segment j, for each (j, t_s, width_s)
        of ``targets`` (the record refitted once at each step for all)."""
        seg, data = self._data(self._segments)
        at = fit_transient(model, seg, data)
        fits = []
        for dp, dr in ((1e-4 * model.undamped_period_s, 0.0), (0.0, 1e-4)):
            up = TransientModel(model.undamped_period_s + dp, model.damping_ratio + dr)
            down = TransientModel(model.undamped_period_s - dp, model.damping_ratio - dr)
            fits.append((fit_transient(up, seg, data), fit_transient(down, seg, data), dp + dr))
        out = []
        for j, t_s, width_s in targets:
            chained = j > 0 and not seg.free[j]
            previous = float(at.covariance[j, j - 1]) if chained else 0.0
            d = [
                (high.mean_transient(j, t_s, width_s)[0] - low.mean_transient(j, t_s, width_s)[0])
                / (2 * step)
                for high, low, step in fits
            ]
            out.append((d[0], d[1], previous))
        return out

    def late_compensations(
        self,
        fit: TransientFit,
        t_s: np.ndarray,
        width_s: np.ndarray,
        n_obs: int,
        correlation_time_s: float | None = None,
    ) -> tuple[
        tuple[float, float, float],
        list[tuple[tuple[int, int], np.ndarray, float, tuple[float, float], float]],
    ]:
        """Each uncompensated series wholly in this record (`observed`: trial 1's, the first of
        a run, and any the record could not yet compensate) compensated now by ``fit``, the
        free fit of the whole record (issue 34: they waited for the transient bound computed
        with the plan's period and damping, which left trial 1 biased by -0.47 SE when the plan
        states a period 10 % short or a damping 0.05 low): per series, (trial index, j), the
        fitted transient over its windows (deg each), the SE of its compensated mean
        (`compensated_mean_se`), the sensitivity d/d(period, ratio) and the covariance with the
        previous series' settle point (`sensitivity`); first, the current series' `sensitivity`
        at its windows ``t_s``, ``width_s`` (one set of refits for all)."""
        seg, data = self._data(self._segments)
        targets = []
        for key, windows in self._observed.items():
            if len(windows) != n_obs:
                continue  # partly in another run's record (a resumed series): its own S^2
            mids, widths = windows.mean(axis=1), windows[:, 1] - windows[:, 0]
            match = np.abs(data.mid_s[None, :] - mids[:, None]) < 1e-6
            if not match.any(axis=1).all():
                raise ValueError(f"series {key}: its windows are not all in the record")
            targets.append((key, int(data.segment[np.argmax(match[0])]), mids, widths))
        current = (len(seg.step_s) - 1, t_s, width_s)
        own, *sens = self._sensitivities(
            fit.model, [current, *((j, t, w) for _, j, t, w in targets)]
        )
        out = []
        for (key, j, mids, widths), (d_period, d_ratio, previous) in zip(
            targets, sens, strict=True
        ):
            values, _ = fit.transient(j, mids, widths)
            se = compensated_mean_se(fit, data, j, mids, widths, correlation_time_s)
            out.append((key, values, se, (d_period, d_ratio), previous))
        return own, out

    @property
    def start_s(self) -> float:
        """Stand second of the record's first window's middle (which record: one run)."""
        return self._segments[0].rows[0][0] if self._segments else math.nan

    @property
    def span_s(self) -> float:
        """Stand seconds from the first window to the last."""
        rows = [row for s in self._segments for row in s.rows]
        return rows[-1][0] - rows[0][0] if rows else 0.0


@dataclass(frozen=True)
class Identified:
    """The compass's period and damping ratio as the whole record gives them (a free fit), well
    determined (`well_determined`), with their standard errors; ``contradicted``: more than
    REJECT_SE from the plan's (`contradicts`)."""

    undamped_period_s: float
    period_se_s: float
    damping_ratio: float
    damping_ratio_se: float
    contradicted: bool

    def describe(self, plan: EstimatePlan) -> str:
        """The "plan contradicted" event message."""
        return (
            f"the record contradicts the plan: period {self.undamped_period_s:.0f} +/- "
            f"{self.period_se_s:.0f} s vs the plan's {plan.undamped_period_s:g} s, damping ratio "
            f"{self.damping_ratio:.3f} +/- {self.damping_ratio_se:.3f} vs the plan's "
            f"{plan.damping_ratio:g} (transient model fitted to the record, Bezvesilna & Gura); "
            "the settle criterion uses the record's values from here: check [settle] "
            "undamped_period_s and damping_ratio"
        )

    def applied(self, plan: EstimatePlan) -> EstimatePlan:
        """``plan`` with the record's period and damping ratio when they contradict its own."""
        if not self.contradicted:
            return plan
        return replace(
            plan, undamped_period_s=self.undamped_period_s, damping_ratio=self.damping_ratio
        )


def identify(record: TransientRecord, plan: EstimatePlan) -> Identified | None:
    """The record's own period and damping ratio once it spans a precession period (a free
    fit needs about one, `estimate_settle_point_free`) and determines them well; None
    otherwise."""
    if record.span_s < plan.undamped_period_s:
        return None
    fitted = record.fit(plan.model, free=True)
    if fitted is None or not well_determined(fitted[0]):
        return None
    fit = fitted[0]
    assert fit.period_se_s is not None and fit.damping_ratio_se is not None
    return Identified(
        fit.model.undamped_period_s,
        fit.period_se_s,
        fit.model.damping_ratio,
        fit.damping_ratio_se,
        contradicts(fit, plan.model),
    )


@dataclass(frozen=True)
class SettleCheck:
    """The rule evaluated at the end of a settle block, ``t_s`` stand seconds from the settle
    start; ``settle_point_deg`` is R_j (a heading; None while the record cannot be fitted)."""

    t_s: float
    settle_point_deg: float | None
    standard_error_deg: float
    spread_deg: float  # max - min of the last `stable_estimates` estimates (inf: fewer yet)
    transient_deg: float  # largest |predicted transient| + 2 SE over the observation windows
    plan: EstimatePlan
    chained: bool  # the series' state at its step is carried over from the record

    @property
    def compensates(self) -> bool:
        """Compensated: only with the state carried over (a free state needs a long record)."""
        return self.plan.compensated and self.chained

    @property
    def stable(self) -> bool:
        """Conditions 1 and 2: the estimate itself is known within the tolerance."""
        tol = self.plan.tolerance_deg
        known = self.settle_point_deg is not None and self.standard_error_deg <= tol
        return known and self.spread_deg <= tol

    @property
    def ready(self) -> bool:
        """Observe from here (condition 3 unless compensated)."""
        bounded = self.transient_deg <= self.plan.transient_tolerance_deg
        return self.stable and (self.compensates or bounded)


def describe(outcome: SettleOutcome, check: SettleCheck) -> str:
    """The "early settle" event message (for people: the series stores `outcome` itself)."""
    plan = check.plan
    text = (
        f"settled by the transient model after {outcome.settle_s:.1f} s: settle point "
        f"{outcome.estimate_deg:.5f} deg (SE {outcome.standard_error_deg:.5f} deg, stable since "
        f"{outcome.stable_since_s:.1f} s at {outcome.stable_estimate_deg:.5f} deg, last estimates "
        f"within {check.spread_deg:.5f} deg; tolerance {plan.tolerance_deg:.5f} deg); "
    )
    if check.compensates:
        text += (
            f"transient over the observations {check.transient_deg:.5f} deg (fit + 2 SE), "
            "to be compensated; "
        )
    else:
        text += (
            f"transient over the observations at most {check.transient_deg:.5f} deg (fit + 2 SE; "
            f"bound {plan.transient_tolerance_deg:.5f} deg); "
        )
    if outcome.band_s is None:
        return text + "band criterion not predicted within max_wait_s: time saved unknown"
    how = "held" if outcome.band_measured else "predicted"
    text += f"band criterion {how} after {outcome.band_s:.1f} s: "
    saved = outcome.band_s - outcome.settle_s
    if saved < 0:  # the estimate became stable only after the band criterion held
        return text + f"no time saved (settled {-saved:.1f} s after it)"
    return text + f"{saved:.1f} s saved"


class EarlySettle:
    """The rule above for one series, fed one settle block at a time (the blocks themselves go
    to the shared `TransientRecord` first)."""

    def __init__(
        self,
        plan: EstimatePlan,
        record: TransientRecord,
        settle_start_ms: int,
        window_s: float,
        step_s: float,
        n_obs: int,
    ) -> None:
        self.plan = plan
        self.record = record
        self.settle_start_ms = settle_start_ms
        self.window_s = window_s
        self.step_s = step_s  # window + spacing: where the observation windows will lie
        self.n_obs = n_obs
        self._estimates: list[float] = []
        self._blocks = 0
        self._last: SettleCheck | None = None
        self._unbounded: np.ndarray | None = None  # `_last`'s windows, its bound not yet taken
        self.stable: SettleCheck | None = None  # first check meeting conditions 1-2
        self.fit: tuple[TransientFit, int] | None = None
        self.band_s: float | None = None  # first block end where the band criterion held

    def check(self, end_ms: int, band: bool) -> SettleCheck:
        """Evaluate the rule at a block end (stand ms) after its mean went to the record; `band`
        tells whether the band criterion holds there."""
        since, end_s = (end_ms - self.settle_start_ms) / 1000, end_ms / 1000
        if band and self.band_s is None:
            self.band_s = since
        self._blocks += 1
        r, se, spread = None, math.inf, math.inf
        self.fit = self.record.fit(self.plan.model) if self._blocks >= MIN_BLOCKS else None
        self._unbounded = None
        if self.fit is not None:
            fit, j = self.fit
            r, se = fit.settle_point(j)
            self._estimates.append(r)
            recent = self._estimates[-self.plan.stable_estimates :]
            if len(recent) == self.plan.stable_estimates:
                spread = max(recent) - min(recent)
            self._unbounded = end_s + self.window_s / 2 + self.step_s * np.arange(self.n_obs)
        check = SettleCheck(since, r, se, spread, math.inf, self.plan, self.record.chained)
        # the transient's bound (a third of a check) only where it can decide (conditions 1-2
        # met), or when asked for (`last`)
        self._last = check
        if check.stable:
            check = self.last
            assert check is not None
            if self.stable is None:
                self.stable = check
        return check

    @property
    def last(self) -> SettleCheck | None:
        """The last check, its transient bound taken if it was not."""
        if self._unbounded is not None and self._last is not None and self.fit is not None:
            fit, j = self.fit
            bound = fit.bound(j, self._unbounded, self.window_s)
            self._last = replace(self._last, transient_deg=bound)
            self._unbounded = None
        return self._last

    def outcome(
        self, reference_deg: float, means_deg: Sequence[float], settle: SettlePlan
    ) -> SettleOutcome:
        """The outcome once `last` is ready; `means_deg` are all block means of the series as
        deviations from `reference_deg` (for the band prediction)."""
        check, stable, fitted = self.last, self.stable, self.fit
        assert check is not None and check.ready and check.settle_point_deg is not None
        assert stable is not None and stable.settle_point_deg is not None and fitted is not None
        band_s = self.band_s
        if band_s is None:
            fit, j = fitted
            start = self.settle_start_ms / 1000

            def predict(t_s: np.ndarray) -> np.ndarray:
                value = fit.settle_point(j)[0] + fit.transient(j, start + t_s, self.window_s)[0]
                return wrap180(value - reference_deg)

            band_s = predict_band_settle_s(means_deg, self.window_s, check.t_s, predict, settle)
        return SettleOutcome(
            criterion="compensated" if check.compensates else "estimate",
            settle_s=check.t_s,
            estimate_deg=float(about(reference_deg, check.settle_point_deg)),
            standard_error_deg=check.standard_error_deg,
            stable_since_s=stable.t_s,
            stable_estimate_deg=float(about(reference_deg, stable.settle_point_deg)),
            band_s=band_s,
            band_measured=self.band_s is not None,
        )


def predict_band_settle_s(
    means_deg: Sequence[float],
    width_s: float,
    end_s: float,
    predict: Callable[[np.ndarray], np.ndarray],
    settle: SettlePlan,
) -> float | None:
    """When (stand seconds from the settle start) the band criterion would first hold if the
    record of block means went on as the fitted transient predicts; None when not within
    max_wait_s. The continuation is noise-free, which lets the band criterion hold sooner than
    on real readings: the time saved it implies errs low."""
    need = hold_blocks(settle, width_s)
    n_ahead = max(0, math.floor((settle.max_wait_s - end_s) / width_s))
    ahead_end = end_s + width_s * np.arange(1, n_ahead + 1)
    record = [*means_deg, *predict(ahead_end - width_s / 2).tolist()]
    for k, t in enumerate(ahead_end, start=len(means_deg) + 1):
        if k >= need and band_settled(record[k - need : k], settle):
            return float(t)
    return None
