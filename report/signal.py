"""Section 10 of the report: the random part of the compass reading and what follows from it
(seed 004, Sveshnikov §8.3), with the settle points stored per series (seed 003).

    uniform_record(t_ms, heading_deg, source) -> ReadingRecord
    signal_section(reading, note, records, acceptance) -> SignalSection

From one stationary stretch of the reading (the longest still series of a campaign, or a stretch
of a raw log), linear trend removed: the noise characterisation of `analysis.noise` (correlation
8.92, exponential and smooth models 8.89, Welch spectrum and hidden harmonics 8.90-8.91, Allan
deviation, sampling interval 8.94); the correlation of successive observations of every series
(the window means that Cochran's and Fisher's tests take as independent); and the acceptance by
excursions (8.79-8.88) when the plan asks for it. Renderers only format these numbers.
"""

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from gyrostand.analysis.angles import about
from gyrostand.analysis.assumptions import AssumptionCheck
from gyrostand.analysis.campaign import json_safe
from gyrostand.analysis.effective import variance_inflation, window_mean_correlation
from gyrostand.analysis.errors import AnalysisError
from gyrostand.analysis.excursions import (
    CHECKED_MIN_LEVEL,
    POISSON_ESTIMATE_MAX_EXCURSIONS,
    POISSON_MAX_EXCURSIONS,
    VANMARCKE_MAX_EXCURSIONS,
    ExcursionAcceptance,
    excursion_acceptance,
    tolerance_for_risk,
)
from gyrostand.analysis.noise import CorrelationModel, NoiseCharacterisation, characterise_noise
from gyrostand.report.compliance import FAIL, PASS
from gyrostand.report.model import ExcursionCriterion, ReadingRecord, TrialRecord

MIN_READINGS = 500  # below this the correlation estimate has fewer than 50 lags (N/10)
TIME_SAVED_NOTE = (
    "Time saved: stand seconds from the moment a series began observing to the moment the plan's "
    "band criterion held on the readings or, when observation began before that, is predicted "
    "to hold on the fitted transient (a noise-free continuation: the saving errs low). A series "
    "that waited for the band criterion saved nothing; unknown: the band criterion is not "
    "predicted within the plan's longest settle wait; not recorded: no settle criterion is "
    "recorded."
)
NO_ACCEPTANCE = "The plan asks for no acceptance by excursions."
RICE_NOTE = (
    "Computed on the smooth correlation model, whose crossings Rice's formula counts; the white "
    "part of the reading is left out (the excursions of uncorrelated sensor noise depend only on "
    "how often it is sampled). With the bounds at least "
    f"{CHECKED_MIN_LEVEL:g} sigma from the mean, P(no excursion) is the Poisson law for a "
    f"broad-band reading up to Rice's expected excursions n = {POISSON_MAX_EXCURSIONS:g}, or "
    f"Vanmarcke's clustering correction up to n = {VANMARCKE_MAX_EXCURSIONS:g}: there they came "
    "within 10 % of simulation; beyond n = 1 up to n = "
    f"{POISSON_ESTIMATE_MAX_EXCURSIONS:g}, for a broad band, the Poisson law is the best estimate "
    "(within 17 % of simulation), where the guaranteed bound is 0. Elsewhere it is given as a "
    "lower bound, so the risk is an upper bound and a PASS holds all the same."
)


def uniform_record(t_ms: np.ndarray, heading_deg: np.ndarray, source: str) -> ReadingRecord:
    """Valid heading frames (stand ms, deg, in time order) on a uniform grid. The interval is
    the median frame spacing; headings are taken about the first one, wrapped to +-180 deg (a
    record crossing 0/360 deg stays continuous); grid points without a frame are interpolated
    linearly. AnalysisError when there is no usable record."""
    t, first = np.unique(np.asarray(t_ms, dtype=float), return_index=True)
    h = np.asarray(heading_deg, dtype=float)[first]
    if t.size < 3:
        raise AnalysisError(f"{source}: {t.size} heading frames, too few for a reading record")
    step_ms = float(np.median(np.diff(t)))
    n = int(round((t[-1] - t[0]) / step_ms)) + 1
    h = about(h[0], h)
    grid = t[0] + step_ms * np.arange(n)
    return ReadingRecord(
        source=source,
        start_ms=float(t[0]),
        dt_s=step_ms / 1000.0,
        reading_deg=np.interp(grid, t, h),
        frames=int(t.size),
        filled=max(n - int(t.size), 0),
    )


# --- correlation of successive observations --------------------------------------------------


