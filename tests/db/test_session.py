"""Opening databases: pragmas, schema creation, version refusal and upgrade via Alembic."""

import json
import shutil
import sqlite3
import sys
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine, text
from sqlalchemy.orm import Session, sessionmaker
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.models import Base, Event, Observation
from gyrostand.db.session import (
    MIGRATIONS_DIR,
    SCHEMA_HEAD,
    DatabaseVersionError,
    _configure_sqlite,
    alembic_config,
    current_revisions,
    database_url,
    migrate,
    open_database,
    sqlite_url,
)
from tests.db.conftest import make_campaign
from tests.postgres import Server

HEAD = ScriptDirectory.from_config(alembic_config()).get_current_head()
NEXT = f"{int(HEAD) + 1:04d}"  # a future release's revision


def version_of(path: Path) -> list[str]:
    with sqlite3.connect(path) as conn:
        return [row[0] for row in conn.execute("SELECT version_num FROM alembic_version")]


def test_pragmas_are_set_on_every_connection(sessions: sessionmaker[Session]) -> None:
    for _ in range(2):
        with sessions() as session:
            assert session.execute(text("PRAGMA journal_mode")).scalar() == "wal"
            assert session.execute(text("PRAGMA foreign_keys")).scalar() == 1
            assert session.execute(text("PRAGMA busy_timeout")).scalar() == 10_000
            assert session.execute(text("PRAGMA synchronous")).scalar() == 2  # FULL


def test_empty_file_is_created_at_head(db_path: Path) -> None:
    assert not db_path.parent.exists()
    open_database(sqlite_url(db_path))
    assert version_of(db_path) == [HEAD]
    with sqlite3.connect(db_path) as conn:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert {"instrument", "campaign", "trial", "series", "observation", "event"} <= tables
    assert "analysis_run" in tables


def test_orm_metadata_matches_the_migrations(sessions: sessionmaker[Session]) -> None:
    with sessions() as session:
        context = MigrationContext.configure(session.connection(), opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []


def test_the_schema_head_constant_is_the_latest_migration() -> None:
    """`SCHEMA_HEAD` (opening a current database reads no migration file): a new migration in
    db/migrations/versions changes it."""
    assert ScriptDirectory.from_config(alembic_config()).get_heads() == [SCHEMA_HEAD]


def test_current_revisions_read_as_alembic_reads_them(tmp_path: Path) -> None:
    engine = create_engine(sqlite_url(tmp_path / "v.sqlite"))
    with engine.begin() as connection:
        assert current_revisions(connection) == set()
        assert MigrationContext.configure(connection).get_current_heads() == ()
    migrate(engine, upgrade=True)
    with engine.begin() as connection:
        alembic_reads = MigrationContext.configure(connection).get_current_heads()
        assert current_revisions(connection) == set(alembic_reads) == {HEAD}
    engine.dispose()


def test_without_upgrade_a_missing_or_empty_database_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DatabaseVersionError, match="no database at"):
        open_database(sqlite_url(tmp_path / "none.sqlite"), upgrade=False)
    assert not (tmp_path / "none.sqlite").exists()
    sqlite3.connect(tmp_path / "empty.sqlite").close()
    with pytest.raises(DatabaseVersionError, match=f"is empty; schema {HEAD} is needed"):
        open_database(sqlite_url(tmp_path / "empty.sqlite"), upgrade=False)


def test_unversioned_database_is_refused_and_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "foreign.sqlite"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE notes (x)")
    before = path.read_bytes()
    with pytest.raises(DatabaseVersionError, match=r"has tables \(notes\) but no schema version"):
        open_database(sqlite_url(path))
    assert path.read_bytes() == before


def test_database_ahead_of_the_code_is_refused(db_path: Path) -> None:
    open_database(sqlite_url(db_path))
    with sqlite3.connect(db_path) as conn:
        conn.execute("UPDATE alembic_version SET version_num = '9999'")
    with pytest.raises(DatabaseVersionError, match="schema version 9999, newer than this"):
        open_database(sqlite_url(db_path))
    assert version_of(db_path) == ["9999"]


SECOND_REVISION = f'''"""Test-only revision: adds a table."""
import sqlalchemy as sa
from alembic import op

revision = "{NEXT}"
down_revision = "{HEAD}"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table("probe", sa.Column("id", sa.Integer(), primary_key=True))


def downgrade() -> None:
    op.drop_table("probe")
'''


