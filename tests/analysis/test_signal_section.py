"""Report section 10 as pure computation (report.signal): the uniform record, the
correlation of successive window means against its closed form, settle rows, the excursion
verdict against Rice's closed form (Sveshnikov eq 8.88) and its method, and what is left
unassessed."""

import math

import numpy as np
import pytest

from gyrostand.analysis.effective import window_mean_correlation
from gyrostand.analysis.noise import CorrelationModel
from gyrostand.report.compliance import FAIL, PASS
from gyrostand.report.model import (
    ExcursionCriterion,
    ObservationRecord,
    ReadingRecord,
    SeriesRecord,
    TrialRecord,
)
from gyrostand.report.signal import (
    MIN_READINGS,
    excursion_verdict,
    observation_correlations,
    settle_rows,
    signal_section,
    uniform_record,
)


def test_uniform_record_fills_gaps_and_stays_continuous_across_north() -> None:
    t = np.arange(0, 2000, 100.0)
    heading = (359.95 + 0.01 * np.arange(t.size)) % 360.0  # crosses 0/360 deg
    keep = np.ones(t.size, bool)
    keep[[5, 6, 12]] = False  # three frames lost
    record = uniform_record(t[keep], heading[keep], "test")
    assert record.dt_s == 0.1 and record.start_ms == 0.0
    assert record.frames == t.size - 3 and record.filled == 3
    assert record.reading_deg == pytest.approx(359.95 + 0.01 * np.arange(t.size), abs=1e-9)
    assert record.duration_s == pytest.approx(1.9)


def exponential_window_correlation(
    sigma2: float, mu: float, white: float, window: float, step: float, dt: float
) -> float:
    """Closed form for K = sigma^2 e^(-mu|tau|), windows not overlapping (step >= window)."""
    x = mu * window
    variance = 2 * sigma2 * (x - 1 + math.exp(-x)) / x**2 + white * dt / window
    covariance = sigma2 * math.exp(-mu * step) * (2 * math.cosh(x) - 2) / x**2
    return covariance / variance


@pytest.mark.parametrize(("mu", "window", "step"), [(0.05, 60, 60), (0.2, 24, 30), (0.01, 30, 90)])
def test_window_mean_correlation_matches_the_closed_form(mu: float, window: float, step: float):
    model = CorrelationModel(1e-4, mu, white_variance=3e-5)
    expected = exponential_window_correlation(1e-4, mu, 3e-5, window, step, 0.1)
    assert window_mean_correlation(model, window, step, 0.1) == pytest.approx(expected, rel=1e-7)


def series(
    j: int, windows_ms: list[tuple[int, int]], values: list[float], **settle
) -> SeriesRecord:
    observations = tuple(
        ObservationRecord(k, v, a, b)
        for k, ((a, b), v) in enumerate(zip(windows_ms, values, strict=True), start=1)
    )
    defaults = {"settle_started_ms": None, "settle_done_ms": None, "settle_estimate_deg": None}
    return SeriesRecord(j=j, observations=observations, **{**defaults, **settle})


RECORDS = (
    TrialRecord(
        1,
        (
            series(
                1,
                [(60_000, 120_000), (120_000, 180_000), (180_000, 240_000)],
                [120.01, 120.03, 120.02],
                settle_started_ms=0,
                settle_done_ms=60_000,
                settle_estimate_deg=120.0,
            ),
            series(2, [(300_000, 324_000), (330_000, 354_000)], [120.5, 120.7]),
        ),
        None,
    ),
    TrialRecord(2, (series(1, [(None, None)], [1.0]),), None),  # imported, untimed: no rows
)


def test_observation_correlations_per_timed_series() -> None:
    model = CorrelationModel(1e-4, 0.05, white_variance=2e-5)
    rows = observation_correlations(model, RECORDS, 0.1, 0.1)
    assert [(r.trial, r.j, r.window_s, r.step_s) for r in rows] == [(1, 1, 60, 60), (1, 2, 24, 30)]
    first = exponential_window_correlation(1e-4, 0.05, 2e-5, 60, 60, 0.1)
    assert rows[0].correlation == pytest.approx(first, rel=1e-7)
    assert rows[0].correlated == (first > 0.1)
    assert rows[1].correlation > rows[0].correlation  # shorter windows closer together


