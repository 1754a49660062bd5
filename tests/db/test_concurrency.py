"""Two stands, one lab database (a SQLite file in WAL mode, and PostgreSQL): two `campaign run`
processes at once both complete, nothing lost or duplicated, nothing "database is locked"; then
the lab's read side on the same database: `campaign list` by stand, `analyze` and `report`."""

import json
from pathlib import Path

from sqlalchemy import create_engine, text
from typer.testing import CliRunner

from gyrostand.cli import app
from tests.db.conftest import run_stands_at_once


def test_two_campaigns_into_one_database_at_once(tmp_path: Path, db_url: str) -> None:
    errors = run_stands_at_once(tmp_path, [db_url, db_url])
    assert not [err for err in errors if "locked" in err]
    engine = create_engine(db_url)
    with engine.connect() as conn:
        campaigns = conn.execute(text("SELECT id, status FROM campaign ORDER BY id")).all()
        counts = conn.execute(
            text(
                "SELECT t.campaign_id, count(*), count(DISTINCT s.id || '-' || o.k)"
                " FROM observation o JOIN series s ON s.id = o.series_id"
                " JOIN trial t ON t.id = s.trial_id GROUP BY t.campaign_id ORDER BY 1"
            )
        ).all()
    engine.dispose()
    assert [tuple(c) for c in campaigns] == [(1, "completed"), (2, "completed")]
    # 3 trials x 2 series x N = 3 observations each, none duplicated
    assert [tuple(c) for c in counts] == [(1, 18, 18), (2, 18, 18)]
    cli = CliRunner()
    listed = cli.invoke(app, ["campaign", "list", "--stand", "S2", "--json", "--db", db_url])
    assert listed.exit_code == 0, listed.output
    (row,) = json.loads(listed.output)["campaigns"]
    assert (row["labels"], row["observations"], row["status"]) == ({"stand": "S2"}, 18, "completed")
    campaign = str(row["id"])  # (which stand stored its campaign first is a race)
    analysed = cli.invoke(app, ["analyze", campaign, "--json", "--db", db_url])
    assert analysed.exit_code == 0, analysed.output
    fit = json.loads(analysed.stdout)["fit"]
    assert fit["converged"] and fit["trial_indices"] == [1, 2, 3]
    out = tmp_path / "reports"
    args = ["report", campaign, "--db", db_url, "--out", str(out), "--format", "json,html"]
    reported = cli.invoke(app, args)
    assert reported.exit_code == 0, reported.output
    document = json.loads((out / f"campaign-{campaign}.json").read_text())
    assert document["analysis"]["fit"]["estimates"] == fit["estimates"]
    assert "SIMULATION" in (out / f"campaign-{campaign}.html").read_text()
