"""When a series may start observing: the band criterion, and early settle from the settle point
estimated online on the transient (seed 003).

Record. The estimator sees the engine's settle blocks, not frames: each block is as long as one
observation window, i.e. whole rocking periods while rocking, so a block mean cancels the
reading's components at the rocking frequency p and 2p, and averages the sensor's correlated
noise (20 s correlation time against 30-60 s blocks). One estimate per block: a modest cadence
(every 30-60 stand seconds) on a record of at most a few hundred points. The mean over a block of
e^(-xi t) (A_c sin(omega t) + A_s cos(omega t)) is again of that form at the block's middle (other
A_c, A_s), so the block means fitted at their mid times leave the settle point R unbiased, and
the fitted model predicts window means: what an observation is.

Rule. With tol = tolerance_fraction x the plan's expected S{<delta>}_e (seed 000 eq 2.6), the
series observes from the end of the first block at which

1. the least-squares fit of the record so far (seed 003 eqs 5-6, damped basis of eq 3 with the
   plan's omega and xi) gives R^ a standard error <= tol,
2. the last `stable_estimates` estimates R^ lie within tol of each other (max - min), and
3. the fitted transient, predicted over the N observation windows to come, stays within +-tol
   of R^: the observations are measured readings, so this is what keeps each of them within
   tol of the settle point.

Condition 3 is what takes the time: the estimate is typically stable after ~20 minutes of an
84-minute compass, the reading needs ~40 to come within 0.015 deg of it. The band criterion is
not a fallback (it may hold on the overshoot of a damped transient, 4.6 % of the step for
xi/omega0 = 0.7, before the estimate does); it is only evaluated to record the time saved:
measured when it held before, else predicted from the fitted transient. A transient the model
does not describe (wrong period or damping in the plan) keeps the standard error up and ends in
the settle timeout.

omega and xi come from the plan (instrument data), not from the record: fitting them too
(`analysis.settle.estimate_settle_point_free`) on records shorter than a period gave confident but
wrong fits (on the paper campaign, 4 of 12 series started within 10 minutes, 0.10-0.28 deg off)
at ~100 times the cost. Fit them once on a whole recorded transient instead, and know them well:
a plan 10 % short on the period, or 0.05 low on the damping ratio, about doubles the error of the
series means; as much the other way only costs time (bench/bench_early_settle.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.settle import SettleEstimate, SettleOutcome, estimate_settle_point
from gyrostand.plan.model import EstimatePlan, SettlePlan

MIN_BLOCKS = 6  # 3 state parameters + 3 degrees of freedom for S^2 and the noise correlation
_PREDICTION_POINTS = 64  # grid on which the transient is predicted over the observation span


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


@dataclass(frozen=True)
class SettleCheck:
    """The early-settle rule evaluated at the end of a settle block, ``t_s`` stand seconds from
    the settle start; angles are deviations (deg) from the trial's reference heading."""

    t_s: float
    estimate: SettleEstimate | None  # None while the record cannot be fitted yet
    spread_deg: float  # max - min of the last `stable_estimates` estimates (inf: fewer yet)
    transient_deg: float  # largest |predicted transient| over the observation span
    tolerance_deg: float

    @property
    def stable(self) -> bool:
        """Conditions 1 and 2: the estimate itself is known within the tolerance."""
        e, tol = self.estimate, self.tolerance_deg
        return e is not None and e.standard_error_deg <= tol and self.spread_deg <= tol

    @property
    def ready(self) -> bool:
        """All three conditions: observe from here."""
        return self.stable and self.transient_deg <= self.tolerance_deg


def describe(outcome: SettleOutcome, check: SettleCheck) -> str:
    """The "early settle" event message (for people: the series stores `outcome` itself);
    `check` adds the rule's figures."""
    text = (
        f"settled by the estimate after {outcome.settle_s:.1f} s: settle point "
        f"{outcome.estimate_deg:.5f} deg (SE {outcome.standard_error_deg:.5f} deg, stable since "
        f"{outcome.stable_since_s:.1f} s at {outcome.stable_estimate_deg:.5f} deg, last estimates "
        f"within {check.spread_deg:.5f} deg, "
        f"predicted transient over the observations {check.transient_deg:.5f} deg; "
        f"tolerance {check.tolerance_deg:.5f} deg); "
    )
    if outcome.band_s is None:
        return text + "band criterion not predicted within max_wait_s: time saved unknown"
    how = "held" if outcome.band_measured else "predicted"
    return (
        text + f"band criterion {how} after {outcome.band_s:.1f} s: {outcome.saved_s:.1f} s saved"
    )


