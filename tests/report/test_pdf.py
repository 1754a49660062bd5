"""The PDF laid out by Typst: PDF/A-3 with the report's data inside (extracted and compared with
`gyrostand analyze --json`), the same numbers and verdicts as the HTML, hostile strings."""

import json
import re
import subprocess
import time
from collections import Counter
from dataclasses import replace
from html.parser import HTMLParser
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import Campaign
from gyrostand.report.build import Report
from gyrostand.report.html import fmt
from gyrostand.report.pdf import breakable, document, write_pdf
from gyrostand.report.writer import write_report

from .conftest import Rendered, Stored, pdf_text

runner = CliRunner()


def test_the_pdf_carries_the_report_json_the_trial_csv_and_the_plan(
    paper: Stored, paper_files: Rendered, tmp_path: Path
) -> None:
    pdf = paper_files.files["pdf"]
    subprocess.run(["pdfdetach", "-saveall", "-o", str(tmp_path), str(pdf)], check=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "campaign-1-plan.toml",
        "campaign-1-trials.csv",
        "campaign-1.json",
    ]
    carried = json.loads((tmp_path / "campaign-1.json").read_text(encoding="utf-8"))
    # the same analysis again: the database keeps its one run (same inputs, same results)
    analysed = runner.invoke(app, ["analyze", "1", "--db", paper.url, "--json"])
    assert analysed.exit_code == 0, analysed.output
    analysis = json.loads(analysed.stdout)
    # the heading source stands in the report's identification
    assert analysis.pop("heading_source") == carried["identification"]["heading_source"]
    # the applied motion's source per trial stands in the report's acquisition table
    sources = {t["index"]: t["motion_source"] for t in carried["acquisition"]["trials"]}
    assert {m["trial"]: m["source"] for m in analysis.pop("motion")} == sources
    assert carried["analysis"] == analysis
    csv = (tmp_path / "campaign-1-trials.csv").read_text(encoding="utf-8")
    assert csv == paper_files.files["csv"].read_text(encoding="utf-8")
    rows = [r.split(",") for r in csv.splitlines()]
    assert [float(r[rows[0].index("delta_deg")]) for r in rows[1:]] == [
        t["delta_deg"] for t in carried["analysis"]["trials"]
    ]
    with paper.sessions() as session:
        plan = session.get(Campaign, paper.campaign_id).plan_toml
    assert (tmp_path / "campaign-1-plan.toml").read_text(encoding="utf-8") == plan
    raw = pdf.read_bytes()  # PDF/A-3: each an associated file of the document
    assert raw.count(b"/AFRelationship/Data") == 3
    assert re.search(rb"/AF\[\d+ 0 R \d+ 0 R \d+ 0 R\]", raw)


class _Visible(HTMLParser):
    """The text a browser shows (no <title>, style or script); badges apart."""

    def __init__(self) -> None:
        super().__init__()
        self.text: list[str] = []
        self.badges: list[str] = []
        self.hidden = 0
        self.badge = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.hidden += tag in ("title", "style", "script")
        self.badge = "badge" in (dict(attrs).get("class") or "").split()

    def handle_endtag(self, tag: str) -> None:
        self.hidden -= tag in ("title", "style", "script")
        self.text.append(" ")

    def handle_data(self, data: str) -> None:
        if not self.hidden:
            self.text.append(data)
            if self.badge:
                self.badges.append(data)
                self.badge = False


NUMBER = re.compile(r"[+-]?\d+(?:\.\d+)?")


def test_every_number_and_verdict_of_the_html_is_in_the_pdf(
    paper_report: Report, paper_files: Rendered
) -> None:
    seen = _Visible()
    seen.feed(paper_files.files["html"].read_text(encoding="utf-8"))
    html = "".join(seen.text)
    pdf = pdf_text(paper_files.files["pdf"], "-raw")
    html_numbers, pdf_numbers = Counter(NUMBER.findall(html)), Counter(NUMBER.findall(pdf))
    missing = {n: k for n, k in html_numbers.items() if pdf_numbers[n] < k}
    assert missing == {}
    assert sum(html_numbers.values()) > 900  # the whole document, not a page of it
    for t in paper_report.trials:  # the document object's numbers, as the trial table prints them
        printed = [fmt(t.delta_deg, "+.4f"), fmt(t.alpha_deg, "+.4f"), fmt(t.residual_deg, "+.4f")]
        assert [n for n in printed if n not in html_numbers or n not in pdf_numbers] == []
    verdicts = Counter(seen.badges)
    words = re.sub(r"\s+", " ", pdf)  # a badge in a narrow column may wrap between its words
    assert {v: words.count(v) >= k for v, k in verdicts.items()} == dict.fromkeys(verdicts, True)
    # the document object's own verdicts, in both
    stated = [
        paper_report.conformity.verdict,
        paper_report.compliance.decision,
        *(item.verdict for item in paper_report.compliance.items),
    ]
    assert [v for v in stated if v not in html or v not in pdf] == []
    assert paper_report.conformity.verdict in verdicts


