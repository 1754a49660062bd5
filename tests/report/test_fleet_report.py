"""The fleet report (report/fleet.py, fleet.html.j2, fleet_plots.py) of a fleet given as numbers:
three factories, factory B's C 20 % larger, one unit of A with an odd T. Its figures against
scipy's one-way analysis of variance and the analysis it renders; the shifted factory is the one
flagged; the JSON document; the PDF's text (one render per module)."""

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from gyrostand.analysis.fleet import FleetUnit, analyze_fleet
from gyrostand.report.errors import ReportError
from gyrostand.report.fleet import (
    SCHEMA,
    FleetInputs,
    FleetReport,
    LeftOut,
    Programme,
    ProgrammeTrial,
    fleet_json,
    render_fleet_html,
    write_fleet_report,
)
from gyrostand.report.html import sci

from .conftest import pdf_text as read_pdf

C_1E7 = {
    "A": [6.00, 6.10, 5.90, 6.05],
    "B": [7.20, 7.30, 7.10, 7.25],
    "C": [6.00, 5.95, 6.10, 6.02],
}
T_S = {
    "A": [1.10, 1.12, 1.08, 1.40],  # outside the type's prediction interval
    "B": [1.11, 1.09, 1.10, 1.12],
    "C": [1.09, 1.11, 1.10, 1.08],
}


def units() -> tuple[FleetUnit, ...]:
    made = []
    for group in C_1E7:
        for i, (c, t) in enumerate(zip(C_1E7[group], T_S[group], strict=True), start=1):
            made.append(
                FleetUnit(
                    campaign_id=len(made) + 1,
                    serial=f"{group}-{i:03d}",
                    group=group,
                    c_gcm2s2=c * 1e7,
                    c_se=0.1e7,
                    t_s=t,
                    t_se=0.02,
                    when=f"2026-03-{len(made) + 1:02d}T09:00:00+00:00",
                )
            )
    return tuple(made)


PROGRAMME = Programme(
    (ProgrammeTrial("fit", 332.0, 24.0, 8.0), ProgrammeTrial("control", 31.0, 23.5, 6.2)),
    5,
    "windows of 30 s still and 4 rocking periods; settle criterion: estimate",
    tuple(range(1, 13)),
)


@pytest.fixture(scope="module")
def report() -> FleetReport:
    fleet = units()
    inputs = FleetInputs(
        "test compass",
        "factory",
        fleet,
        (LeftOut(13, "A-001", "a later campaign of serial A-001 counts (1)"),),
        programmes=(PROGRAMME,),
    )
    return FleetReport(
        inputs=inputs,
        analysis=analyze_fleet(fleet, factor="factory"),
        generated_at="2026-03-20 12:00:00+00:00",
        database="sqlite:///lab.sqlite",
        software="gyrostand test",
        simulated=tuple(u.campaign_id for u in fleet),
        marked_draft=True,
    )


@pytest.fixture(scope="module")
def html(report: FleetReport) -> str:
    return render_fleet_html(report)


@pytest.fixture(scope="module")
def pdf_text(report: FleetReport, tmp_path_factory: pytest.TempPathFactory) -> str:
    return read_pdf(write_fleet_report(report, tmp_path_factory.mktemp("fleet") / "fleet.pdf"))


def test_the_anova_figures_are_scipys(report: FleetReport, html: str) -> None:
    for p, by_group in zip(report.analysis.parameters, (C_1E7, T_S), strict=True):
        groups = [np.array(v) for v in by_group.values()]
        expected = stats.f_oneway(*groups)
        a = p.anova
        assert a.f == pytest.approx(expected.statistic, rel=1e-9)
        assert a.p_value == pytest.approx(expected.pvalue, rel=1e-6)
        assert a.f_critical == pytest.approx(stats.f.ppf(0.95, 2, 9))
        assert (a.dof_between, a.dof_within) == (2, 9)
        row = f'<td class="n" rowspan="2">{a.f:.3g}</td><td class="n" rowspan="2">'
        assert row + f"{a.f_critical:.3g}</td>" in html
        if p.symbol == "C":  # the sums of squares in g·cm²·s⁻² squared, printed as x·10^k
            scale = 1e14  # (1e7)²
            q_within = sum(((g - g.mean()) ** 2).sum() for g in groups) * scale
            assert a.q_within == pytest.approx(q_within)
            assert str(sci(a.q_within, 3)) in html and str(sci(a.q_between, 3)) in html


