"""What a reviewer reads (issue 33, the minor list): no plain-text notation, plan keys, jargon or
local file paths in the reports; one symbol per quantity with a nomenclature table; the plan
without its comments; an imported campaign's appendix without empty tables."""

import re

import pytest

from gyrostand.report.build import Report
from gyrostand.report.html import file_names, notation, render_html, without_comments

from .conftest import Rendered

ASCII_LEFT = re.compile(
    r"\btau ?=|\bnu ?=|\|rho\||\btheta0|\bsqrt\(|\bT_s\b|\bTs =|\d\.\d+e-\d\d|HIL twin|PUC_2513|"
    r"running-median|spacing_s|max_wait_s|\[acceptance\]|/tmp/|examples/"
)


def test_notation_typesets_the_plain_text_symbols() -> None:
    assert str(notation("A = theta0 h, |rho| <= 0.1, sqrt(S^2/N), nu = 5")) == (
        "A = θ<sub>0</sub> h, |ρ| ≤ 0.1, √(S<sup>2</sup>/N), ν = 5"
    )


def test_local_paths_name_the_file_only() -> None:
    assert file_names("raw frames in /var/lab/runs/raw/c-1.blf (sha256 ab)") == (
        "raw frames in c-1.blf (sha256 ab)"
    )
    assert file_names("sqlite:////srv/lab/gyro.sqlite") == "gyro.sqlite"
    assert file_names("postgresql://lab:***@db/gyro") == "postgresql://lab:***@db/gyro"


def test_the_plan_without_its_comments() -> None:
    toml = (
        '# the lab\'s note\n[campaign]  # heading\nname = "a # b"  # inline\n\n\n'
        'text = """\n# kept: inside a string\n"""\nn_obs = 5\n'
    )
    assert without_comments(toml) == (
        '[campaign]\nname = "a # b"\n\ntext = """\n# kept: inside a string\n"""\nn_obs = 5\n'
    )


def test_the_imported_report_reads_clean(paper_files: Rendered) -> None:
    text = " ".join(paper_files.pdf_text.split())
    appendix_b = text.rindex("Appendix B: the plan as submitted")  # the plan's TOML as written
    assert ASCII_LEFT.findall(text[:appendix_b]) == []
    assert re.findall(r"\b\d(?:\.\d+)?e[-+]\d\d\b", text[:appendix_b]) == []  # figures too
    assert "Nomenclature" in text and "Symbols: one quantity each" in text
    for symbol in ("p = 2π/τ", "R̂(u)", "σA(ta)", "Ω", "kg·m²·s−2"):
        assert symbol in text, symbol
    # no per-trial observation tables without observations; no "completed" trial without them
    assert "No single observations are stored" in text
    assert not re.search(r"Table \d+\. Trial 1 \(fit\)", text)
    html = paper_files.files["html"].read_text(encoding="utf-8")
    assert html.count("<td>imported summary</td>") == 6


def test_the_simulated_report_reads_clean(simulated_report: Report) -> None:
    html = render_html(simulated_report)
    body = re.sub(r"<[^>]+>", " ", html.split("<body>")[1].split('id="plan-text"')[0])
    assert ASCII_LEFT.findall(body) == []
    assert "|ρ|" in body or "ρ" not in body  # the independence check's threshold, typeset
    assert "# " not in html.split('id="plan-text"')[1]  # Appendix B: the plan without comments


@pytest.mark.parametrize("word", ["HIL", "PUC_2513_14", "running-median"])
def test_no_jargon_in_the_templates(word: str) -> None:
    from gyrostand.report.html import TEMPLATES

    assert word not in (TEMPLATES / "report.html.j2").read_text(encoding="utf-8")


TERMINAL_ASCII = re.compile(
    r"\b(?:tau|nu|nu_[er]|rho|sigma2?|delta|alpha_p)\b|<delta|\+/-|<=|\^-?\d|\bS_e\b|\bG_ex\b|"
    r"\bF_p\b|\btheta0|\bC_gcm2s2\b|\bT_s\b"
)
"""The analysis's plain-text notation as `gyrostand analyze` printed it (nu = 5, tau s, S^2_e,
G_ex, +/- ...) where the report has its symbols."""


def test_the_analysis_text_speaks_the_reports_symbols(
    paper_report: Report, simulated_report: Report
) -> None:
    """`gyrostand analyze` in the nomenclature's symbols, one per quantity (issue 33): ν, τ,
    ⟨δᵢ⟩, Sₑ², ±; the paper's imported summaries and a simulated campaign's correlated series
    (its N_eff columns and the transient section)."""
    from gyrostand.report.text import render_text

    for report in (paper_report, simulated_report):
        assert report.analysis is not None
        text = render_text(report.analysis)
        assert TERMINAL_ASCII.findall(text) == []
        c = report.analysis.cochran
        assert f"Gₑₓ = {c.g_ex:.4f}, G* = {c.g_critical:.4f} (q = {c.q}, ν = {c.nu}, " in text
        assert f"Sₑ = {c.s_e:.4f} deg" in text
        assert "τ s" in text.split("\n")[1]  # the trial table's header
    f = paper_report.analysis.forecasts[0]
    assert f"{f.alpha_deg:+.3f} ± {f.half_width_deg:.3f} deg" in render_text(paper_report.analysis)
