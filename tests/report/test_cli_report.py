"""`gyrostand report` and `gyrostand analyze CAMPAIGN_ID --db`: files, JSON, one-line errors."""

import json
import re
from pathlib import Path

import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import AnalysisRun

from .conftest import Stored, import_paper

runner = CliRunner()


@pytest.fixture
def stored(tmp_path: Path) -> Stored:
    return import_paper(tmp_path)


def test_report_writes_the_asked_formats(stored: Stored, tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ["report", str(stored.campaign_id), "--db", stored.url, "--out", str(out)]
    result = runner.invoke(app, [*args, "--format", "json,csv"])
    assert result.exit_code == 0, result.output
    json_path, csv_path = out / "campaign-1.json", out / "campaign-1-trials.csv"
    assert f"wrote json: {json_path}" in result.stdout and f"wrote csv: {csv_path}" in result.stdout
    assert not (out / "campaign-1.pdf").exists() and not (out / "campaign-1.html").exists()
    doc = json.loads(json_path.read_text())
    assert doc["analysis"]["adequacy"]["f_p"] == pytest.approx(1.409, abs=1e-3)
    assert doc["identification"]["database"] == stored.url
    assert len(csv_path.read_text().splitlines()) == 7
    assert "report: drawing the figures" not in result.stderr  # no HTML asked: no figures
    html = runner.invoke(app, [*args, "--format", "html"])
    stages = [line for line in html.stderr.splitlines() if line.startswith("report: ")]
    assert stages[1].startswith("report: a DRAFT: it lacks report number, laboratory, ")
    assert stages[2:-1] == [f"report: writing html to {out}", "report: drawing the figures"]
    assert re.fullmatch(rf"report: campaign 1: 1 files written in {out} \(\d+\.\d s\)", stages[-1])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["report", "9"], "no campaign 9 in the database"),
        (["report", "1", "--format", "html,docx"], "docx not among"),
        (["report", "1", "--profile", "nope"], "no compliance profile named 'nope'"),
        (["analyze", "9"], "no campaign 9"),
        (["analyze", "1", "--csv", "x.csv"], "not both"),
    ],
)
def test_one_line_errors(stored: Stored, args: list[str], message: str) -> None:
    result = runner.invoke(app, [*args, "--db", stored.url])
    assert result.exit_code == 2
    assert message in result.stderr and "Traceback" not in result.output
    missing = runner.invoke(app, ["report", "1", "--db", str(Path(stored.url).with_name("x.db"))])
    assert missing.exit_code == 2 and "no database at" in missing.stderr


def test_analyze_a_stored_campaign_records_one_run(stored: Stored) -> None:
    for _ in range(2):
        result = runner.invoke(app, ["analyze", "1", "--db", stored.url, "--json"])
        assert result.exit_code == 0, result.output
        data = json.loads(result.stdout)
        assert data["cochran"]["g_ex"] == pytest.approx(0.4936, abs=1e-4)
    text = runner.invoke(app, ["analyze", "1", "--db", stored.url])
    assert "COCHRAN" in text.stdout and "FORECAST" in text.stdout
    with stored.sessions() as session:
        assert session.scalar(select(func.count(AnalysisRun.id))) == 1


@pytest.mark.parametrize("profile", ["imo-a424", "imo-a821", "iso-22090-1"])
def test_report_takes_each_shipped_profile(stored: Stored, tmp_path: Path, profile: str) -> None:
    out = tmp_path / "out"
    args = ["report", "1", "--db", stored.url, "--out", str(out), "-f", "json"]
    result = runner.invoke(app, [*args, "--profile", profile])
    assert result.exit_code == 0, result.output
    name = "campaign-1.json" if profile == "imo-a424" else f"campaign-1-{profile}.json"
    compliance = json.loads((out / name).read_text())["compliance"]
    assert compliance["profile_id"] == profile
    # no shipped limit is verified by a laboratory; the ISO draft's stand test moves 3 axes
    decision = "NOT ASSESSED" if profile == "iso-22090-1" else "INCONCLUSIVE"
    assert compliance["decision"] == decision and decision not in compliance["summary"]
    assert compliance["decision_rule"] == "guarded"
    worst = next(i["worst"] for i in compliance["predictions"] if i["worst"] is not None)
    assert worst["angle_deg"] == pytest.approx(20.0) and worst["period_s"] > 10.0


def test_a_report_against_another_profile_keeps_the_earlier_one(
    stored: Stored, tmp_path: Path
) -> None:
    """Before: every profile wrote campaign-1.json, the last overwriting the first."""
    out = tmp_path / "out"
    args = ["report", "1", "--db", stored.url, "--out", str(out), "-f", "json,csv"]
    for profile in ("imo-a424", "imo-a821"):
        assert runner.invoke(app, [*args, "--profile", profile]).exit_code == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "campaign-1-imo-a821-trials.csv",
        "campaign-1-imo-a821.json",
        "campaign-1-trials.csv",
        "campaign-1.json",
    ]
    for name, profile in (("campaign-1", "imo-a424"), ("campaign-1-imo-a821", "imo-a821")):
        assert json.loads((out / f"{name}.json").read_text())["compliance"]["profile_id"] == profile


