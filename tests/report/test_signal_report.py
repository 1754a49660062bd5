"""Report section 10 of the simulated campaign (tests/report/conftest.py): the stationary record
against the raw log decoded frame by frame with cantools, the observation correlations against
their closed form, settle rows against the database, the section in HTML, PDF and JSON, and
`gyrostand analyze CAMPAIGN --signal`. The PDF is looked at in test_signal_early.py."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from gyrostand.analysis.noise import characterise_noise
from gyrostand.cli import app
from gyrostand.db.models import Series, Trial
from gyrostand.report.build import Report, build_report
from gyrostand.report.compliance import load_profile
from gyrostand.report.html import render_html
from gyrostand.report.json_doc import report_document
from gyrostand.report.model import ExcursionCriterion
from gyrostand.report.text import terminal_notation
from gyrostand.stand.protocol import Codec, HeadingFrame

from .conftest import GENERATED, Rendered, Simulated, Stored

runner = CliRunner()
CRITERION = ExcursionCriterion(tolerance_deg=0.05, duration_s=600.0, max_risk=0.01)


def still_span(report: Report, index: int) -> tuple[int, int]:
    record = next(r for r in report.inputs.records if r.index == index)
    (series,) = [s for s in record.series if s.j == 1]
    return series.observations[0].window_start_ms, series.observations[-1].window_end_ms


def decoded(simulated: Simulated, span: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Valid heading frames in [start, end), decoded one by one by the cantools codec."""
    codec = Codec()
    frames = [
        f
        for f in (codec.decode(m) for m in simulated.stream)
        if isinstance(f, HeadingFrame) and f.valid and span[0] <= f.stand_time_ms < span[1]
    ]
    return np.array([f.stand_time_ms for f in frames]), np.array([f.heading_deg for f in frames])


def test_the_record_is_the_longest_still_series(
    simulated: Simulated, simulated_report: Report
) -> None:
    section = simulated_report.signal
    counts = {
        r.index: decoded(simulated, still_span(simulated_report, r.index))[0].size
        for r in simulated_report.inputs.records
    }
    longest = max(sorted(counts), key=counts.get)
    assert section.record.source.startswith(f"trial {longest}, still series (j = 1)")
    t, heading = decoded(simulated, still_span(simulated_report, longest))
    assert section.record.frames == t.size == section.record.reading_deg.size  # no frame lost
    assert section.record.start_ms == t[0] and section.record.dt_s == 0.1
    assert section.record.reading_deg == pytest.approx(heading, abs=1e-9)  # far from north

    # the characterisation is that of the detrended record, its correlation function pooling
    # the other still series (each less its own line)
    def detrended(index: int) -> np.ndarray:
        t, heading = decoded(simulated, still_span(simulated_report, index))
        return heading - np.polyval(np.polyfit((t - t[0]) / 1000, heading, 1), (t - t[0]) / 1000)

    others = [detrended(i) for i in sorted(counts) if i != longest]
    direct = characterise_noise(detrended(longest), 0.1, trend_degree=1, others=others)
    assert section.noise.correlation.records == (counts[longest], *(x.size for x in others))
    assert "pool the 3 other still series" in section.record_note
    # 120 s still series of a reading whose correlation time is 20 s: at the longest lag, 12 s
    assert section.noise.exponential.correlation_time_s == pytest.approx(12.0)
    assert "correlation time is the longest lag estimated (12 s)" in section.record_note
    assert section.noise.correlation.covariance == pytest.approx(
        direct.correlation.covariance, rel=1e-9
    )
    for fitted in ("exponential", "smooth"):
        got, want = getattr(section.noise, fitted), getattr(direct, fitted)
        assert (got.variance, got.decay_per_s, got.white_variance) == pytest.approx(
            (want.variance, want.decay_per_s, want.white_variance), rel=1e-6
        )
    assert section.noise.allan.deviation == pytest.approx(direct.allan.deviation, rel=1e-9)


def test_observation_correlations_follow_the_closed_form(simulated_report: Report) -> None:
    section = simulated_report.signal
    model = section.noise.exponential
    assert len(section.observations) == 2 * len(simulated_report.inputs.records)
    for o in section.observations:
        periods = next(
            t.cmd_period_s for t in simulated_report.inputs.acquisition if t.index == o.trial
        )
        assert o.window_s == pytest.approx(30.0 if o.j == 1 else 4 * periods, abs=0.05)
        # K = sigma^2 e^(-mu|tau|) averaged over windows W, starts D apart (D >= W)
        x, s2 = model.decay_per_s * o.window_s, model.variance
        variance = 2 * s2 * (x - 1 + math.exp(-x)) / x**2 + model.white_variance * 0.1 / o.window_s
        covariance = s2 * math.exp(-model.decay_per_s * o.step_s) * (2 * math.cosh(x) - 2) / x**2
        assert o.correlation == pytest.approx(covariance / variance, rel=1e-6)
        assert o.correlated == (abs(o.correlation) > 0.1)
        # at lag k the covariance decays by e^(-mu D) per step: the mean's inflation over all lags
        k = np.arange(1, o.n)
        rho = o.correlation * np.exp(-model.decay_per_s * o.step_s * (k - 1))
        assert o.inflation == pytest.approx(1 + 2 * np.sum((1 - k / o.n) * rho), rel=1e-6)
    # and the analysis takes each series' N_eff = N / f for its trial means
    analysed = {t.index: t for t in simulated_report.analysis.trials}
    rows = {r.index: r for r in simulated_report.trials}  # the trial table shows the same N_eff
    for o in section.observations:
        t, row = analysed[o.trial], rows[o.trial]
        assert (t.n_eff_before if o.j == 1 else t.n_eff_under) == pytest.approx(o.n_eff)
        assert (row.n_eff_before if o.j == 1 else row.n_eff_under) == pytest.approx(o.n_eff)
        assert t.var_mean_deg2 > t.paper_var_mean_deg2