def test_settle_rows_from_the_stored_series() -> None:
    (row,) = settle_rows(RECORDS)  # only trial 1 j = 1 stored a settle
    assert (row.trial, row.j, row.settle_s, row.estimate_deg) == (1, 1, 60.0, 120.0)
    assert row.observed_mean_deg == pytest.approx(120.02)
    assert row.offset_deg == pytest.approx(0.02)


SMOOTH = CorrelationModel(4e-5, 0.3, 0.5)


def rice_mid_band(model: CorrelationModel, eps: float, duration: float) -> float:
    """Seed 004 eq 8.88 written out: n = T sigma_v / (pi sigma) e^(-eps^2 / (2 sigma^2))."""
    sigma = math.sqrt(model.variance)
    sigma_v = math.sqrt(model.variance * (model.decay_per_s**2 + model.frequency_rad_s**2))
    return duration * sigma_v / (math.pi * sigma) * math.exp(-(eps**2) / (2 * sigma**2))


def test_excursion_verdict_against_rice_and_its_inverse() -> None:
    criterion = ExcursionCriterion(tolerance_deg=0.025, duration_s=600.0, max_risk=0.05)
    verdict = excursion_verdict(SMOOTH, criterion)
    e = verdict.excursions
    n = rice_mid_band(SMOOTH, 0.025, 600.0)
    assert e.rice.mean_excursions == pytest.approx(n, rel=1e-12)
    # q = 0.63, n = 0.046, bounds 4 sigma out: the Poisson law (8.84) with a start inside
    assert (e.method, e.is_bound) == ("poisson", False)
    inside = math.erf(0.025 / math.sqrt(2 * SMOOTH.variance))
    assert verdict.risk == pytest.approx(1 - inside * math.exp(-n), rel=1e-12)
    assert verdict.verdict == (PASS if verdict.risk <= 0.05 else FAIL)
    assert verdict.detail.startswith(f"P(excursion in 600 s) = {verdict.risk:.3g} ")
    assert "Poisson law with P(start inside)" in verdict.detail
    eps = verdict.tolerance_for_max_risk_deg
    n_eps = rice_mid_band(SMOOTH, eps, 600.0)
    inside_eps = math.erf(eps / math.sqrt(2 * SMOOTH.variance))
    assert 1 - inside_eps * math.exp(-n_eps) == pytest.approx(0.05, rel=1e-8)
    # a band narrower than that tolerance fails, a wider one passes
    assert excursion_verdict(SMOOTH, ExcursionCriterion(0.99 * eps, 600, 0.05)).verdict == FAIL
    assert excursion_verdict(SMOOTH, ExcursionCriterion(1.01 * eps, 600, 0.05)).verdict == PASS


@pytest.mark.parametrize(
    ("tolerance", "method", "alpha"),
    [
        (0.001, "rice", "P(none) >= 0 (lower bound: P(start inside) minus Rice's"),
        (0.014, "poisson", "(lower bound: P(start inside) e^(-n), below every simulated"),
    ],
)
def test_outside_the_checked_region_the_verdict_rests_on_a_bound(
    tolerance: float, method: str, alpha: str
) -> None:
    """A lightly damped reading (q = 0.27) and a band 0.16 or 2.2 sigma wide: the risk is only an
    upper bound, so the FAIL says that it is not shown to be within the allowed one."""
    ringing = CorrelationModel(4e-5, 0.05, 0.8)
    verdict = excursion_verdict(ringing, ExcursionCriterion(tolerance, 600.0, 0.05))
    e = verdict.excursions
    assert (e.method, e.is_bound, verdict.verdict) == (method, True, FAIL)
    assert verdict.risk == pytest.approx(1 - e.p_no_excursion)
    assert "not shown to be within the allowed 0.05" in verdict.detail
    assert alpha in verdict.detail and "not checked against simulation here" in verdict.detail


def test_a_short_record_is_not_characterised_and_nothing_depends_on_it() -> None:
    reading = ReadingRecord("short", 0.0, 0.1, np.zeros(MIN_READINGS - 1), MIN_READINGS - 1, 0)
    section = signal_section(reading, "note", RECORDS, ExcursionCriterion(0.1, 60, 0.1))
    assert section.noise is None and "too short" in section.noise_error
    assert section.observations == () and section.acceptance is None
    assert section.acceptance_note.startswith("Not assessed: ")
    assert section.reading_interval_ok is None and section.correlated_observations is None
    assert len(section.settle) == 1
    assert section.to_dict()["noise"] is None