def test_only_the_shifted_factory_is_flagged(report: FleetReport, html: str) -> None:
    c, t = report.analysis.parameters
    assert [g.group for g in c.groups if g.differs] == ["B"]
    assert not t.anova.groups_differ and not any(g.differs for g in t.groups)
    assert html.count("set apart: <b>factory B</b>") == 1
    assert html.count("set apart: <b>") == 1
    flagged = re.findall(r"<tr><td>(\w)</td>(?:(?!</tr>).)*badge fail\">differs<", html)
    assert flagged == ["B"]
    assert 'badge fail">the groups differ<' in html and 'badge pass">no difference<' in html


def test_the_odd_unit_and_the_identification(report: FleetReport, html: str) -> None:
    c, t = report.analysis.parameters
    assert not c.outliers and [u.serial for u in t.outliers] == ["A-004"]
    outside = html.split("Units outside the type's prediction interval: T")[1].split("</table>")[0]
    assert "<tr><td>A-004</td><td>A</td>" in outside
    assert "C: every unit lies within the type's prediction interval" in html
    assert "SIMULATION: the instruments and the stand were simulated" in html
    assert 'class="watermark" aria-hidden="true">DRAFT<br>SIMULATION<' in html
    assert "a later campaign of serial A-001 counts (1)" in html
    assert "1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12: each unit" in html
    assert html.count('<img src="data:image/svg+xml;base64,') == 2  # the control charts of C, T
    assert "Sveshnikov" in html and ".py" not in html


def test_json_is_the_analysis_with_units_and_what_was_left_out(report: FleetReport) -> None:
    document = json.loads(fleet_json(report))
    assert document["schema"] == SCHEMA == "gyrostand.fleet-report/1"
    assert document["model"] == "test compass" and document["factor"] == "factory"
    assert document["draft"] is True and document["simulated_campaigns"] == list(range(1, 13))
    assert document["parameters"] == json.loads(json.dumps(report.analysis.to_dict()))["parameters"]
    assert [u["serial"] for u in document["units"]] == [u.serial for u in units()]
    assert document["units"][4]["c_gcm2s2"] == pytest.approx(7.2e7)
    assert document["left_out"] == [
        {
            "campaign_id": 13,
            "serial": "A-001",
            "reason": "a later campaign of serial A-001 counts (1)",
        }
    ]
    c = document["parameters"][0]
    assert c["anova"]["f"] == pytest.approx(stats.f_oneway(*C_1E7.values()).statistic)
    assert [g["group"] for g in c["groups"] if g["differs"]] == ["B"]


def test_pdf_has_the_sections_and_key_figures(report: FleetReport, pdf_text: str) -> None:
    c, t = report.analysis.parameters
    for needle in (
        "Fleet report (unnumbered): test compass, units grouped by factory",
        "DRAFT: not for issue; it lacks report number, laboratory",
        "Table 1. The test programme: campaigns 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12; N = 5",
        "8. Signatures",
        "Approved by",
        "End of report (unnumbered: a DRAFT)",
        "SIMULATION: the instruments and the stand were simulated",
        "DRAFT",
        "1. Identification",
        "2. Method and references",
        "3. Analysis of variance",
        "4. Smirnov's tests",
        "5. Units against the type's prediction interval",
        "6. Control charts",
        "7. The units",
        "Figure 1. Control chart of C",
        "Figure 2. Control chart of T",
        f"F = {c.anova.f:.3g} > F* = {c.anova.f_critical:.3g}",
        f"F = {t.anova.f:.3g} ≤ F* = {t.anova.f_critical:.3g}",
        "set apart: factory B",
        "A-004 (A)",
        "Sveshnikov A. A.",
    ):
        assert needle in " ".join(pdf_text.split()), needle  # lines joined: a title wraps


