"""The station's child processes get the database in GYROSTAND_DB, never in their arguments
(`ps` shows every process's arguments: a PostgreSQL URL's password would be readable by every
user of the machine), and the commands' --db default reads it."""

import json
import sys
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.io import SEED_000_METADATA, import_file
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.db.url import DB_ENV
from gyrostand.station.processes import Processes

URL = "postgresql+psycopg://lab:s3cret-pw@db.example/lab"
PAPER_CSV = Path(__file__).resolve().parents[2] / "examples" / "paper.csv"


def recorder(out: Path) -> list[str]:
    """A stand-in for `python -m gyrostand` that writes down its argv and its database."""
    script = (
        "import json, os, sys; "
        f"open({str(out)!r}, 'w').write(json.dumps([sys.argv, os.environ.get({DB_ENV!r})]))"
    )
    return [sys.executable, "-c", script]


def test_the_station_hands_the_database_over_in_the_environment(tmp_path: Path) -> None:
    acquisition, report = tmp_path / "acquisition.json", tmp_path / "report.json"
    processes = Processes(URL, recorder(acquisition))
    processes.resume(3)
    assert processes.acquisitions[3].process.wait() == 0
    reports = Processes(URL, recorder(report))
    reports.report(3, tmp_path, "html")
    assert reports.reports[3].process.process.wait() == 0
    for out, args in (
        (acquisition, ["campaign", "resume", "3", "--quiet"]),
        (report, ["report", "3", "--out", str(tmp_path), "--format", "html"]),
    ):
        argv, db = json.loads(out.read_text())
        assert argv[1:] == args and db == URL  # no --db URL among the arguments


def test_the_db_option_defaults_to_the_environment(tmp_path: Path) -> None:
    path = tmp_path / "lab.sqlite"
    metadata = {**SEED_000_METADATA, "software_version": "test"}
    import_file(open_database(sqlite_url(path)), PAPER_CSV, metadata)
    result = CliRunner().invoke(app, ["campaign", "list", "--json"], env={DB_ENV: str(path)})
    assert result.exit_code == 0, result.stderr
    assert [c["id"] for c in json.loads(result.stdout)["campaigns"]] == [1]
    missing = CliRunner().invoke(
        app, ["campaign", "list"], env={DB_ENV: str(tmp_path / "none.sqlite")}
    )
    assert missing.exit_code != 0 and "none.sqlite" in missing.stderr
