"""Costly test artefacts (a whole campaign's database) built once per test session, not once per
pytest-xdist worker, and private copies of SQLite databases for the tests that write to them."""

from __future__ import annotations

import fcntl
import os
import shutil
import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest


def built_once(
    tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], None]
) -> Path:
    """The folder `name`, filled by `build(folder)` once in the whole test session: under
    pytest-xdist the first worker to ask builds it while holding a lock and the others wait for
    it, then use it (the recipe of pytest-xdist's documentation, "Making session-scoped fixtures
    execute only once"). Tests read it; they write to copies."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above every worker's own
    folder = root / name
    with (root / f"{name}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, even on a failure
        if not (folder / ".built").exists():  # (a build that failed left no mark: built anew)
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            build(folder)
            (folder / ".built").touch()
    return folder


def copy_database(source: Path, target: Path) -> Path:
    """`target`: a copy of the SQLite database `source` with what is still in its write-ahead
    log (SQLite's online backup)."""
    with sqlite3.connect(source) as src, sqlite3.connect(target) as dst:
        src.backup(dst)
    src.close()
    dst.close()
    return target