def test_the_type_sd_with_its_interval(report: FleetReport, html: str) -> None:
    """The type's SD of T (3 groups of 4, SEs 0.02 s): the split and its chi-square interval
    computed here from the units' numbers."""
    t = report.analysis.parameters[1]
    within = sum(((np.array(v) - np.mean(v)) ** 2).sum() for v in T_S.values()) / 9
    share = 0.02**2  # equal groups, equal SEs: the mean SE²
    assert t.anova.s2_type == pytest.approx(within - share)
    dof = t.anova.s2_type_dof
    assert dof == pytest.approx(9)  # equal groups, equal precision: Satterthwaite's ν' = N - k
    low = 9 * within / stats.chi2.ppf(0.975, 9) - share
    high = 9 * within / stats.chi2.ppf(0.025, 9) - share
    assert t.anova.s2_type_interval == pytest.approx((max(0.0, low), high))
    sd = f"{(within - share) ** 0.5:.4g} ({max(0.0, low) ** 0.5:.4g} to {high**0.5:.4g}) s"
    assert sd in html


def test_an_identified_report_is_no_draft(report: FleetReport) -> None:
    issued = replace(report, marked_draft=False, number="FL-7", laboratory="Stand lab")
    assert issued.missing == () and not issued.draft
    assert issued.title == "Fleet report FL-7: test compass, by factory"
    document = json.loads(fleet_json(issued))
    assert (document["draft"], document["missing"], document["number"]) == (False, [], "FL-7")
    assert document["programmes"][0]["n_obs"] == 5
    assert replace(issued, laboratory=None).missing == ("laboratory",)
    html = render_fleet_html(issued)
    assert "<title>Fleet report FL-7: test compass, by factory</title>" in html
    assert "DRAFT" not in html.split("<body>")[1].split('<section id="method">')[0]


def test_a_suffix_that_names_no_format_and_an_unwritable_file(
    report: FleetReport, tmp_path: Path
) -> None:
    with pytest.raises(ReportError, match=r"fleet\.txt: the suffix names no fleet report format"):
        write_fleet_report(report, tmp_path / "fleet.txt")
    (tmp_path / "file").write_text("")
    with pytest.raises(ReportError, match="cannot write .*file/fleet.json: .*file is a file"):
        write_fleet_report(report, tmp_path / "file" / "fleet.json")


def test_smirnov_not_rejecting_for_a_group_set_apart_is_inconclusive(report: FleetReport) -> None:
    """Factory B's C is set apart by the analysis of variance; had Smirnov's test (4 units
    against 8) not reached its level, it would be inconclusive, not "no difference"."""
    c = report.analysis.parameters[0]
    b = next(s for s in c.smirnov if s.group == "B")
    assert b.differs and c.smirnov_verdict(b) == "differs from the rest"
    weak = replace(b, p_value=0.085, differs=False)
    c_weak = replace(c, smirnov=tuple(weak if s is b else s for s in c.smirnov))
    assert c_weak.smirnov_verdict(weak) == "inconclusive: the analysis of variance sets it apart"
    others = [s for s in c.smirnov if s.group != "B"]
    assert [c.smirnov_verdict(s) for s in others] == ["no difference found"] * 2
    analysis = replace(report.analysis, parameters=(c_weak, *report.analysis.parameters[1:]))
    html = render_fleet_html(replace(report, analysis=analysis))
    assert "<td>inconclusive: the analysis of variance sets it apart</td>" in html