@dataclass(frozen=True)
class ObservationCorrelation:
    """Series j of a trial: its ``n`` observations are means over windows of ``window_s`` whose
    starts are ``step_s`` apart; ``correlation`` between successive ones from the fitted
    correlation; ``correlated`` when it exceeds ``max_correlation`` (independence broken);
    ``inflation`` f of the variance of their mean over all lags, N_eff = n / f
    (`analysis.effective`)."""

    trial: int
    j: int
    window_s: float
    step_s: float
    correlation: float
    max_correlation: float
    correlated: bool
    n: int
    inflation: float

    @property
    def n_eff(self) -> float:
        return self.n / self.inflation


def _windows(record: TrialRecord, j: int) -> tuple[float, float] | None:
    """Median window length and start-to-start step (s) of series j, when it has two timed
    observations or more."""
    series = next((s for s in record.series if s.j == j), None)
    if series is None:
        return None
    timed = [o for o in series.observations if o.window_start_ms is not None]
    timed = [o for o in timed if o.window_end_ms is not None]
    if len(timed) < 2:
        return None
    starts = np.array([o.window_start_ms for o in timed], dtype=float)
    lengths = np.array([o.window_end_ms for o in timed], dtype=float) - starts
    return float(np.median(lengths)) / 1000.0, float(np.median(np.diff(starts))) / 1000.0


def observation_correlations(
    model: CorrelationModel, records: tuple[TrialRecord, ...], dt_s: float, max_correlation: float
) -> tuple[ObservationCorrelation, ...]:
    """`window_mean_correlation` at every lag for every series with timed observations."""
    rows = []
    for record in records:
        for j in (1, 2):
            windows = _windows(record, j)
            if windows is None or windows[0] <= 0:
                continue
            window, step = windows
            n = len(next(s for s in record.series if s.j == j).observations)
            rho = [window_mean_correlation(model, window, k * step, dt_s) for k in range(1, n)]
            rows.append(
                ObservationCorrelation(
                    record.index,
                    j,
                    window,
                    step,
                    rho[0],
                    max_correlation,
                    abs(rho[0]) > max_correlation,
                    n,
                    variance_inflation(np.array(rho), n),
                )
            )
    return tuple(rows)


# --- settle points ----------------------------------------------------------------------------


@dataclass(frozen=True)
class SettleRow:
    """The settle of one series as stored: start and end (stand ms), the settle time, the settle
    estimate and how far the mean of the series' observations (compensated ones corrected)
    came out from it; by which criterion it settled (None: not recorded), the estimate's
    standard error (transient model), when the band criterion held or is predicted to hold
    (s from the settle start) and the stand seconds saved against waiting for it (see
    ``TIME_SAVED_NOTE``)."""

    trial: int
    j: int
    started_ms: int | None
    done_ms: int | None
    settle_s: float | None
    estimate_deg: float | None
    observed_mean_deg: float | None
    offset_deg: float | None  # observed mean - estimate
    criterion: str | None
    standard_error_deg: float | None
    band_s: float | None
    band_measured: bool | None
    saved_s: float | None


def settle_rows(records: tuple[TrialRecord, ...]) -> tuple[SettleRow, ...]:
    """One row per stored series that recorded a settle (start, end or estimate)."""
    rows = []
    for record in records:
        for s in record.series:
            stored = (s.settle_started_ms, s.settle_done_ms, s.settle_estimate_deg)
            if all(v is None for v in stored):
                continue
            values = [o.corrected_deg for o in s.observations]
            mean = float(np.mean(values)) if values else None
            known = s.settle_started_ms is not None and s.settle_done_ms is not None
            how = s.settle
            rows.append(
                SettleRow(
                    trial=record.index,
                    j=s.j,
                    started_ms=s.settle_started_ms,
                    done_ms=s.settle_done_ms,
                    settle_s=(s.settle_done_ms - s.settle_started_ms) / 1000.0 if known else None,
                    estimate_deg=s.settle_estimate_deg,
                    observed_mean_deg=mean,
                    offset_deg=None
                    if mean is None or s.settle_estimate_deg is None
                    else mean - s.settle_estimate_deg,
                    criterion=None if how is None else how.criterion,
                    standard_error_deg=None if how is None else how.standard_error_deg,
                    band_s=None if how is None else how.band_s,
                    band_measured=None if how is None else how.band_measured,
                    saved_s=None if how is None else how.saved_s,
                )
            )
    return tuple(rows)


# --- acceptance by excursions -----------------------------------------------------------------


@dataclass(frozen=True)
class ExcursionVerdict:
    """The plan's acceptance by excursions on the fitted smooth correlation (Sveshnikov §8.3,
    8.79-8.89): alpha = P(no excursion out of +-tolerance about the mean in the control time) by
    the method ``excursions.method`` names, ``risk`` = 1 - alpha (an upper bound when alpha is a
    lower one), the tolerance that gives exactly the allowed risk by the same method (inverse
    problem; None when no band can), and the verdict."""

    criterion: ExcursionCriterion
    excursions: ExcursionAcceptance
    risk: float
    tolerance_for_max_risk_deg: float | None
    verdict: str
    detail: str


