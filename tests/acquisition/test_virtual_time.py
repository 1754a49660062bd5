"""Virtual time (stand.virtual_time): the in-process simulated stand runs on the acquisition's
SIM_SYNC, so the same plan and seed give the same database and the same raw log whatever the
host load; commands take effect at the stand time fixed by the stream; silence and missing
acknowledgements are timed in stand time."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from contextlib import closing, contextmanager
from pathlib import Path

import cantools
import pytest

from gyrostand.acquisition.runner import RunResult, run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.logfile import read_raw_frames
from gyrostand.plan.model import parse_plan
from gyrostand.stand.protocol import DBC_PATH
from gyrostand.stand.virtual_time import DEFAULT_LEAD_MS

from .harness import plan_text

FAST_SIM = """
[bus.simulator.compass]
undamped_period_s = 240.0
damping_ratio = 0.8
"""
WALL_CLOCK_COLUMNS = {"created_at", "started_at", "finished_at", "wall_time"}


@contextmanager
def cpu_hog() -> Iterator[None]:
    """Keep another core busy (a shared 2-core CI machine)."""
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        hog.kill()
        hog.wait()


def run_in(folder: Path, monkeypatch: pytest.MonkeyPatch, extra: str = "", **kw) -> RunResult:
    """The small plan in `folder`, with relative paths so that two runs store the same plan."""
    folder.mkdir()
    monkeypatch.chdir(folder)
    plan = parse_plan(plan_text(database="db.sqlite", raw_dir="raw", **kw) + FAST_SIM + extra)
    store = CampaignStore.create(open_database(sqlite_url(Path("db.sqlite"))), plan)
    return run_live(plan, store, quiet=True)


def content(db: Path) -> dict[str, list[tuple]]:
    """Every table, row by row, without the wall-clock columns; the run's folder (raw log paths
    are stored absolute) as "FOLDER"."""
    folder = str(db.parent)
    with closing(sqlite3.connect(db)) as conn:
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        out = {}
        for table in tables:
            columns = [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]
            keep = ", ".join(f'"{c}"' for c in columns if c not in WALL_CLOCK_COLUMNS)
            rows = conn.execute(f'SELECT {keep} FROM "{table}" ORDER BY 1').fetchall()
            out[table] = [
                tuple(v.replace(folder, "FOLDER") if isinstance(v, str) else v for v in row)
                for row in rows
            ]
    return out


def test_same_seed_same_database_and_raw_log_under_load(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    idle = run_in(tmp_path / "idle", monkeypatch)
    with cpu_hog():
        busy = run_in(tmp_path / "busy", monkeypatch)
    assert idle.outcome == busy.outcome == "completed"
    a, b = content(tmp_path / "idle" / "db.sqlite"), content(tmp_path / "busy" / "db.sqlite")
    assert a.keys() == b.keys() and len(a["observation"]) == 2 * 2 * 3
    for table in a:
        assert a[table] == b[table], table
    assert idle.raw_log_sha256 == busy.raw_log_sha256
    assert (tmp_path / "idle" / "raw" / "db-campaign-1.blf").read_bytes() == (
        tmp_path / "busy" / "raw" / "db-campaign-1.blf"
    ).read_bytes()


def test_commands_take_effect_at_their_stand_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each command is decided at the stand time the acquisition had processed (its event) and
    acknowledged by the stand exactly the SIM_SYNC lead later, right after the stand repeats it
    in the stream; the raw log is stamped with the stand clock."""
    result = run_in(tmp_path / "run", monkeypatch)
    db = cantools.database.load_file(str(DBC_PATH))
    ack, command = db.get_message_by_name("STAND_ACK"), db.get_message_by_name("STAND_COMMAND")
    heading = db.get_message_by_name("GYRO_HEADING")
    acks, previous = [], None
    assert result.raw_log is not None
    for raw in read_raw_frames(result.raw_log):
        for i in range(len(raw)):
            frame_id, data = int(raw.arbitration_id[i]), bytes(raw.data[i])
            if frame_id == ack.frame_id:
                assert previous == command.frame_id  # the stand's repeat of the command
                acks.append(ack.decode(data)["STAND_TIME"])
            if frame_id == heading.frame_id:
                stand_ms = heading.decode(data)["STAND_TIME"]
                assert round(raw.timestamp[i] * 1000) == stand_ms
            previous = frame_id
    with closing(sqlite3.connect("db.sqlite")) as conn:
        decided = [
            r[0]
            for r in conn.execute(
                "SELECT stand_time_ms FROM event WHERE kind = 'command' ORDER BY id"
            )
        ]
    assert len(decided) == 7  # stop, set, start, stop; set, start, stop
    assert acks == [t + DEFAULT_LEAD_MS for t in decided]


def test_silence_fails_the_trial_in_stand_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stand that falls silent for good: the simulation's clock goes on, so the trial fails
    once the plan's bus_silence_s (5 s) of stand time passes without a heading frame, and the
    campaign pauses, at once instead of after a wall-clock watchdog."""
    faults = "\n[bus.simulator.faults]\nsilence_at_s = 300.0\nsilence_for_s = 1e9\n"
    result = run_in(tmp_path / "run", monkeypatch, faults, on_failure="pause")
    assert result.outcome == "paused"
    with closing(sqlite3.connect("db.sqlite")) as conn:
        (reason,) = conn.execute(
            "SELECT failure_reason FROM trial WHERE status = 'failed'"
        ).fetchone()
        (t_ms,) = conn.execute(
            "SELECT stand_time_ms FROM event WHERE kind = 'bus silence'"
        ).fetchone()
    # the last heading frame is at 299.9 s; the first SIM_CLOCK tick more than 5 s later: 305 s
    assert reason == "bus silence: no heading frame for 5.1 s of stand time"
    assert t_ms == 305_000


def test_a_stand_that_never_answers_fails_in_stand_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    result = run_in(
        tmp_path / "run", monkeypatch, "\n[bus.simulator.faults]\nno_ack = true\n", n_obs=2
    )
    assert result.outcome == "failed" and result.trials_failed == 2  # (nothing to analyse)
    with closing(sqlite3.connect("db.sqlite")) as conn:
        reasons = [r[0] for r in conn.execute("SELECT failure_reason FROM trial")]
    assert reasons == ["stand did not acknowledge 'stop' within 2 s of stand time"] * 2
