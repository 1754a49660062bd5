"""A campaign with a heading source timed by reception (`[compass] protocol = "nmea2000"`, and
"cia406" with a counter-clockwise encoder) from the command line, as a user runs it on the
simulated stand: plan check, campaign run, analyze and report stating the heading source, replay
re-deriving the same observations from the raw log."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from tests.acquisition.harness import FAST_SIM, plan_text

runner = CliRunner()
TRIALS = [(45.0, 24.0, 6.0, "fit"), (135.0, 20.0, 5.0, "fit"), (315.0, 16.0, 8.0, "fit")]
TIME_BASE = (
    "time base: reception time on the stand clock; virtual time: the simulated compass's frames "
    "are received at their stand time"
)
SOURCES = {  # protocol: (the rest of its [compass] table, resolution deg, the source stated)
    "nmea2000": (
        "",
        1e-4 * 180 / 3.141592653589793,
        f"nmea2000, heading resolution 0.0057 deg; {TIME_BASE}",
    ),
    "cia406": (
        "node_id = 5\ncounts_per_revolution = 65536\nzero_counts = 300\n"
        'direction = "counterclockwise"\n',
        360 / 65536,
        f"cia406, heading resolution 0.0055 deg; {TIME_BASE}; CiA 406 TPDO 0x185 sent on its "
        "event timer",
    ),
}
OBSERVATIONS = """SELECT t."index", s.j, o.k, o.value_deg, o.frames_used, o.frames_lost, o.flags
    FROM observation o JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id
    WHERE t.campaign_id = ? ORDER BY t."index", s.j, o.k"""


@pytest.fixture(scope="module", params=list(SOURCES))
def campaign(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp(request.param)
    plan = folder / f"{request.param}.toml"  # (its stem: the protocol)
    text = plan_text(trials=TRIALS, database=str(folder / "db.sqlite"), raw_dir=str(folder))
    compass = f'\n[compass]\nprotocol = "{request.param}"\n{SOURCES[request.param][0]}'
    plan.write_text(text + FAST_SIM + compass)
    proc = subprocess.run(
        [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan), "--quiet"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    return plan


def test_plan_check_names_the_heading_source(campaign: Path) -> None:
    result = runner.invoke(app, ["plan", "check", str(campaign)])
    assert result.exit_code == 0 and f"compass on {campaign.stem}" in result.stdout


def test_the_campaign_records_its_heading_source(campaign: Path) -> None:
    with sqlite3.connect(campaign.with_name("db.sqlite")) as conn:
        row = conn.execute(
            "SELECT status, heading_source, heading_resolution_deg FROM campaign"
        ).fetchone()
        observations = conn.execute(OBSERVATIONS, (1,)).fetchall()
    protocol = row[1]
    assert row[0] == "completed" and protocol == campaign.stem
    assert row[2] == pytest.approx(SOURCES[protocol][1], rel=1e-12)
    assert len(observations) == 18 and all(o[5] == 0 for o in observations)


def test_analyze_and_report_state_it(campaign: Path, tmp_path: Path) -> None:
    db = str(campaign.with_name("db.sqlite"))
    source = SOURCES[campaign.stem][2]
    text = runner.invoke(app, ["analyze", "1", "--db", db])
    assert text.exit_code == 0, text.output
    assert text.stdout.startswith(f"HEADING SOURCE\n{source}\n\nMOTION (commanded; applied")
    assert "(stand report)" in text.stdout and "\n\nTRIALS" in text.stdout
    doc = json.loads(runner.invoke(app, ["analyze", "1", "--db", db, "--json"]).stdout)
    assert doc["heading_source"] == source
    out = tmp_path / "out"
    result = runner.invoke(app, ["report", "1", "--db", db, "--out", str(out), "-f", "json"])
    assert result.exit_code == 0, result.output
    report = json.loads((out / "campaign-1.json").read_text())
    assert report["identification"]["heading_source"] == source
    assert report["signal"]["record"]["frames"] > 100  # the source's heading frames of the log


def test_replay_derives_the_same_observations(campaign: Path) -> None:
    db = campaign.with_name("db.sqlite")
    (log,) = campaign.parent.glob("*campaign-1.blf")  # (named after the database)
    result = runner.invoke(app, ["replay", str(log), "--plan", str(campaign)])
    assert result.exit_code == 0, result.output
    with sqlite3.connect(db) as conn:
        live, again = (conn.execute(OBSERVATIONS, (c,)).fetchall() for c in (1, 2))
    assert again == live
