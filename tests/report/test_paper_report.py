"""The report of the seed-000 paper example imported from examples/paper.csv: its numbers against
the analysis issue's reference values, the rendered PDF, escaping, determinism, the CSV."""

import csv
import io
import json
import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from sqlalchemy import func, select

from gyrostand.db.models import AnalysisRun
from gyrostand.report.build import Report
from gyrostand.report.errors import ReportError
from gyrostand.report.html import _contents, notation
from gyrostand.report.json_doc import report_json
from gyrostand.report.writer import write_report

from .conftest import (
    GENERATED,
    OPERATOR,
    PAPER_CSV,
    Rendered,
    Stored,
    pdf_text,
    watermark_letters,
)

# seed 000 example, as the analysis issue states them
REFERENCE = {"g_ex": 0.4936, "g_star": 0.5175, "C": 5.94e7, "T": 1.151, "F_p": 1.41}


def test_numbers_are_the_papers(paper_report: Report) -> None:
    a = paper_report.analysis
    assert a.cochran.g_ex == pytest.approx(REFERENCE["g_ex"], abs=1e-4)
    assert a.cochran.g_critical == pytest.approx(REFERENCE["g_star"], abs=1e-4)
    assert a.fit.estimates["C_gcm2s2"] == pytest.approx(REFERENCE["C"], rel=2e-3)
    assert a.fit.estimates["T_s"] == pytest.approx(REFERENCE["T"], abs=1e-3)
    assert a.adequacy.f_p == pytest.approx(REFERENCE["F_p"], abs=5e-3)
    point = paper_report.forecast.point
    assert point.alpha_deg == pytest.approx(-2.33, abs=5e-3)
    assert point.half_width_deg == pytest.approx(0.53, abs=5e-3)


def test_trial_table_is_the_paper_table_with_model_values(paper_report: Report) -> None:
    with PAPER_CSV.open() as f:
        paper = list(csv.DictReader(line for line in f if not line.startswith("#")))
    rows = paper_report.trials
    assert [r.index for r in rows] == [int(p["trial"]) for p in paper]
    for row, p in zip(rows, paper, strict=True):
        assert row.delta_deg == float(p["delta_mean_deg"])
        assert row.period_s == float(p["period_s"])
        assert row.p_rad_s == pytest.approx(2 * math.pi / float(p["period_s"]))
        assert row.residual_deg == pytest.approx(row.delta_deg - row.alpha_deg, abs=1e-12)
    controls = {r.index: r.alpha_deg for r in rows if r.role == "control"}
    assert controls == pytest.approx({5: 0.302, 6: -0.129}, abs=2e-3)  # issue: +0.302, -0.129


def test_pdf_has_every_section_and_the_key_numbers(
    paper_files: Rendered, paper_report: Report
) -> None:
    text = paper_files.pdf_text
    assert 5 <= paper_files.pdf_pages <= 12
    headings = (
        "1. Identification",
        "2. Method and references",
        "3. The plan",
        "4. Acquisition summary",
        "5. Trial table",
        "6. Reproducibility",
        "7. Fit of model 1.1",
        "8. Adequacy",
        "9. Control trials",
        "10. Forecast at sea",
        "11. The reading's random part",
        "12. Compliance",
        "13. Signatures",
        "Appendix A: every observation",
        "Appendix B: the plan as submitted",
    )
    body = text[text.index(headings[-1]) + 1 :]  # after the table of contents
    assert [h for h in headings if h not in body] == []
    positions = [body.index(h) for h in headings]
    assert positions == sorted(positions)
    raw = pdf_text(paper_files.files["pdf"], "-raw")  # in reading order: the watermark's glyphs
    contents = raw[raw.index("Contents") : raw.index(headings[-1]) + len(headings[-1]) + 400]
    for n, (_, title) in enumerate(_contents(paper_report), 1):  # each with its page
        number = f"{n}. " if n <= 13 else ""
        assert re.search(re.escape(number + title) + r"[ .]*\d+", contents), title
    for number in ("0.4936", "0.5175", "1.409", "-2.328", "0.534", "3.634"):
        assert number in text, number
    assert re.search(r"5\.941\d\s*×\s*10\s*7", text)  # C, superscript exponent
    assert "1.1509" in text  # T


