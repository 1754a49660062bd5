"""`gyrostand db merge` given what it cannot merge: no file, a file that is no SQLite database,
no gyrostand database, an empty one, one of an older schema (`db upgrade` brings it up, then it
merges), a bad lab URL, the lab itself. One line each, nothing changed."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import create_engine

from gyrostand.db.session import alembic_config, schema_heads, sqlite_url

from .cases import Case, check, folder, ids, invoke, text_file
from .conftest import Stand

(HEAD,) = schema_heads()


def foreign_sqlite(_stand: Stand, tmp: Path) -> Path:
    """A SQLite database of another program."""
    path = tmp / "other.sqlite"
    with sqlite3.connect(path) as connection:
        connection.execute("CREATE TABLE things (id INTEGER PRIMARY KEY)")
    connection.close()
    return path


def schema_0007(_stand: Stand, tmp: Path) -> Path:
    """A gyrostand database of schema 0007 (before the merge's table)."""
    path = tmp / "old.sqlite"
    engine = create_engine(sqlite_url(path))
    config = alembic_config()
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.upgrade(config, "0007")
    engine.dispose()
    return path


CASES = [
    Case("missing", ("db", "merge", "{tmp}/none.sqlite", "--into", "{db}"), "no database at"),
    Case(
        "not sqlite",
        ("db", "merge", "{file}", "--into", "{db}"),
        "is not a SQLite database or is damaged",
        make=text_file("stand.sqlite", b"not a database, " * 512),
    ),
    Case(
        "folder",
        ("db", "merge", "{file}", "--into", "{db}"),
        "is a folder, not a database file",
        make=folder("stand.sqlite"),
    ),
    Case(
        "not gyrostand",
        ("db", "merge", "{file}", "--into", "{db}"),
        "has tables (things) but no schema version: it was not created by gyrostand",
        make=foreign_sqlite,
    ),
    Case(
        "empty",
        ("db", "merge", "{file}", "--into", "{db}"),
        "is an empty database, not a stand's gyrostand database",
        make=text_file("empty.sqlite", b""),
    ),
    Case(
        "old schema",
        ("db", "merge", "{file}", "--into", "{db}"),
        f"has schema 0007, the lab {HEAD}: upgrade it first with `gyrostand db upgrade ",
        make=schema_0007,
    ),
    Case(
        "bad lab url",
        ("db", "merge", "{db}", "--into", "nosuchdialect://host/lab"),
        "unknown database dialect 'nosuchdialect'",
    ),
    Case("lab itself", ("db", "merge", "{db}", "--into", "{db}"), "is the lab database itself", 1),
]


@pytest.mark.parametrize("case", CASES, ids=ids(CASES))
def test_what_cannot_be_merged_is_one_line(case: Case, stand: Stand, tmp_path: Path) -> None:
    check(case, stand, tmp_path, stand.db_copy(tmp_path))


def test_old_stand_database_merges_once_upgraded(stand: Stand, tmp_path: Path) -> None:
    old = schema_0007(stand, tmp_path)
    code, out, err = invoke("db", "upgrade", str(old))
    assert (code, out, err) == (0, f"{old}: schema {HEAD}\n", "")
    code, out, _ = invoke("db", "merge", str(old), "--into", str(tmp_path / "lab.sqlite"))
    assert (code, out) == (0, "0 merged, 0 replaced, 0 already merged, 0 skipped\n")
