"""A simulated campaign run with early settle ([settle] method = "estimate", seed 003) produces a
report whose section 10 gives each series' settle point, its standard error and the time saved,
as the series rows and the "early settle" events record them; a campaign that waited for the band
criterion saved nothing."""

import re
from dataclasses import replace

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import Event, Series
from gyrostand.report.build import Report, build_report
from gyrostand.report.compliance import load_profile
from gyrostand.report.html import render_html
from gyrostand.report.json_doc import report_document
from gyrostand.report.model import ExcursionCriterion
from gyrostand.report.signal_text import render_signal_text
from gyrostand.report.writer import write_report

from .conftest import (
    GENERATED,
    SIM_TRIALS,
    Rendered,
    Simulated,
    pdf_text,
    run_simulated,
    watermark_letters,
)

CRITERION = ExcursionCriterion(tolerance_deg=0.03, duration_s=600.0, max_risk=0.01)
EARLY = """[settle]
method = "estimate"
undamped_period_s = 240.0
damping_ratio = 0.8
expected_se_deg = 0.02
tolerance_fraction = 1.0
stable_estimates = 3
"""


def early_plan(text: str) -> str:
    """The simulated compass's transient (quick_config: 240 s, 0.8) as instrument data, and a
    band criterion that would hold the reading for 300 s."""
    text = text.replace("hold_s = 60.0", "hold_s = 300.0")
    return text.replace("[settle]\n", EARLY)


@pytest.fixture(scope="module")
def early(tmp_path_factory: pytest.TempPathFactory) -> Simulated:
    return run_simulated(tmp_path_factory.mktemp("early"), early_plan)


@pytest.fixture(scope="module")
def early_report(early: Simulated) -> Report:
    """The early-settle campaign's report, judged by an [acceptance] table as well."""
    report = early.report()
    inputs = replace(report.inputs, acceptance=CRITERION)
    return build_report(inputs, report.analysis, load_profile(), generated_at=GENERATED)


@pytest.fixture(scope="module")
def early_files(early_report: Report, tmp_path_factory: pytest.TempPathFactory) -> Rendered:
    files = write_report(early_report, tmp_path_factory.mktemp("early-report"), ("html", "pdf"))
    return Rendered(files, pdf_text(files["pdf"]), 0)


def test_every_series_settled_early_as_recorded(early: Simulated, early_report: Report) -> None:
    rows = early_report.signal.settle
    assert len(rows) == 2 * len(SIM_TRIALS)
    with early.sessions() as session:
        series = {s.id: s for s in session.query(Series)}
        events = session.query(Event).filter_by(kind="early settle").all()
        assert len(events) == len(rows)
        by_series = {(series[e.series_id].trial.index, series[e.series_id].j): e for e in events}
        for row in rows:
            message = by_series[(row.trial, row.j)].message
            took = float(re.search(r"after ([\d.]+) s", message)[1])
            band = float(
                re.search(r"band criterion (?:held|predicted) after ([\d.]+) s", message)[1]
            )
            assert row.criterion == "estimate"
            assert row.settle_s == pytest.approx(took, abs=0.05)  # the series row's own times
            assert row.band_s == band and row.saved_s == pytest.approx(band - took, abs=0.05)
            assert row.saved_s > 0  # observing began before a 300 s hold could have ended
            assert f"settle point {row.estimate_deg:.5f} deg" in message
            assert row.standard_error_deg <= 0.02  # within the plan's tolerance
    assert early_report.signal.time_saved_s == pytest.approx(sum(r.saved_s for r in rows))


def test_html_and_json_show_the_saving(early_report: Report, early_files: Rendered) -> None:
    html = early_files.files["html"].read_text()
    section = early_report.signal
    assert f"Stand time saved: {section.time_saved_s:.1f} s" in html
    assert html.count("<td>estimate</td>") == len(section.settle)
    assert section.noise is not None and "<h2>The reading's random part" in html
    doc = report_document(early_report)["signal"]
    assert doc["time_saved_s"] == section.time_saved_s
    assert [r["criterion"] for r in doc["settle"]] == ["estimate"] * len(section.settle)


def test_pdf_shows_the_new_sections(early_report: Report, early_files: Rendered) -> None:
    section = early_report.signal
    for needle in (
        "11. The reading's random part",
        "Correlation function of the reading (eq 8.92)",  # figure captions (the figures are
        "Spectrum of the reading",  # images: their titles are not text)
        "Allan deviation of the reading",
        "Sampling interval and independence",
        f"{section.noise.sampling.interval_s:.3g} s",
        "Settle points",
        f"Stand time saved: {section.time_saved_s:.1f} s",
        "Acceptance by excursions",
        f"{section.acceptance.verdict} P(excursion",
        f"{section.noise.exponential.decay_per_s:.4g}",
        "12. Compliance",
    ):
        assert needle in early_files.pdf_text, needle


def test_waiting_for_the_band_saves_nothing(simulated_report: Report) -> None:
    rows = simulated_report.signal.settle
    assert rows and all(r.criterion == "band" and r.saved_s == 0.0 for r in rows)
    assert all(r.band_s == r.settle_s for r in rows)
    assert simulated_report.signal.time_saved_s == 0.0


def test_imported_series_record_no_criterion(paper_report: Report) -> None:
    assert all(s.settle is None for r in paper_report.inputs.records for s in r.series)


def test_the_time_saved_is_in_the_cli_text(early: Simulated, early_report: Report) -> None:
    result = CliRunner().invoke(
        app, ["analyze", str(early.campaign_id), "--db", early.url, "--signal"]
    )
    assert result.exit_code == 0, result.output
    assert f"stand time saved: {early_report.signal.time_saved_s:.1f} s" in result.stdout


def test_simulation_is_marked_on_every_page(early_files: Rendered) -> None:
    marks = watermark_letters(early_files.files["pdf"])
    # unsigned and unidentified, it is a DRAFT as well
    assert len(marks) > 5 and set(marks) == {"".join(sorted("DRAFTSIMULATION"))}


def test_stand_time_lost_is_said_so(early_report: Report) -> None:
    """Series that settled later than the band criterion would have: time lost, not a
    negative saving."""
    rows = tuple(
        replace(r, saved_s=-abs(r.saved_s or 0.0) - 1.0) for r in early_report.signal.settle
    )
    late = replace(early_report, signal=replace(early_report.signal, settle=rows))
    lost = -late.signal.time_saved_s
    assert lost > 0
    assert f"Stand time lost: {lost:.1f} s" in render_html(late)
    assert f"stand time lost: {lost:.1f} s (later than the band criterion)" in render_signal_text(
        late.signal
    )