def test_operator_text_is_inert(paper_files: Rendered) -> None:
    html = paper_files.files["html"].read_text()
    assert "<script" not in html.lower()
    assert "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; I. Ivanov" in html
    assert OPERATOR in paper_files.pdf_text  # shown as text, not run


def test_html_is_self_contained(paper_files: Rendered) -> None:
    html = paper_files.files["html"].read_text()
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:|//|file:)""", html)
    assert html.count('<img src="data:image/svg+xml;base64,') >= 4  # measured vs model, residuals,
    # iterations, forecast
    assert "@page" in html


def test_json_is_deterministic_and_the_run_is_recorded_once(paper: Stored) -> None:
    first = json.loads(report_json(paper.report()))
    second = json.loads(report_json(paper.report("2030-06-30 12:00:00+00:00")))
    assert first["generated_at"] == GENERATED
    del first["generated_at"], second["generated_at"]
    assert first == second
    assert report_json(paper.report()) == report_json(paper.report())
    with paper.sessions() as session:
        runs = session.scalar(
            select(func.count(AnalysisRun.id)).where(AnalysisRun.campaign_id == paper.campaign_id)
        )
    assert runs == 1
    assert first["schema"] == "gyrostand.report/5"
    assert first["analysis"]["cochran"]["g_ex"] == pytest.approx(REFERENCE["g_ex"], abs=1e-4)
    assert first["identification"]["analysis_run"] >= 1


def test_json_grid_holds_the_forecast(paper_report: Report) -> None:
    doc = json.loads(report_json(paper_report))
    grid = doc["forecast"]["grid"]
    course = grid["course_deg"].index(45.0)
    period = grid["period_s"].index(7.0)
    # the plan's A = 65 cm is kept in the grid, so the grid reproduces the point forecast
    assert grid["alpha_deg"][course][0][period][0] == pytest.approx(
        doc["forecast"]["point"]["alpha_deg"], rel=1e-12
    )
    assert len(grid["course_deg"]) == 73 and grid["course_deg"][-1] == 360.0


def test_csv_has_every_trial(paper_files: Rendered, paper_report: Report) -> None:
    rows = list(csv.DictReader(io.StringIO(paper_files.files["csv"].read_text())))
    assert [int(r["index"]) for r in rows] == [t.index for t in paper_report.trials]
    assert rows[0]["var_deg2"] and rows[4]["var_deg2"] == ""  # control: no variance printed
    assert [float(r["alpha_deg"]) for r in rows] == [t.alpha_deg for t in paper_report.trials]


def test_missing_pdf_engine_is_one_clear_error(
    paper_report: Report, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "typst", None)  # import typst -> ImportError
    with pytest.raises(ReportError, match=r"gyrostand\[pdf\].*written: .*campaign-1\.html"):
        write_report(paper_report, tmp_path, ("html", "pdf"))
    assert (tmp_path / "campaign-1.html").exists() and not (tmp_path / "campaign-1.pdf").exists()


