"""Shared by the CLI tests: one tiny campaign run on the simulated stand (its plan, database and
raw log), and helpers to compare a database's bytes before and after a command."""

from __future__ import annotations

import gc
import shutil
import sqlite3
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.acquisition.harness import FAST_SIM, plan_text
from tests.artefacts import built_once


def write_plan(folder: Path, name: str = "plan.toml", **kw: object) -> Path:
    """A two-trial plan (N = 3) on a quickly settling simulated stand, in virtual time."""
    kw.setdefault("database", str(folder / "db.sqlite"))
    kw.setdefault("raw_dir", str(folder / "raw"))
    path = folder / name
    path.write_text(plan_text(**kw) + FAST_SIM)  # type: ignore[arg-type]
    return path


@dataclass(frozen=True)
class Stand:
    """A completed campaign 1: its plan, database and raw CAN log (BLF)."""

    plan: Path
    db: Path
    blf: Path

    def db_copy(self, folder: Path) -> Path:
        """A private copy of the database (commands under test may not touch the shared one)."""
        copy = folder / "copy.sqlite"
        shutil.copyfile(self.db, copy)
        return copy


def run_campaign_1(folder: Path) -> None:
    plan = write_plan(folder)
    # in a process of its own: its exit closes the database, so the file holds everything
    # (no write-ahead log left over) and copies of it are whole
    proc = subprocess.run(
        [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan), "--quiet"],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert not (folder / "db.sqlite-wal").exists()


@pytest.fixture(scope="session")
def stand(tmp_path_factory: pytest.TempPathFactory) -> Stand:
    """Campaign 1, run once for all the session's workers, in a folder of this worker's own (the
    plan's database and raw log folder are there: a command run on the plan writes nowhere
    another worker reads)."""
    built = built_once(tmp_path_factory, "stand", run_campaign_1)
    folder = tmp_path_factory.mktemp("stand")
    plan = folder / "plan.toml"
    plan.write_text((built / "plan.toml").read_text().replace(str(built), str(folder)))
    shutil.copyfile(built / "db.sqlite", folder / "db.sqlite")
    shutil.copytree(built / "raw", folder / "raw")
    return Stand(plan, folder / "db.sqlite", folder / "raw" / "db-campaign-1.blf")


def db_state(db: Path) -> tuple[bytes, bytes] | None:
    """The database file's bytes and its write-ahead log's (None when there is no database): a
    command that wrote anything changes one of them, even before a checkpoint."""
    if not db.exists():
        return None
    wal = db.with_name(db.name + "-wal")
    return db.read_bytes(), wal.read_bytes() if wal.exists() else b""


def checkpointed(db: Path) -> Path:
    """`db` with everything committed moved from its write-ahead log into the file, so that a
    later checkpoint (when this process closes a connection) does not change its bytes."""
    gc.collect()  # engines of earlier in-process commands close their connections
    connection = sqlite3.connect(db)
    try:
        busy, _, _ = connection.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
        assert not busy
    finally:
        connection.close()
    return db