def test_report_help_lists_the_shipped_profiles() -> None:
    result = runner.invoke(app, ["report", "--help"], env={"COLUMNS": "200"})
    assert "imo-a424, imo-a821, iso-22090-1" in result.stdout


def test_a_profile_without_verified_flags_is_refused_in_one_line(
    stored: Stored, tmp_path: Path
) -> None:
    shipped = Path(__file__).resolve().parents[2] / "report/profiles/imo-a821.toml"
    bad = tmp_path / "bad.toml"
    bad.write_text(shipped.read_text().replace("verified = true\n", "", 1))
    result = runner.invoke(app, ["report", "1", "--db", stored.url, "--profile", str(bad)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert result.stderr.strip().splitlines() == [
        f"gyrostand: error: compliance profile {bad}: requirements[1]: verified is missing or "
        "of the "
        "wrong type"
    ]


def identified(folder: Path, *, sign: tuple[str, ...] = ("tested_by", "checked_by")) -> Stored:
    """The paper example imported with every item of ISO/IEC 17025 7.8.2 in its plan, signed
    off at the station for the given roles."""
    from gyrostand.db.io import SEED_000_METADATA, metadata_toml
    from gyrostand.station.signoff import sign_off

    plan = metadata_toml(SEED_000_METADATA).replace(
        "[instrument]\n", '[instrument]\nmanufacturer = "Kurs works, Kyiv"\n'
    ) + (
        '\n[report]\nnumber = "GS-2026-017"\nlaboratory = "Gyro lab, 1 Quay St, Odesa"\n'
        'customer = "Black Sea Shipping, Odesa"\ndates = "1981-03-02 to 1981-03-06"\n'
    )
    stored = import_paper(folder, plan_toml=plan)
    with stored.sessions.begin() as session:
        for role, name in (("tested_by", "I. Ivanov"), ("checked_by", "P. Petrov")):
            if role in sign:
                sign_off(session, stored.campaign_id, role, name)
    return stored


def runs(stored: Stored) -> int:
    with stored.sessions() as session:
        return session.scalar(select(func.count(AnalysisRun.id)))


def test_final_refuses_a_report_missing_its_identification_or_sign_off(tmp_path: Path) -> None:
    """ISO/IEC 17025 7.8.2: without its items a report is a DRAFT; --final names what is
    missing in one line and records nothing."""
    bare = import_paper(tmp_path / "bare")
    args = ["report", "1", "--db", bare.url, "--out", str(tmp_path / "out"), "-f", "json"]
    refused = runner.invoke(app, [*args, "--final"])
    assert refused.exit_code == 2 and "Traceback" not in refused.output
    assert refused.stderr.strip().splitlines()[-1] == (
        "gyrostand: error: report --final: campaign 1 lacks report number, laboratory, "
        "customer, manufacturer, dates of the trials, sign-off 'tested by', sign-off "
        "'checked by' (ISO/IEC 17025 7.8.2); it can only be a DRAFT"
    )
    assert runs(bare) == 0 and not (tmp_path / "out" / "campaign-1.json").exists()
    draft = runner.invoke(app, args)  # without --final: written, a DRAFT
    assert draft.exit_code == 0 and "report: a DRAFT: it lacks report number" in draft.stderr
    doc = json.loads((tmp_path / "out" / "campaign-1.json").read_text())
    assert doc["draft"] is True and len(doc["missing"]) == 7
    assert doc["title"] == (
        "Rolling-error test report of campaign 1 (unnumbered): two-rotor gyrocompass (example "
        "of Potemkin 1982), serial Potemkin-1982"
    )
    unchecked = identified(tmp_path / "unchecked", sign=("tested_by",))
    refused = runner.invoke(
        app, ["report", "1", "--db", unchecked.url, "--out", str(tmp_path), "--final", "-f", "json"]
    )
    assert refused.exit_code == 2 and "lacks sign-off 'checked by' (ISO" in refused.stderr
    both = runner.invoke(app, [*args, "--final", "--draft"])
    assert both.exit_code == 2 and "give one of them" in both.stderr


def test_final_issues_an_identified_signed_report(tmp_path: Path) -> None:
    stored = identified(tmp_path)
    out = tmp_path / "out"
    args = ["report", "1", "--db", stored.url, "--out", str(out), "-f", "json,html"]
    result = runner.invoke(app, [*args, "--final"])
    assert result.exit_code == 0, result.output
    doc = json.loads((out / "campaign-1.json").read_text())
    assert doc["draft"] is False and doc["missing"] == []
    ident = doc["identification"]
    assert ident["manufacturer"] == "Kurs works, Kyiv"
    assert ident["test_dates"] == "1981-03-02 to 1981-03-06"  # an import records none itself
    assert doc["title"] == (
        "Rolling-error test report GS-2026-017: two-rotor gyrocompass (example of Potemkin "
        "1982), serial Potemkin-1982"
    )
    assert doc["end_of_report"] == "End of report GS-2026-017"
    html = (out / "campaign-1.html").read_text()
    assert f"<title>{doc['title']}</title>" in html and "DRAFT" not in html
    assert html.rstrip().endswith("&mdash; End of report GS-2026-017 &mdash;</p>\n</body>\n</html>")
    assert runner.invoke(app, [*args, "--draft"]).exit_code == 0  # a draft on request
    assert json.loads((out / "campaign-1.json").read_text())["draft"] is True