@pytest.fixture
def newer_migrations(tmp_path: Path) -> Path:
    """A copy of the shipped migrations plus a second revision, as a future release would have."""
    location = tmp_path / "migrations"
    shutil.copytree(MIGRATIONS_DIR, location, ignore=shutil.ignore_patterns("__pycache__"))
    (location / "versions" / f"{NEXT}_probe.py").write_text(SECOND_REVISION)
    return location


def test_older_database_is_upgraded_on_open(db_path: Path, newer_migrations: Path) -> None:
    open_database(sqlite_url(db_path))  # written by "this" release, at HEAD
    engine = create_engine(sqlite_url(db_path))
    with pytest.raises(
        DatabaseVersionError, match=f"has old schema {HEAD}; schema {NEXT} is needed"
    ):
        migrate(engine, upgrade=False, script_location=newer_migrations)
    assert version_of(db_path) == [HEAD]
    migrate(engine, upgrade=True, script_location=newer_migrations)
    engine.dispose()
    assert version_of(db_path) == [NEXT]
    with sqlite3.connect(db_path) as conn:
        assert conn.execute("SELECT count(*) FROM probe").fetchone() == (0,)
    # and the released code (which only knows up to HEAD) now refuses the upgraded file
    with pytest.raises(DatabaseVersionError, match=f"{NEXT}, newer than this gyrostand"):
        open_database(sqlite_url(db_path))


def test_failed_migration_leaves_the_database_unchanged(
    db_path: Path, newer_migrations: Path
) -> None:
    open_database(sqlite_url(db_path))
    broken = SECOND_REVISION.replace(
        'op.create_table("probe", sa.Column("id", sa.Integer(), primary_key=True))',
        'op.create_table("probe", sa.Column("id", sa.Integer(), primary_key=True))\n'
        '    op.execute("SELECT no_such_function()")',
    )
    (newer_migrations / "versions" / f"{NEXT}_probe.py").write_text(broken)
    engine = create_engine(sqlite_url(db_path))
    _configure_sqlite(engine)
    with pytest.raises(Exception, match="no_such_function"):
        migrate(engine, upgrade=True, script_location=newer_migrations)
    engine.dispose()
    assert version_of(db_path) == [HEAD]
    with sqlite3.connect(db_path) as conn:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert "probe" not in tables


def test_database_url_accepts_paths_and_urls(tmp_path: Path) -> None:
    assert database_url("postgresql+psycopg://lab/gyro") == "postgresql+psycopg://lab/gyro"
    assert database_url(str(tmp_path / "a.sqlite")) == f"sqlite:///{tmp_path / 'a.sqlite'}"


def test_0002_fills_settle_outcomes_from_0001_event_text(db_path: Path) -> None:
    """A 0.1.0 database (schema 0001) told an early settle only in event text: the upgrade to
    0002 turns that text into the series' structured outcome, and band settles into theirs."""
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        campaign = make_campaign(session, n_trials=1)
        early, band = campaign.trials[0].series
        for s, done in ((early, 61_000), (band, 1_801_000)):
            s.settle_started_ms, s.settle_done_ms, s.settle_estimate_deg = 1_000, done, 120.5
        message = (
            "settled by the estimate after 60.0 s: settle point 120.50000 deg (SE 0.00310 deg, "
            "stable since 45.0 s at 120.49000 deg, last estimates within 0.00100 deg, predicted "
            "transient over the observations 0.00200 deg; tolerance 0.00500 deg); band criterion "
            "predicted after 900.0 s: 840.0 s saved"
        )
        session.add(Event(campaign=campaign, series_id=early.id, kind="early settle",
                          severity="info", message=message))  # fmt: skip
        ids = early.id, band.id
    engine = create_engine(sqlite_url(db_path))
    config = alembic_config()
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, "0001")
        assert connection.execute(text("SELECT count(*) FROM series")).scalar() == 2
    engine.dispose()
    assert version_of(db_path) == ["0001"]
    open_database(sqlite_url(db_path))  # upgrades to head
    with sqlite3.connect(db_path) as conn:
        rows = dict(conn.execute("SELECT id, settle_outcome FROM series"))
    assert json.loads(rows[ids[0]]) == {
        "criterion": "estimate", "settle_s": 60.0, "estimate_deg": 120.5,
        "standard_error_deg": 0.0031, "stable_since_s": 45.0, "stable_estimate_deg": 120.49,
        "band_s": 900.0, "band_measured": False,
    }  # fmt: skip
    assert json.loads(rows[ids[1]]) == {
        "criterion": "band", "settle_s": 1800.0, "estimate_deg": 120.5,
        "standard_error_deg": None, "stable_since_s": None, "stable_estimate_deg": None,
        "band_s": 1800.0, "band_measured": True,
    }  # fmt: skip


