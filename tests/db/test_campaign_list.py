"""`gyrostand campaign list`: the filters (model, serial, stand, status, day, labels) in text
and JSON, on both database back ends."""

import json
from datetime import UTC, datetime, timedelta

from sqlalchemy import update
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import Campaign
from gyrostand.db.session import open_database
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