def test_long_unbroken_strings_wrap_in_bounded_time(paper_report: Report, tmp_path: Path) -> None:
    """Issue 30, point 10: 20 kB of unbroken `<script>` in model and serial (in every page's
    footer too) took minutes in the old PDF layout. The operator's Typst markup is text."""
    long = "<script>" + "x" * 20_000 + "</script>"
    markup = '#set page(fill: red) $x$ #pagebreak() <label> @ref *b* ] ) } "'
    ident = replace(
        paper_report.inputs.identification,
        operator=markup,
        instrument_model=long,
        instrument_serial=long,
    )
    report = replace(paper_report, inputs=replace(paper_report.inputs, identification=ident))
    start = time.process_time()
    files = write_report(report, tmp_path, ("html", "pdf"))
    assert time.process_time() - start < 60  # a guard against pathological layout: ~4 s here
    pages = [p for p in pdf_text(files["pdf"]).split("\f") if p.strip()]
    assert len(pages) < 60  # 41: the 40 kB appear in the identification, the title and the plan
    seen = _Visible()
    seen.feed(files["html"].read_text(encoding="utf-8"))
    shown = "".join(seen.text).count("x" * 20_000)
    assert shown >= 2
    assert "".join(pages).count("x") >= shown * 20_000  # all of it, wrapped, not cut
    lines = subprocess.run(["pdftotext", str(files["pdf"]), "-"], capture_output=True).stdout
    wrapped = [line for line in lines.decode().splitlines() if "x" * 12 in line]
    assert max(map(len, wrapped)) < 200  # a line of the page, not 20 000 characters
    assert [len(re.findall(r"page \d+ of \d+", p)) for p in pages] == [1] * len(pages)
    assert f"operator recorded: {markup}" in " ".join(pdf_text(files["pdf"], "-raw").split())


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("a" * 23, "a" * 23),
        ("a" * 24, "a" * 12 + "\u200b" + "a" * 12),
        (
            "sha " + "f" * 30 + " end",
            "sha " + "f" * 12 + "\u200b" + "f" * 12 + "\u200b" + "f" * 6 + " end",
        ),
    ],
)
def test_long_runs_get_break_opportunities(text: str, expected: str) -> None:
    assert breakable(text) == expected


def test_the_html_becomes_plain_data() -> None:
    html = (
        "<html><head><title>T  1</title></head><body><header class='doc'><div class='doc-id'>"
        "id &amp; no.</div></header><div class='watermark'>DRAFT<br>SIMULATION</div>"
        "<section id='s'><h2>Head</h2><table><caption>Cap</caption><thead><tr><th colspan='2'>"
        "x</th></tr></thead><tr><td class='n'>1</td><td><b>#bold</b> text</td></tr></table>"
        "</section></body></html>"
    )
    doc = document(html)
    assert doc["meta"] == {
        "title": "T 1",
        "doc_id": "id & no.",
        "banner": "",
        "watermark": ["DRAFT", "SIMULATION"],
    }
    section = doc["body"][2]
    assert section["k"][0] == {"t": "h2", "c": "", "id": "s", "k": ["Head"]}
    table = section["k"][1]
    assert (table["columns"], table["caption"], len(table["head"]), len(table["body"])) == (
        2,
        ["Cap"],
        1,
        1,
    )
    assert table["body"][0]["k"][1]["k"] == [{"t": "b", "c": "", "k": ["#bold"]}, " text"]


def test_table_headers_repeat_and_every_page_is_numbered(tmp_path: Path) -> None:
    rows = "".join(f"<tr><td class='n'>{i}</td><td>row {i}</td></tr>" for i in range(250))
    html = (
        "<html><head><title>t</title></head><body><header class='doc'><h1>T</h1>"
        "<div class='doc-id'>doc 7</div></header><section id='a'><h2>A</h2><table>"
        "<caption>Long</caption><thead><tr><th>index</th><th>name of the row</th></tr></thead>"
        f"{rows}</table></section></body></html>"
    )
    pdf = write_pdf(html, tmp_path / "t.pdf")
    pages = [p for p in pdf_text(pdf).split("\f") if p.strip()]
    assert len(pages) >= 3
    assert [p.count("name of the row") for p in pages] == [1] * len(pages)
    assert [f"page {i} of {len(pages)}" in p for i, p in enumerate(pages, 1)] == [True] * len(pages)
    assert all("doc 7" in p for p in pages)  # the running footer