def test_settle_rows_are_the_stored_series(simulated: Simulated, simulated_report: Report) -> None:
    with simulated.sessions() as session:
        stored = {
            (t.index, s.j): s
            for t in session.query(Trial).filter_by(campaign_id=simulated.campaign_id)
            for s in session.query(Series).filter_by(trial_id=t.id)
        }
        rows = simulated_report.signal.settle
        assert {(r.trial, r.j) for r in rows} == set(stored)
        for r in rows:
            s = stored[(r.trial, r.j)]
            assert r.settle_s == (s.settle_done_ms - s.settle_started_ms) / 1000
            assert r.estimate_deg == s.settle_estimate_deg
            values = [o.value_deg for o in s.observations]
            assert r.offset_deg == pytest.approx(np.mean(values) - s.settle_estimate_deg)


@pytest.fixture(scope="module")
def with_acceptance(simulated_report: Report) -> Report:
    inputs = replace(simulated_report.inputs, acceptance=CRITERION)
    return build_report(inputs, simulated_report.analysis, load_profile(), generated_at=GENERATED)


def test_html_and_json_carry_the_section(with_acceptance: Report) -> None:
    html = render_html(with_acceptance)
    section = with_acceptance.signal
    for text in (
        "<h2>The reading's random part",
        "Hidden harmonics",
        "Sampling interval and independence",
        "Settle points",
        "Acceptance by excursions",
        "<h2>Compliance",
        "<h2>Signatures",
        f"{section.noise.exponential.decay_per_s:.4g}",
        f"{section.noise.sampling.interval_s:.3g} s",
    ):
        assert text in html, text
    assert html.index("<h2>The reading") < html.index("<h2>Compliance") < html.index("<h2>Signat")
    doc = report_document(with_acceptance)
    assert doc["schema"] == "gyrostand.report/5"
    assert doc["signal"]["acceptance"]["verdict"] == section.acceptance.verdict
    assert doc["signal"]["noise"]["exponential"]["variance"] == section.noise.exponential.variance
    again = build_report(
        with_acceptance.inputs, with_acceptance.analysis, load_profile(), generated_at="later"
    )
    assert report_document(again)["signal"] == doc["signal"]  # deterministic


def test_cli_prints_the_campaign_section(simulated: Simulated, simulated_report: Report) -> None:
    args = ["analyze", str(simulated.campaign_id), "--db", simulated.url, "--signal"]
    text = runner.invoke(app, args)
    assert text.exit_code == 0, text.output
    assert simulated_report.signal.record.source in text.stdout
    assert "SETTLE POINTS" in text.stdout and "stand time saved: 0.0 s" in text.stdout
    result = runner.invoke(app, [*args, "--json"])
    doc = json.loads(result.stdout)
    assert doc.pop("schema") == "gyrostand.signal/2"
    assert doc == report_document(simulated_report)["signal"]


def test_cli_errors_for_a_campaign(paper: Stored, simulated: Simulated) -> None:
    cases = [
        (["analyze", "99", "--db", simulated.url, "--signal"], "campaign 99"),
        (["analyze", str(paper.campaign_id), "--db", paper.url, "--signal"], "imported"),
    ]
    for args, message in cases:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, result.output
        (line,) = result.stderr.strip().splitlines()
        assert line.startswith("gyrostand: error: ") and message in line


def test_an_imported_campaign_has_no_record(paper_report: Report, paper_files: Rendered) -> None:
    section = paper_report.signal
    assert section.record is None and section.noise is None and section.settle == ()
    html = paper_files.files["html"].read_text()
    assert "Noise not characterised" in html and "Settle points: not recorded" in html


def test_one_independence_verdict_everywhere(
    simulated: Simulated, simulated_report: Report, paper: Stored
) -> None:
    """The question "are successive observations independent?" has one test: the reading's
    correlation function when the campaign has a record; the analysis, its warnings, `analyze`
    and the report's glance box all carry that verdict."""
    section = simulated_report.signal
    correlated = [o for o in section.observations if abs(o.correlation) > 0.1]
    (check,) = [c for c in simulated_report.analysis.assumptions if c.name == "independence"]
    assert check.holds is (not correlated)
    assert "correlation function" in check.method
    assert check.detail.startswith(f"{len(correlated)} of {len(section.observations)} series")
    largest = max(section.observations, key=lambda o: abs(o.correlation))
    assert check.statistic == largest.correlation
    warned = [w for w in simulated_report.analysis.warnings if "independence" in w]
    expected = f"assumption of independence violated: {check.detail}"
    assert warned == ([expected] if correlated else [])
    text = runner.invoke(app, ["analyze", str(simulated.campaign_id), "--db", simulated.url])
    assert terminal_notation(f"independence: {check.verdict} ({check.method}") in text.stdout
    html = render_html(simulated_report)
    badge = '<span class="badge fail">NO</span>' if correlated else "badge pass"
    assert f"observations independent: {badge}" in html
    # without a record (the paper's imported table) the N observations themselves are tested
    (imported,) = [c for c in paper.report().analysis.assumptions if c.name == "independence"]
    assert imported.method.startswith("lag-1 autocorrelation (Ljung-Box Q)")