def test_one_statement_of_conformity(paper_report: Report, paper_files: Rendered) -> None:
    """The profile's decision, qualified: a PASS rests on the whole campaign and its checks;
    the decision word appears once, with the decision rule."""
    from dataclasses import replace

    from gyrostand.analysis.campaign import LeftOutTrial
    from gyrostand.report.build import conformity
    from gyrostand.report.compliance import DECISION_RULES, FAIL, INCONCLUSIVE, PASS

    c, a = paper_report.compliance, paper_report.analysis
    stated = paper_report.conformity
    assert stated.verdict == c.decision == INCONCLUSIVE  # the limits are not verified by a lab
    assert stated.statement.startswith(f"against {c.profile_name}: {c.summary}")
    assert stated.decision_rule == DECISION_RULES["guarded"]
    # the paper's campaign: Fisher's test on the trial means rejects the model (F_p 7.05 > 3.63)
    assert stated.reasons == ("the model is not adequate (Fisher, on the trial means)",)
    page_1 = paper_files.pdf_text.split("Results at a glance")[0]
    assert "Statement of conformity." in page_1 and "Decision rule: guarded acceptance" in page_1
    assert re.sub(r"\s+", " ", page_1).count("INCONCLUSIVE") == 1
    document = json.loads(paper_files.files["json"].read_text())
    assert INCONCLUSIVE not in document["compliance"]["summary"]
    assert INCONCLUSIVE not in document["conformity"]["statement"]
    passed = replace(c, items=tuple(replace(i, verdict=PASS) for i in c.items))
    assert conformity(passed, a, None, False, 6).verdict == INCONCLUSIVE  # not adequate
    a = replace(a, adequacy=replace(a.adequacy, adequate_mean_basis=True))  # were it adequate
    assert conformity(passed, a, None, False, 6).verdict == PASS
    simulated = conformity(passed, a, None, True, 6)
    assert simulated.verdict == INCONCLUSIVE
    assert simulated.reasons == ("the instrument and the stand were simulated",)
    dropped = replace(a, left_out=(LeftOutTrial(7, 1, "fit", "failed", "trial failed: x"),))
    missing = conformity(passed, dropped, None, False, 7)
    assert missing.verdict == INCONCLUSIVE
    assert missing.reasons == (f"{len(a.trials)} of 7 planned trials analysed (trial 7 not)",)
    unequal = replace(a, cochran=replace(a.cochran, homogeneous=False))
    assert conformity(passed, unequal, None, False, 6).reasons == (
        "the trial variances are not homogeneous (Cochran)",
    )
    failed = replace(c, items=(replace(c.items[0], verdict=FAIL, verified=True),))
    assert conformity(failed, unequal, None, True, 6).verdict == FAIL  # a verified FAIL stands
    not_analysed = conformity(passed, None, "every trial failed", False, 6)
    assert (not_analysed.verdict, not_analysed.statement) == (
        "NOT ASSESSED",
        "the campaign could not be analysed (every trial failed).",
    )


def test_pdf_is_archival_pdf_a_3a(paper_files: Rendered) -> None:
    pdf = str(paper_files.files["pdf"])
    xmp = subprocess.run(["pdfinfo", "-meta", pdf], check=True, capture_output=True).stdout
    assert "<pdfaid:part>3</pdfaid:part><pdfaid:conformance>A</pdfaid:conformance>" in xmp.decode()
    info = subprocess.run(["pdfinfo", pdf], check=True, capture_output=True).stdout.decode()
    assert re.search(r"PDF version:\s+1\.7", info)
    fonts = subprocess.run(["pdffonts", pdf], check=True, capture_output=True).stdout.decode()
    rows = fonts.splitlines()[2:]
    assert rows and all(row.split()[-5] == "yes" for row in rows)  # every font embedded


def test_draft_is_marked_on_every_page_and_in_the_json(
    paper_report: Report, paper_files: Rendered, tmp_path: Path
) -> None:
    """Imported without a plan's [report] table and unsigned, the paper's report lacks every
    item of ISO/IEC 17025 7.8.2: a DRAFT on every page, saying what it lacks; identified and
    signed, it is not."""
    from gyrostand.report.build import build_report
    from gyrostand.report.compliance import load_profile
    from gyrostand.report.model import Signatures

    lacks = (
        "report number, laboratory, customer, manufacturer, dates of the trials, "
        "sign-off 'tested by', sign-off 'checked by'"
    )
    assert paper_report.draft and ", ".join(paper_report.missing) == lacks
    assert json.loads(paper_files.files["json"].read_text())["draft"] is True
    page_1 = pdf_text(paper_files.files["pdf"], "-layout", "-l", "1")
    unbroken = re.sub(r"\s+", "", f"DRAFT: not for issue; it lacks {lacks}")  # lines may break
    assert unbroken in re.sub(r"\s+", "", page_1)
    assert set(watermark_letters(paper_files.files["pdf"])) == {"ADFRT"}  # on every page
    inputs = paper_report.inputs
    stated = replace(
        inputs,
        identification=replace(
            inputs.identification,
            report_number="GS-1",
            laboratory="Gyro lab",
            customer="Black Sea Shipping",
            manufacturer="Kurs works",
            test_dates="1981-03-02 to 1981-03-06",
        ),
        signatures=Signatures(
            "I. Ivanov", ("I. Ivanov", "2026-01-02"), ("P. Petrov", "2026-01-03")
        ),
    )
    issued = build_report(
        stated,
        paper_report.analysis,
        load_profile(),
        generated_at=GENERATED,
        signal=paper_report.signal,
    )
    assert not issued.draft and issued.missing == ()
    files = write_report(issued, tmp_path, ("json", "pdf"))
    assert json.loads(files["json"].read_text())["draft"] is False
    assert set(watermark_letters(files["pdf"])) == {""}
    text = pdf_text(files["pdf"], "-raw")
    assert "DRAFT" not in text and "End of report GS-1" in text
    unsigned = build_report(
        replace(stated, signatures=Signatures("I. Ivanov")),
        paper_report.analysis,
        load_profile(),
        generated_at=GENERATED,
        signal=paper_report.signal,
    )
    assert unsigned.draft and unsigned.missing == ("sign-off 'tested by'", "sign-off 'checked by'")


