"""`gyrostand campaign list`: the filters (model, serial, stand, status, day, labels, text) in
text and JSON, and the same campaigns and verdicts on the station's campaigns page, on both
database back ends."""

import json
import re
from datetime import UTC, datetime, timedelta
from pathlib import Path

from sqlalchemy import update
from starlette.testclient import TestClient
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import AnalysisRun, Campaign
from gyrostand.db.session import open_database
from gyrostand.station.app import create_app
from gyrostand.station.security import Access
from tests.acquisition.harness import ROOT

PAPER_CSV = str(ROOT / "examples" / "paper.csv")


def gyrostand(*args: str) -> str:
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result.stdout


def listed(db: str, *filters: str) -> list[int]:
    document = json.loads(gyrostand("campaign", "list", "--json", "--db", db, *filters))
    return [c["id"] for c in document["campaigns"]]


def test_filters_in_json_and_text(db_url: str) -> None:
    for tags in (["stand=S1", "factory=A"], ["stand=S2", "factory=A"], ["stand=S1"]):
        gyrostand("import", PAPER_CSV, "--db", db_url, *(a for t in tags for a in ("--tag", t)))
    sessions = open_database(db_url)
    with sessions.begin() as session:  # campaign 3: another unit, stored last year, failed
        session.execute(update(Campaign).where(Campaign.id == 3).values(status="failed"))
        session.execute(
            update(Campaign)
            .where(Campaign.id == 3)
            .values(created_at=datetime(2025, 6, 30, 23, 30, tzinfo=UTC))
        )
    sessions.kw["bind"].dispose()
    today = datetime.now(UTC).strftime("%Y-%m-%d")
    assert listed(db_url) == [1, 2, 3]
    assert listed(db_url, "--stand", "S1") == [1, 3]
    assert listed(db_url, "--tag", "factory=A", "--stand", "S1") == [1]
    assert listed(db_url, "--status", "completed") == [1, 2]
    assert listed(db_url, "--model", "gyrocompass", "--serial", "nope") == []
    assert listed(db_url, "--since", today) == [1, 2]
    assert listed(db_url, "--until", "2025-06-30") == [3]
    assert listed(db_url, "--since", "2025-07-01", "--until", today) == [1, 2]
    tomorrow = (datetime.now(UTC) + timedelta(days=1)).strftime("%Y-%m-%d")
    assert listed(db_url, "--since", tomorrow) == []
    (first,) = json.loads(gyrostand("campaign", "list", "--json", "--db", db_url, "--stand", "S2"))[
        "campaigns"
    ]
    assert first["labels"] == {"factory": "A", "stand": "S2"}
    assert first["source"] == "import" and first["observations"] == 0  # per-trial table
    assert datetime.fromisoformat(first["started_at"]).tzinfo is not None
    text = gyrostand("campaign", "list", "--db", db_url, "--tag", "factory=A")
    assert "factory=A stand=S1" in text and "factory=A stand=S2" in text
    assert text.rstrip().endswith("2 campaigns")


def station_rows(client: TestClient, text: str) -> list[tuple[int, str]]:
    """(id, verdict) of each line of the station's campaigns page for the filter `text`."""
    page = client.get("/", params={"q": text}).text
    return [
        (int(row[1]), re.findall(r"<td>(.*?)</td>", row[0], re.S)[6])
        for row in re.finditer(r'<tr><td><a href="/campaigns/(\d+)">.*?</tr>', page, re.S)
    ]


def listed_alike(db: str, client: TestClient, text: str = "") -> list[tuple[int, str]]:
    """(id, verdict) of the campaigns `campaign list --json --text` lists, by id, having checked
    that the station's page lists the same, newest first."""
    document = json.loads(gyrostand("campaign", "list", "--json", "--db", db, "--text", text))
    rows = [(c["id"], c["verdict"]) for c in document["campaigns"]]
    assert station_rows(client, text) == rows[::-1]
    return rows


def test_text_and_latest_verdict_alike_in_json_and_station(db_url: str, tmp_path: Path) -> None:
    gyrostand("import", PAPER_CSV, "--db", db_url, "--operator", "Ann Smith")
    gyrostand("import", PAPER_CSV, "--db", db_url, "--operator", "bob_jones", "--tag", "lot=7")
    # the paper: Cochran passes, Fisher's test on the trial means (the decision basis) fails
    gyrostand("analyze", "1", "--db", db_url)
    sessions = open_database(db_url)
    client = TestClient(
        create_app(
            db_url,
            sessions,
            Access.for_host("127.0.0.1", None, ["testserver"]),
            tmp_path / "reports",
        )
    )
    first = (1, "homogeneous yes, adequate on trial means no")
    never = (2, "not analysed")
    assert listed_alike(db_url, client) == [first, never]
    assert listed_alike(db_url, client, "SMITH") == [first]  # operator, any case
    assert listed_alike(db_url, client, "potemkin-1982") == [first, never]  # serial
    assert listed_alike(db_url, client, "Two-Rotor") == [first, never]  # model
    assert listed_alike(db_url, client, "_") == [never]  # no wildcard: bob_jones only
    assert listed_alike(db_url, client, "%") == []
    with sessions.begin() as session:  # analysed again, with another outcome
        session.add(
            AnalysisRun(
                campaign_id=1,
                inputs_hash="1" * 64,
                results_json={"cochran": {"homogeneous": False}, "adequacy": {}},
                software_version="test",
            )
        )
    assert listed_alike(db_url, client) == [(1, "homogeneous no, adequate on trial means ?"), never]
    assert "<td>lot=7</td>" in client.get("/").text
    text = gyrostand("campaign", "list", "--db", db_url, "--text", "smith")
    assert "  0    homogeneous no, adequate on trial means ?" in text and text.rstrip().endswith(
        "1 campaign"
    )
    sessions.kw["bind"].dispose()
