"""Compliance profiles: the shipped IMO A.424(XI) profile, its verdicts on the paper example
against an independent selection of the evidence, and bad profiles."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gyrostand.analysis.campaign import analyze_campaign
from gyrostand.analysis.csv_input import read_trials_csv
from gyrostand.report.build import Report, forecast_section
from gyrostand.report.compliance import (
    EVIDENCE,
    FAIL,
    NOT_ASSESSED,
    PASS,
    assess,
    load_profile,
)
from gyrostand.report.errors import ReportError
from gyrostand.report.settings import SEED_000_SETTINGS

from .conftest import PAPER_CSV

PROFILE = (Path(__file__).resolve().parents[2] / "report/profiles/imo-a424.toml").read_text()


def item(report_or_items: object, evidence: str) -> object:
    items = getattr(report_or_items, "items", report_or_items)
    return next(i for i in items if i.evidence == evidence)


def test_shipped_profile_states_its_source_and_clauses() -> None:
    profile = load_profile()
    assert profile.id == "imo-a424" and "A.424(XI)" in profile.source
    assert profile.envelope.period_s == (6.0, 15.0)
    assert all(r.clause.startswith("A.424(XI) Annex 4.") for r in profile.requirements)
    assert {r.evidence for r in profile.requirements} == set(EVIDENCE)
    assert load_profile(Path(__file__).parents[2] / "report/profiles/imo-a424.toml")


def test_paper_verdicts(paper_report: Report) -> None:
    c = paper_report.compliance
    # evidence the campaign cannot give
    for evidence in ("settle_point_error", "settling_time", "heading_rms", "speed_course_errors"):
        assert item(c, evidence).verdict == NOT_ASSESSED
    # stand: trials with 6 <= tau <= 15 s and A p^2 <= 1 m/s^2 are 1, 2 and 5 (tau 8, 6.3, 6.2)
    stand = item(c, "rolling_error_stand")
    inside = [
        t
        for t in paper_report.trials
        if 6 <= t.period_s <= 15 and t.amplitude_cm * (2 * math.pi / t.period_s) ** 2 <= 100
    ]
    assert [t.index for t in inside] == [1, 2, 5]
    assert stand.value_deg == max(abs(t.delta_deg) for t in inside) == 0.32
    assert stand.limit_deg == pytest.approx(1 / math.cos(math.radians(46.5)))
    assert stand.verdict == PASS
    # forecast: the largest |alpha| + half-width over the grid points in the envelope
    f = paper_report.forecast
    best = max(
        abs(f.grid.alpha_deg[c, 0, p, 0]) + f.grid.half_width_deg[c, 0, p, 0]
        for c in range(f.grid.course_deg.size)
        for p, period in enumerate(f.grid.period_s)
        if 6 <= period <= 15
    )
    forecast = item(c, "rolling_error_forecast")
    assert forecast.value_deg == pytest.approx(best, rel=1e-12)
    assert forecast.limit_deg == pytest.approx(1 / math.cos(math.radians(57.0)))
    assert forecast.verdict == FAIL  # the 1982 compass errs by 2.3 deg and more at 57 deg


def paper_analysis(latitude_deg: float = 46.5):
    s = SEED_000_SETTINGS
    constants = replace(s.constants, latitude_deg=latitude_deg)
    return analyze_campaign(
        read_trials_csv(PAPER_CSV), constants, q=s.q, start=s.start, forecast=s.forecast
    )


def test_limits_beyond_the_standards_latitude_are_not_assessed() -> None:
    analysis = paper_analysis(latitude_deg=65.0)
    c = assess(load_profile(), analysis, None)
    stand = item(c, "rolling_error_stand")
    assert stand.verdict == NOT_ASSESSED and "beyond" in stand.detail
    assert item(c, "rolling_error_forecast").verdict == NOT_ASSESSED  # no grid given


def test_a_custom_profile_file(tmp_path: Path) -> None:
    strict = tmp_path / "strict.toml"
    strict.write_text(
        PROFILE.replace('id = "imo-a424"', 'id = "strict"').replace(
            "limit_deg = 1.0", "limit_deg = 0.2"
        )
    )
    profile = load_profile(strict)
    analysis = paper_analysis()
    c = assess(profile, analysis, forecast_section(analysis, (6.0,)).grid)
    stand = item(c, "rolling_error_stand")
    assert c.profile_id == "strict" and stand.verdict == FAIL
    assert stand.limit_deg == pytest.approx(0.2 / np.cos(np.radians(46.5)))


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (('evidence = "heading_rms"', 'evidence = "astrology"'), "unknown evidence 'astrology'"),
        (("limit_deg = 0.25\n", ""), "needs limit_deg"),
        (("period_s = [6.0, 15.0]", "period_s = [15.0, 6.0]"), "period_s must be"),
        (("[profile]", "[profile"), "not valid TOML"),
    ],
)
def test_bad_profiles_are_refused(tmp_path: Path, edit: tuple[str, str], message: str) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(PROFILE.replace(*edit, 1))
    with pytest.raises(ReportError, match=message):
        load_profile(bad)
    with pytest.raises(ReportError, match="no compliance profile named"):
        load_profile("no-such-profile")