@pytest.mark.parametrize(
    ("text", "html"),
    [
        ("F_p = 0.789 on the S_e basis", "F<sub>p</sub> = 0.789 on the S<sub>e</sub> basis"),
        ("A p^2 <= 1 m/s^2", "A p<sup>2</sup> \u2264 1 m/s<sup>2</sup>"),
        ("largest |<delta_i>|", "largest |\u27e8\u03b4<sub>i</sub>\u27e9|"),
        ("alpha_p = -6.464", "\u03b1<sub>p</sub> = -6.464"),
        ("G_ex = 0.4428 < G* = 0.5175", "G<sub>ex</sub> = 0.4428 &lt; G* = 0.5175"),
        ("+/-0.75 deg x sec(latitude)", "\u00b10.75 deg \u00d7 sec(latitude)"),
        ("n_obs and max_wait_s", "n_obs and max_wait_s"),  # plan keys stay as written
        ("<script>x</script>", "&lt;script&gt;x&lt;/script&gt;"),
    ],
)
def test_plain_text_notation_is_typeset(text: str, html: str) -> None:
    assert notation(text) == html


def test_no_plain_text_notation_reaches_the_pdf(paper_files: Rendered) -> None:
    body = paper_files.pdf_text.split("Appendix B: the plan as submitted")[-2]  # not the plan
    assert not re.findall(r"\b[A-Z]_[a-z]+\b|<=|>=|\^\d|<delta|\+/-|deg x sec", body)


def test_one_adequacy_basis_everywhere(paper_report: Report, paper_files: Rendered) -> None:
    """Fisher's test decides on the trial means (S_r^2 against S_e^2 / N): page 1, the body,
    the JSON and `campaign list` give the same verdict; the paper's basis is for comparison."""
    from gyrostand.db.queries import verdict

    a = paper_report.analysis.adequacy
    f_p = a.s2_r / (a.s2_e / 5)  # the paper's N = 5 readings per series
    assert a.f_p_mean == pytest.approx(f_p) == pytest.approx(7.046, abs=1e-3)
    assert a.decision is False and a.adequate is True  # 7.05 > F_T 3.63 > 1.41
    text = re.sub(r"\s+", " ", paper_files.pdf_text)
    assert "model adequate (Fisher, on the trial means): NO" in text.split("Contents")[0]
    assert "Adequacy of the model: the decision on the trial means, the paper's basis" in text
    assert "would be adequate" in text
    document = json.loads(paper_files.files["json"].read_text())
    assert document["analysis"]["adequacy"]["basis"] == "trial means"
    assert document["analysis"]["adequacy"]["decision"] is False
    assert document["checks"][1] == {
        "name": "model adequate (Fisher, on the trial means)",
        "verdict": False,
        "caveat": None,
    }
    assert verdict(document["analysis"]) == "homogeneous yes, adequate on trial means no"


def test_a_verdict_whose_assumption_fails_says_so(paper_report: Report) -> None:
    """Cochran's and Fisher's tests assume independent observations: when that check fails,
    both verdicts carry the caveat where they stand."""
    from gyrostand.report.build import method_checks

    a = paper_report.analysis
    assert [c.caveat for c in method_checks(a)] == [None, None, None]
    correlated = tuple(
        replace(c, holds=False, detail="12 of 12 series show lag-1 correlation at q = 0.05")
        if c.name == "independence"
        else c
        for c in a.assumptions
    )
    cochran, fisher, controls = method_checks(replace(a, assumptions=correlated))
    assert cochran.verdict is True and fisher.verdict is False and controls.verdict is True
    for check in (cochran, fisher):
        assert check.caveat == (
            "the observations are not independent (12 of 12 series show lag-1 correlation at "
            "q = 0.05): S_e understates the scatter and the verdict leans towards acceptance"
        )
    assert controls.caveat is None