def test_0003_moves_the_raw_log_into_segments_and_keeps_every_row(db_path: Path) -> None:
    """0003 copies the campaign table (it drops two columns): with SQLite's foreign keys on,
    dropping the old copy would have deleted every trial, series and observation (cascade)."""
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        campaign = make_campaign(session, n_trials=2)
        for series in campaign.trials[1].series:
            series.observations = [Observation(k=k, value_deg=1.0) for k in (1, 2)]
    engine = create_engine(sqlite_url(db_path))
    config = alembic_config()
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, "0002")
        connection.execute(
            text("UPDATE campaign SET raw_log_path = '/x/campaign-1.blf', raw_log_sha256 = :h"),
            {"h": "ab" * 32},
        )
    engine.dispose()
    with sqlite3.connect(db_path) as conn:
        before = {t: conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0]
                  for t in ("trial", "series", "observation")}  # fmt: skip
    assert before == {"trial": 2, "series": 4, "observation": 4}
    open_database(sqlite_url(db_path))  # upgrades to head
    with sqlite3.connect(db_path) as conn:
        after = {t: conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in before}
        segments = conn.execute(
            "SELECT campaign_id, seq, path, start, first_frame, sha256, ending FROM raw_log_segment"
        ).fetchall()
        engine_writes = conn.execute("SELECT engine_writes FROM campaign").fetchone()
    assert after == before
    assert segments == [(1, 1, "/x/campaign-1.blf", "new", 0, "ab" * 32, "closed")]
    assert engine_writes == (0,)


def test_0010_states_the_heading_source_of_earlier_campaigns(db_path: Path) -> None:
    """Campaigns acquired before 0010 read gyrostand's heading frame and its stand clock; an
    import has no heading source. The downgrade keeps every row."""
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        make_campaign(session, n_trials=2)
        make_campaign(session, n_trials=1).source = "import"
    engine = create_engine(sqlite_url(db_path))
    config = alembic_config()
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, "0008")
    engine.dispose()
    open_database(sqlite_url(db_path))  # upgrades to head
    query = "SELECT id, heading_source, heading_time_base, heading_resolution_deg FROM campaign"
    with sqlite3.connect(db_path) as conn:
        rows = conn.execute(query).fetchall()
    base = "stand clock carried in every heading frame"
    assert rows == [(1, "gyrostand", base, None), (2, None, None, None)]
    engine = create_engine(sqlite_url(db_path))
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.downgrade(config, "0008")
    engine.dispose()
    with sqlite3.connect(db_path) as conn:
        assert conn.execute("SELECT count(*) FROM trial").fetchone() == (3,)


@pytest.mark.parametrize(
    "url", ["postgresql+psycopg://lab@/lab?host=/run/postgresql", "postgresql://lab@/lab"]
)
def test_a_missing_postgresql_driver_names_the_install(
    url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before: "the database driver for postgresql+psycopg is not installed (...)", no more."""
    monkeypatch.setitem(sys.modules, "psycopg", None)  # `import psycopg` fails, as uninstalled
    result = CliRunner().invoke(app, ["campaign", "list", "--db", url])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.stderr.startswith(f"gyrostand: error: {url}: the database driver for ")
    assert result.stderr.rstrip().endswith(
        "is not installed (import of psycopg halted; None in sys.modules); gyrostand's "
        "PostgreSQL driver is psycopg: pip install 'gyrostand[postgres]' and give a "
        "postgresql+psycopg:// URL"
    )


def test_a_missing_postgresql_database_says_to_create_it(postgres_server: Server) -> None:
    url = postgres_server.url("nosuchlab")
    result = CliRunner().invoke(app, ["campaign", "list", "--db", url])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert 'FATAL:  database "nosuchlab" does not exist; gyrostand makes its tables, not the ' in (
        result.stderr
    )
    assert result.stderr.rstrip().endswith(
        "create it first (createdb nosuchlab, as a role allowed to)"
    )