class EarlySettle:
    """The settle record of one series and the rule above, fed one settle block at a time."""

    def __init__(self, plan: EstimatePlan, observe_span_s: float) -> None:
        self.plan = plan
        self.observe_span_s = observe_span_s
        self._t_s: list[float] = []
        self._mean_deg: list[float] = []
        self._estimates_deg: list[float] = []
        self.last: SettleCheck | None = None
        self.stable: SettleCheck | None = None  # first check meeting conditions 1-2
        self.band_s: float | None = None  # first block end where the band criterion held

    def add_block(self, mid_s: float, mean_deg: float, end_s: float, band: bool) -> SettleCheck:
        """Add a block mean (deg) at its middle time, note whether the band criterion holds at
        its end, and evaluate the rule there (times in stand seconds from the settle start)."""
        if band and self.band_s is None:
            self.band_s = end_s
        self._t_s.append(mid_s)
        self._mean_deg.append(mean_deg)
        tol = self.plan.tolerance_deg
        estimate = self._fit() if len(self._t_s) >= MIN_BLOCKS else None
        spread = transient = math.inf
        if estimate is not None:
            r = estimate.settle_point_deg
            self._estimates_deg.append(r)
            recent = self._estimates_deg[-self.plan.stable_estimates :]
            if len(recent) == self.plan.stable_estimates:
                spread = max(recent) - min(recent)
            ahead = np.linspace(end_s, end_s + self.observe_span_s, _PREDICTION_POINTS)
            transient = float(np.max(np.abs(estimate.predict(ahead) - r)))
        self.last = SettleCheck(end_s, estimate, spread, transient, tol)
        if self.last.stable and self.stable is None:
            self.stable = self.last
        return self.last

    def _fit(self) -> SettleEstimate | None:
        t, y, p = np.array(self._t_s), np.array(self._mean_deg), self.plan
        try:
            return estimate_settle_point(t, y, p.omega_rad_s, p.damping_per_s)
        except AnalysisError:  # too short or degenerate yet: no estimate at this block
            return None

    def outcome(
        self, reference_deg: float, means_deg: Sequence[float], width_s: float, settle: SettlePlan
    ) -> SettleOutcome:
        """The outcome once `last` is ready; `means_deg` are all block means of the series (for
        the band prediction), `reference_deg` turns deviations into headings."""
        check, stable = self.last, self.stable
        assert check is not None and check.ready and check.estimate is not None
        assert stable is not None and stable.estimate is not None
        band_s = self.band_s
        if band_s is None:
            band_s = predict_band_settle_s(means_deg, width_s, check.t_s, check.estimate, settle)
        return SettleOutcome(
            criterion="estimate",
            settle_s=check.t_s,
            estimate_deg=reference_deg + check.estimate.settle_point_deg,
            standard_error_deg=check.estimate.standard_error_deg,
            stable_since_s=stable.t_s,
            stable_estimate_deg=reference_deg + stable.estimate.settle_point_deg,
            band_s=band_s,
            band_measured=self.band_s is not None,
        )


def predict_band_settle_s(
    means_deg: Sequence[float],
    width_s: float,
    end_s: float,
    estimate: SettleEstimate,
    settle: SettlePlan,
) -> float | None:
    """When (stand seconds from the settle start) the band criterion would first hold if the
    record of block means went on as the fitted transient predicts; None when not within
    max_wait_s. The continuation is noise-free, which lets the band criterion hold sooner than
    on real readings: the time saved it implies errs low."""
    need = hold_blocks(settle, width_s)
    n_ahead = max(0, math.floor((settle.max_wait_s - end_s) / width_s))
    ahead_end = end_s + width_s * np.arange(1, n_ahead + 1)
    record = [*means_deg, *estimate.predict(ahead_end - width_s / 2).tolist()]
    for k, t in enumerate(ahead_end, start=len(means_deg) + 1):
        if k >= need and band_settled(record[k - need : k], settle):
            return float(t)
    return None