def test_degrees_of_freedom_and_t_quantiles_are_stated(
    paper_report: Report, paper_files: Rendered
) -> None:
    from scipy import stats

    dof = paper_report.dof
    # 4 fit trials of two series of N = 5: nu_i = 2 (N - 1) = 8; nu_r = 4 - 2; nu_e = 4 (5 - 1)
    assert (dof.nu_trial, dof.n_obs, dof.k, dof.dof_r, dof.dof_e) == ((8, 8, 8, 8), 5, 4, 2, 16)
    assert dof.t_prediction == pytest.approx(stats.t.ppf(0.975, 2)) == pytest.approx(4.303, 1e-3)
    assert dof.t_s_e_bound == pytest.approx(stats.t.ppf(0.975, 16)) == pytest.approx(2.120, 1e-3)
    bound = paper_report.analysis.controls[0].s_e_bound_deg
    assert bound == pytest.approx(dof.t_s_e_bound * paper_report.analysis.cochran.s_e)
    text = re.sub(r"\s+", " ", paper_files.pdf_text)
    assert "t(0.975; νr = 2) = 4.303" in text and "t(0.975; 16) = 2.120" in text
    assert "νi = 8 for each fit trial" in text and "νe = sum(νi) / 2 = 16" in text


def test_every_forecast_beyond_the_tested_range_is_an_extrapolation(
    paper_report: Report, paper_files: Rendered
) -> None:
    """The trials covered A 17.8-24 cm, tau 3.5-8 s: the plan's forecast (A = 65 cm) and the
    envelope's worst case (20 deg at h = 750 cm, 1 m/s^2) lie far beyond, and say by how much."""
    trials = paper_report.trials
    amplitude = [t.amplitude_cm for t in trials]
    accel = [t.amplitude_cm * (2 * math.pi / t.period_s) ** 2 / 100 for t in trials]
    f = paper_report.forecast
    assert f.tested.amplitude_cm == (min(amplitude), max(amplitude)) == (17.8, 24.0)
    assert f.tested.period_s == (3.5, 8.0)
    assert f.tested.acceleration_m_s2[1] == pytest.approx(max(accel))
    assert f.point_extrapolation.factor == pytest.approx(65 / 24)
    assert f.point_extrapolation.text == "extrapolation: A = 65 cm (\u00d72.71)"
    assert all(g.extrapolation.factor == pytest.approx(65 / 24) for g in f.table)
    assert f.tested.beyond(20.0, 5.0) is None  # inside: no mark
    (worst,) = paper_report.compliance.predictions
    a_worst = math.radians(20) * 750
    assert worst.extrapolation.factor == pytest.approx(a_worst / 24)  # x10.9
    assert f"A p^2 = 1 m/s^2 (\u00d7{1 / max(accel):.3g})" in worst.extrapolation.text
    assert "from a fit with nu_r = 2 degrees of freedom" in worst.detail
    document = json.loads(paper_files.files["json"].read_text())
    assert document["forecast"]["point_extrapolation"]["factor"] == pytest.approx(65 / 24)
    assert document["compliance"]["predictions"][0]["extrapolation"]["factor"] > 10
    text = re.sub(r"\s+", " ", paper_files.pdf_text)
    assert "Tested range. The stand's analysed trials covered A 17.8-24 cm" in text


def test_imported_data_get_no_stand_boilerplate(paper_report: Report) -> None:
    """Imported without a plan: the reasons speak of the imported data, and the admissible
    region is the example's, not a plan's."""
    details = {i.evidence: i.detail for i in paper_report.compliance.items}
    assert details["settling_time"] == "the imported data record no run-up from switch-on"
    assert details["settle_repeatability"].startswith("the imported data record no run-up")
    assert not any("settle waits" in d or "one run-up only" in d for d in details.values())
    (admissible,) = [w for w in paper_report.analysis.warnings if "admissible" in w]
    assert admissible.startswith("T = 1.15094 s lies outside the admissible region [0.1, 1] s")
    assert admissible.endswith(" of the example of Potemkin (1982); reported unconstrained")
    assert "stated in the plan" not in admissible
