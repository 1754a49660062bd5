"""Raw logs are named for their database (DB-campaign-ID.blf): databases sharing a raw log folder
never share a name, whatever their campaign ids; a resume continues its first run's name; the
live file a killed run leaves is removed when the campaign is resumed."""

from __future__ import annotations

import os
import signal
import sqlite3
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.merge import database_identity
from gyrostand.db.session import open_database, sqlite_url

from .harness import FAST_SIM, plan_text
from .test_cli_campaign import start, wait_for_observations


def campaign(*args: str) -> None:
    result = CliRunner().invoke(app, ["campaign", *args, "--quiet"])
    assert result.exit_code == 0, result.stderr


def segments(db: Path) -> list[str]:
    with sqlite3.connect(db) as conn:
        rows = conn.execute("SELECT path FROM raw_log_segment ORDER BY seq").fetchall()
    return [Path(path).name for (path,) in rows]


def write_plan(folder: Path, db: Path, raw: Path, name: str = "plan.toml") -> Path:
    plan = folder / name
    plan.write_text(plan_text(database=str(db), raw_dir=str(raw)) + FAST_SIM)
    return plan


def test_databases_sharing_a_raw_folder_never_share_a_log_name(tmp_path: Path) -> None:
    raw = tmp_path / "raw"
    other = tmp_path / "elsewhere"
    other.mkdir()
    dbs = [tmp_path / "a.sqlite", tmp_path / "b.sqlite", other / "a.sqlite"]
    for n, db in enumerate(dbs):  # each database's campaign 1
        plan = write_plan(tmp_path, db, raw, f"plan-{n}.toml")
        campaign("run", str(plan))
    a, b, elsewhere = (segments(db) for db in dbs)
    assert a == ["a-campaign-1.blf"] and b == ["b-campaign-1.blf"]
    # a database of the same name elsewhere, writing into the same folder: its identity too
    sessions = open_database(sqlite_url(dbs[2]))
    with sessions() as session:
        identity = database_identity(session)
    sessions.kw["bind"].dispose()
    assert identity is not None
    ((name,),) = [elsewhere]
    assert name == f"a-{identity[:8]}-campaign-1.blf"
    assert sorted(p.name for p in raw.iterdir()) == sorted([*a, *b, name])
    result = CliRunner().invoke(
        app,
        [
            "replay",
            str(raw / b[0]),
            "--plan",
            str(tmp_path / "plan-1.toml"),
            "--db",
            str(tmp_path / "replay.sqlite"),
        ],
    )
    assert result.exit_code == 0, result.stderr


def test_a_killed_runs_live_file_goes_when_the_campaign_is_resumed(tmp_path: Path) -> None:
    db, raw = tmp_path / "db.sqlite", tmp_path / "raw"
    plan = write_plan(tmp_path, db, raw)
    proc = start("campaign", "run", str(plan), "--quiet", cwd=tmp_path)
    wait_for_observations(db, 2, proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert [p.name for p in raw.glob("*.live.json")] == ["db-campaign-1.live.json"]
    campaign("resume", "1", "--db", str(db))
    assert segments(db) == ["db-campaign-1.blf", "db-campaign-1-resume1.blf"]
    assert list(raw.glob("*.live.json")) == []