def _method_text(result: ExcursionAcceptance) -> str:
    """alpha and where it comes from, e.g. "P(none) 0.9938 (Vanmarcke's clustering correction,
    ...; the Poisson value e^(-n) 0.9923 is lower)", with the unchecked estimates beside a bound."""
    alpha = f"P(none) {'>= ' if result.is_bound else ''}{result.p_no_excursion:.4g}"
    rice = result.rice
    if rice is None:
        return f"{alpha} ({result.method_note})"
    if result.method == "vanmarcke":
        side = "lower" if rice.p_poisson < result.p_no_excursion else "higher"
        poisson = f"the Poisson value e^(-n) {rice.p_poisson:.4g} is {side}"
        return f"{alpha} ({result.method_note}; {poisson})"
    if not result.is_bound:
        return f"{alpha} ({result.method_note}; e^(-n) {rice.p_poisson:.4g})"
    others = [f"Vanmarcke's clustering correction gives {rice.p_vanmarcke:.4g}"]
    if result.method == "rice":
        others.append(f"the Poisson value e^(-n) {rice.p_poisson:.4g}")
    unchecked = " and ".join(others) + ", not checked against simulation here"
    return f"{alpha} ({result.method_note}; {unchecked})"


def excursion_verdict(model: CorrelationModel, criterion: ExcursionCriterion) -> ExcursionVerdict:
    """PASS when the risk of an excursion in the control time is at most the plan's (when the
    risk is only an upper bound, FAIL means that it is not shown to be)."""
    eps, duration = criterion.tolerance_deg, criterion.duration_s
    result = excursion_acceptance(model, -eps, eps, duration)
    try:
        eps_risk: float | None = tolerance_for_risk(model, 1.0 - criterion.max_risk, duration)
    except AnalysisError:
        eps_risk = None
    passed = result.risk <= criterion.max_risk
    if result.is_bound:
        within = "within" if passed else "not shown to be within"
        risk = f"is at most {result.risk:.3g}, {within} the allowed {criterion.max_risk:g}"
    else:
        risk = f"= {result.risk:.3g} {'<=' if passed else '>'} the allowed {criterion.max_risk:g}"
    detail = f"P(excursion in {duration:g} s) {risk}: {_method_text(result)}."
    return ExcursionVerdict(
        criterion, result, result.risk, eps_risk, PASS if passed else FAIL, detail
    )


# --- the section ------------------------------------------------------------------------------


@dataclass(frozen=True)
class SignalSection:
    """Section 10. ``noise`` is None when there is no usable record (``record_note`` or
    ``noise_error`` say why); then nothing that depends on it is assessed."""

    record: ReadingRecord | None
    record_note: str
    trend_deg_per_h: float | None
    noise: NoiseCharacterisation | None
    noise_error: str | None
    observations: tuple[ObservationCorrelation, ...]
    settle: tuple[SettleRow, ...]
    acceptance: ExcursionVerdict | None
    acceptance_note: str

    @property
    def reading_interval_ok(self) -> bool | None:
        """The record's reading interval is within the recommended Delta (8.94)."""
        if self.noise is None or self.record is None:
            return None
        return self.record.dt_s <= self.noise.sampling.interval_s

    @property
    def time_saved_s(self) -> float | None:
        """Stand seconds saved over the series whose saving is known (None: none is)."""
        saved = [r.saved_s for r in self.settle if r.saved_s is not None]
        return float(sum(saved)) if saved else None

    @property
    def correlated_observations(self) -> bool | None:
        """Some series has correlated successive observations (None: not assessed)."""
        if not self.observations:
            return None
        return any(o.correlated for o in self.observations)

    def independence(self) -> AssumptionCheck | None:
        """The campaign's one check of independent observations, from the reading's fitted
        correlation function (eqs 8.92-8.94); None when no series could be assessed (the
        analysis then tests the N observations themselves)."""
        if not self.observations:
            return None
        largest = max(self.observations, key=lambda o: abs(o.correlation))
        correlated = [o for o in self.observations if o.correlated]
        return AssumptionCheck(
            "independence",
            "correlation of successive observations from the reading's correlation function "
            "(Sveshnikov, section 8.3, eqs 8.92-8.94)",
            largest.correlation,
            None,
            not correlated,
            f"{len(correlated)} of {len(self.observations)} series have successive "
            f"observations correlated beyond |rho| = {largest.max_correlation:.2f} (largest "
            f"{largest.correlation:+.3f}, trial {largest.trial} series {largest.j})",
        )

    def inflation(self) -> dict[int, tuple[float, float]]:
        """Per trial with both series assessed, the variance inflation f of the mean of the
        series before and under rocking (the analysis then takes N_eff = N/f)."""
        found = {(o.trial, o.j): o.inflation for o in self.observations}
        trials = {o.trial for o in self.observations}
        return {
            i: (found[i, 1], found[i, 2]) for i in trials if (i, 1) in found and (i, 2) in found
        }

    def to_dict(self) -> dict[str, Any]:
        r, a = self.record, self.acceptance
        return json_safe(
            {
                "record": None
                if r is None
                else {
                    "source": r.source,
                    "start_ms": r.start_ms,
                    "dt_s": r.dt_s,
                    "n": int(r.reading_deg.size),
                    "duration_s": r.duration_s,
                    "frames": r.frames,
                    "filled": r.filled,
                },
                "record_note": self.record_note,
                "trend_deg_per_h": self.trend_deg_per_h,
                "noise": None if self.noise is None else self.noise.to_dict(),
                "noise_error": self.noise_error,
                "reading_interval_ok": self.reading_interval_ok,
                "observations": [asdict(o) for o in self.observations],
                "correlated_observations": self.correlated_observations,
                "settle": [asdict(s) for s in self.settle],
                "time_saved_s": self.time_saved_s,
                "acceptance": None
                if a is None
                else {
                    "criterion": asdict(a.criterion),
                    "excursions": a.excursions.to_dict(),
                    "risk": a.risk,
                    "tolerance_for_max_risk_deg": a.tolerance_for_max_risk_deg,
                    "verdict": a.verdict,
                    "detail": a.detail,
                },
                "acceptance_note": self.acceptance_note,
            }
        )


