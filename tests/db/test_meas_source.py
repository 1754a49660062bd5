"""Migration 0015: a trial's measured motion is flagged by its source; every trial measured
before came from the stand controller's own reports."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from alembic import command
from sqlalchemy import create_engine

from gyrostand.db.session import alembic_config, open_database, sqlite_url
from tests.db.conftest import make_campaign


def _downgrade(db_path: Path, revision: str) -> None:
    engine = create_engine(sqlite_url(db_path))
    config = alembic_config()
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, revision)
    engine.dispose()


def test_0015_flags_earlier_measured_motion_as_the_stands_report(tmp_path: Path) -> None:
    db_path = tmp_path / "m.sqlite"
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        campaign = make_campaign(session, n_trials=2)
        campaign.trials[0].meas_amplitude_cm = 24.1  # measured; the other one not
    _downgrade(db_path, "0010")
    open_database(sqlite_url(db_path))  # upgrades to head
    with sqlite3.connect(db_path) as conn:
        rows = conn.execute('SELECT "index", meas_source FROM trial ORDER BY "index"').fetchall()
    assert rows == [(1, "stand report"), (2, None)]
    _downgrade(db_path, "0010")
    with sqlite3.connect(db_path) as conn:
        assert conn.execute("SELECT count(*) FROM trial").fetchone() == (2,)
