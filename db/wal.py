"""A SQLite file in WAL mode keeps recent commits in FILE-wal beside it until a checkpoint copies
them into FILE: a copy of FILE alone lacks them. So every writer checkpoints when it finishes a
campaign and every process at its clean exit (`checkpoint`, `checkpoint_at_exit`), and a copy may
be taken while no gyrostand process has the file open; `unmerged_wal` tells when FILE-wal still
holds commits (a process has the file open, or one ended without closing it)."""

from __future__ import annotations

import atexit
import sqlite3
import weakref
from pathlib import Path

from sqlalchemy import Engine
from sqlalchemy.exc import DBAPIError

_OPEN: weakref.WeakSet[Engine] = weakref.WeakSet()


def _file(engine: Engine) -> Path | None:
    """The SQLite file of `engine` (None: another backend, or an in-memory database)."""
    database = engine.url.database
    if engine.dialect.name != "sqlite" or not database or database == ":memory:":
        return None
    return Path(database)


def checkpoint(engine: Engine) -> bool:
    """Copy the write-ahead log into the file and empty it (`PRAGMA wal_checkpoint(TRUNCATE)`):
    the file alone then holds every commit. False when another process's reader or writer kept
    it from completing, or the file refused it (a full disk: the commits stay in the log, where
    SQLite reads them); True for other backends."""
    path = _file(engine)
    if path is None or not path.exists():
        return True
    try:
        raw = engine.raw_connection()  # outside any transaction (a checkpoint cannot run in one)
        try:
            busy, _, _ = raw.driver_connection.execute(  # type: ignore[union-attr]
                "PRAGMA wal_checkpoint(TRUNCATE)"
            ).fetchone()
        finally:
            raw.close()
    except (DBAPIError, sqlite3.Error):
        return False
    return busy == 0


def checkpoint_at_exit(engine: Engine) -> None:
    """Checkpoint `engine`'s file when the process exits normally (SIGTERM included where it is
    turned into an exit: `campaign run`, the station), as long as the engine is in use."""
    if _file(engine) is not None:
        _OPEN.add(engine)


@atexit.register
def _at_exit() -> None:
    for engine in list(_OPEN):
        checkpoint(engine)
        engine.dispose()


def unmerged_wal(path: Path) -> int:
    """Bytes of PATH-wal beside the SQLite file `path` (0: none, or empty)."""
    wal = path.with_name(path.name + "-wal")
    try:
        return wal.stat().st_size
    except OSError:
        return 0