def _characterise(reading: ReadingRecord) -> tuple[float, NoiseCharacterisation]:
    """Trend (deg/h) and the characterisation of the detrended record (a settled compass still
    creeps: a leftover of the damped transient, seed 003, would pass for correlated noise); its
    correlation function pools the record's ``others``, each less its own line."""
    n = reading.reading_deg.size
    if n < MIN_READINGS:
        raise AnalysisError(f"{n} readings: too short for the noise analysis (need {MIN_READINGS})")
    slope, residual = _detrended(reading.reading_deg, reading.dt_s)
    others = tuple(_detrended(x, reading.dt_s)[1] for x in reading.others)
    noise = characterise_noise(residual, reading.dt_s, trend_degree=1, others=others)
    return slope * 3600.0, noise


def _detrended(x: np.ndarray, dt_s: float) -> tuple[float, np.ndarray]:
    """The slope (unit/s) of a reading's least-squares line, and the reading less the line."""
    t = np.arange(x.size) * dt_s
    slope, intercept = np.polyfit(t, x, 1)
    return float(slope), x - (slope * t + intercept)


def signal_section(
    reading: ReadingRecord | None,
    note: str,
    records: tuple[TrialRecord, ...],
    acceptance: ExcursionCriterion | None,
) -> SignalSection:
    """Section 10 from the stationary record, the stored series and the plan's acceptance."""
    settle = settle_rows(records)
    trend, noise, error = None, None, None
    if reading is not None:
        try:
            trend, noise = _characterise(reading)
        except (AnalysisError, ValueError) as exc:
            error = str(exc)
    unassessed = SignalSection(
        record=reading,
        record_note=note,
        trend_deg_per_h=trend,
        noise=None,
        noise_error=error,
        observations=(),
        settle=settle,
        acceptance=None,
        acceptance_note=NO_ACCEPTANCE if acceptance is None else f"Not assessed: {error or note}",
    )
    if noise is None or reading is None:
        return unassessed
    verdict, acceptance_note = None, NO_ACCEPTANCE
    if acceptance is not None:
        try:
            verdict, acceptance_note = excursion_verdict(noise.smooth, acceptance), RICE_NOTE
        except (AnalysisError, ValueError) as exc:
            acceptance_note = f"Not assessed: {exc}"
    longest_lag_s = float(noise.correlation.lag_s[-1])
    if noise.exponential.correlation_time_s >= longest_lag_s * (1 - 1e-6):  # `fit_correlation`
        note += (
            f" The fitted correlation time is the longest lag estimated ({longest_lag_s:.4g} s): "
            "the record cannot tell a longer one, so the observations may be more correlated "
            "than stated."
        )
    return replace(
        unassessed,
        record_note=note,
        noise=noise,
        observations=observation_correlations(
            noise.exponential, records, reading.dt_s, noise.sampling.max_correlation
        ),
        acceptance=verdict,
        acceptance_note=acceptance_note,
    )
