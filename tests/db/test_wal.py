"""A SQLite file in WAL mode holds its latest commits in FILE-wal until a checkpoint: a campaign
writer checkpoints when it finishes, and the station at its exit (SIGTERM included), so that a
copy of FILE alone holds every campaign; `db merge` warns about a FILE-wal that still holds
commits (a copy without it would lack them)."""

from __future__ import annotations

import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.cli import app
from tests.acquisition.harness import FAST_SIM, plan_text

ROOT = Path(__file__).resolve().parents[2]


def wal_size(db: Path) -> int:
    wal = db.with_name(db.name + "-wal")
    return wal.stat().st_size if wal.exists() else 0


def campaigns_in_copy(db: Path, folder: Path) -> int:
    """How many campaigns a copy of `db` alone (without its -wal and -shm) holds."""
    folder.mkdir(exist_ok=True)
    copy = folder / "copy.sqlite"
    shutil.copyfile(db, copy)
    with sqlite3.connect(copy) as conn:
        return conn.execute("SELECT count(*) FROM campaign").fetchone()[0]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_campaign_end_and_station_sigterm_leave_the_file_whole(tmp_path: Path) -> None:
    db = tmp_path / "db.sqlite"
    plan = tmp_path / "plan.toml"
    plan.write_text(plan_text(database=str(db), raw_dir=str(tmp_path / "raw")) + FAST_SIM)
    station = subprocess.Popen(
        [sys.executable, "-m", "gyrostand", "station", "--db", str(db), "--port", str(free_port())],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while "open http" not in (line := station.stderr.readline()):  # serving: db open
            assert line and time.monotonic() < deadline, "the station did not start"
        for n in (1, 2):  # while the station has the file open (no writer is its last user)
            result = CliRunner().invoke(app, ["campaign", "run", str(plan), "--quiet"])
            assert result.exit_code == 0, result.stderr
            assert campaigns_in_copy(db, tmp_path / "copy") == n
        assert wal_size(db) == 0  # checkpointed (TRUNCATE) by the campaign's writer
        with sqlite3.connect(db) as conn:  # a write of another program, left in the WAL
            conn.execute("PRAGMA wal_autocheckpoint=0")
            conn.execute("UPDATE campaign SET operator = 'changed' WHERE id = 2")
        assert wal_size(db) > 0
    finally:
        station.send_signal(signal.SIGTERM)
        station.wait(timeout=60)
    assert station.returncode == 143  # SIGTERM as an exit: its exit handlers ran
    assert wal_size(db) == 0
    copy = tmp_path / "copy"
    assert campaigns_in_copy(db, copy) == 2
    with sqlite3.connect(copy / "copy.sqlite") as conn:
        assert conn.execute("SELECT operator FROM campaign WHERE id = 2").fetchone() == ("changed",)


def test_db_merge_warns_of_a_wal_holding_commits(tmp_path: Path) -> None:
    stand, lab = tmp_path / "stand.sqlite", tmp_path / "lab.sqlite"
    plan = tmp_path / "plan.toml"
    plan.write_text(plan_text(database=str(stand), raw_dir=str(tmp_path / "raw")) + FAST_SIM)
    result = CliRunner().invoke(app, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 0, result.stderr
    holder = sqlite3.connect(stand)  # a process that has the file open and wrote
    try:
        holder.execute("PRAGMA wal_autocheckpoint=0")
        with holder:
            holder.execute("UPDATE campaign SET operator = 'latest' WHERE id = 1")
        size = wal_size(stand)
        assert size > 0
        result = CliRunner().invoke(app, ["db", "merge", str(stand), "--into", str(lab)])
    finally:
        holder.close()
    assert result.exit_code == 0, result.stderr
    assert result.stderr.splitlines() == [
        f"gyrostand: warning: {stand}-wal beside it holds {size} bytes of its write-ahead log "
        "(a process has it open, or one ended without closing it): merged from there, but a "
        "copy of stand.sqlite without its -wal would lack the latest commits"
    ]
    with sqlite3.connect(lab) as conn:  # merged with what the WAL held
        assert conn.execute("SELECT operator FROM campaign").fetchall() == [("latest",)]
