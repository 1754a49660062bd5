"""`campaign run` of a plan with [[procedure]]: the procedures run before the trials on the
simulated compass, their results stored (procedure_run, migration 0020) and judged in the
report's clause table (the slow stage: a campaign and a report, ~20 s on a loaded machine)."""

from __future__ import annotations

import hashlib
import json
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from tests.acquisition.harness import FAST_SIM, plan_text
from tests.db.test_meas_source import _downgrade

PROCEDURES = """
[standard]
profile = "imo-a821"
[reference]
heading_deg = 120.0
uncertainty_deg = 0.01
[[procedure]]
kind = "settling"
max_wait_s = 1800.0
[[procedure]]
kind = "settle_point"
interval_s = 30.0
"""
TRANSIENT = "max_wait_s = 3600.0\nundamped_period_s = 240.0\ndamping_ratio = 0.8"


def plan(tmp_path: Path) -> str:
    trials = [(45.0, 24.0, 6.0, "fit")]
    text = plan_text(trials, database=str(tmp_path / "p.sqlite"), raw_dir=str(tmp_path / "raw"))
    return text.replace("max_wait_s = 3600.0", TRANSIENT) + FAST_SIM + PROCEDURES


def test_campaign_run_stores_the_procedures_and_the_report_judges_them(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text(plan(tmp_path))
    checked = CliRunner().invoke(app, ["plan", "check", str(path)])
    assert checked.exit_code == 0, checked.output
    assert (
        "procedure — settling: from switch-on, band 0.7 deg, recorded 1800 s, fitted from 60 s "
        "(departs from the standard: max_wait_s 1800 s instead of the standard's 21600 s)"
    ) in checked.output
    run = CliRunner().invoke(app, ["campaign", "run", str(path), "--quiet"])
    assert run.exit_code == 0, run.output
    db = tmp_path / "p.sqlite"
    with sqlite3.connect(db) as conn:
        (stored,) = conn.execute("SELECT results_json FROM procedure_run").fetchone()
        events = conn.execute("SELECT message FROM event WHERE kind = 'procedures'").fetchall()
    results = json.loads(stored)
    assert events == [("the standard's procedures run and stored: settling, settle_point",)]
    out = tmp_path / "reports"
    report = CliRunner().invoke(
        app, ["report", "1", "--db", str(db), "--out", str(out), "-f", "json,html"]
    )
    assert report.exit_code == 0, report.output
    compliance = json.loads(next(out.glob("*.json")).read_text())["compliance"]
    # no --profile: the plan's [standard] profile, not the shipped default (imo-a424)
    assert compliance["profile_id"] == "imo-a821"
    items = {i["id"]: i for i in compliance["items"]}
    settling = items["settling-time"]
    assert settling["value_deg"] == pytest.approx(results["settling"]["value_s"] / 3600)
    # hours, and said so: in the JSON and in the report's clause table (not under "deg")
    assert settling["unit"] == "h" and items["heading-rms"]["unit"] == "deg"
    html = next(out.glob("*.html")).read_text()
    hours = f"{settling['value_deg']:.3f} &plusmn; {settling['uncertainty_deg']:.3f} h</td>"
    assert hours in html and "value &plusmn; U, deg" not in html
    assert "departs from the standard's: max_wait_s 1800 s" in settling["detail"]
    error = items["settle-point-error"]
    assert error["value_deg"] == pytest.approx(abs(results["settle_point"]["error_deg"]))
    assert items["heading-rms"]["value_deg"] == pytest.approx(results["settle_point"]["rms_deg"])
    # the schema before 0020 has no procedure_run; the upgrade makes it, the downgrade drops it
    _downgrade(db, "0015")
    with sqlite3.connect(db) as conn:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert "procedure_run" not in tables and "campaign" in tables


def test_replay_re_derives_the_procedures_from_their_raw_log(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text(plan(tmp_path))
    run = CliRunner().invoke(app, ["campaign", "run", str(path), "--quiet"])
    assert run.exit_code == 0, run.output
    db = tmp_path / "p.sqlite"
    (trials_log,) = (tmp_path / "raw").glob("*campaign-1.blf")
    procedures_log = trials_log.with_name(f"{trials_log.stem}.procedures.blf")

    def stored(campaign: int) -> dict:
        with sqlite3.connect(db) as conn:
            (text,) = conn.execute(
                "SELECT results_json FROM procedure_run WHERE campaign_id = ?", (campaign,)
            ).fetchone()
        return json.loads(text)

    live = stored(1)
    assert live["raw_log"]["path"] == str(procedures_log.resolve())
    assert live["raw_log"]["sha256"] == hashlib.sha256(procedures_log.read_bytes()).hexdigest()
    args = ["replay", str(trials_log), "--plan", str(path), "--db", str(db)]
    replayed = CliRunner().invoke(app, args)
    assert replayed.exit_code == 0, replayed.output
    again = stored(2)
    assert again.pop("raw_log") == live.pop("raw_log")
    assert again == live  # the same results, to the bit (JSON floats round-trip exactly)
    # without the procedures' log beside the trials': refused in one line, nothing written
    procedures_log.rename(tmp_path / "elsewhere.blf")
    refused = CliRunner().invoke(app, args)
    assert refused.exit_code != 0
    assert refused.output.strip().splitlines() == [
        f"gyrostand: error: cannot replay {procedures_log}: no such file: the plan has the "
        f"standard's procedures, whose frames are in this log beside {trials_log.name}"
    ]
    with sqlite3.connect(db) as conn:
        assert conn.execute("SELECT count(*) FROM campaign").fetchone() == (2,)
