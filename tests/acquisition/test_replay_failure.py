"""A replay that fails part-way (a raw log segment that changed after it was read, Ctrl-C) leaves
the database as it was: no campaign marked failed, no trial, event or raw log segment of it, no
instrument it brought, no lease file; the command says what is wrong in one line. (The CiA 402
replay's own cases: tests/acquisition/test_cia402_replay.py.)"""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker
from typer.testing import CliRunner

from gyrostand.acquisition import runner
from gyrostand.acquisition.engine import Engine
from gyrostand.acquisition.operator import OperatorLink
from gyrostand.acquisition.runner import replay, run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.cli import app
from gyrostand.db.models import Base
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.logfile import BatchBLFWriter, read_raw_frames
from gyrostand.plan.model import Plan, parse_plan

from .harness import FAST_SIM, dump, files, plan_text
from .test_cia402_replay import cia402_plan


def campaign(tmp_path: Path) -> tuple[Plan, Path, list[Path]]:
    """A live campaign, its raw log cut in two segments (as a resumed campaign's), and the
    database moved aside so that the instrument is a new one in the database replayed into."""
    plan = parse_plan(
        plan_text(database=str(tmp_path / "live.sqlite"), raw_dir=str(tmp_path / "raw")) + FAST_SIM
    )
    sessions = open_database(sqlite_url(plan.database))
    live = run_live(plan, CampaignStore.create(sessions, plan), quiet=True)
    assert live.outcome == "completed" and live.raw_log is not None
    frames = list(read_raw_frames(live.raw_log, chunk=500))
    segments = []
    for name, part in (
        ("a.blf", frames[: len(frames) // 2]),
        ("b.blf", frames[len(frames) // 2 :]),
    ):
        writer = BatchBLFWriter(tmp_path / name)
        for raw in part:
            writer.write_frames(raw)
        writer.stop()
        segments.append(tmp_path / name)
    db = tmp_path / "replayed.sqlite"
    path = tmp_path / "plan.toml"
    path.write_text(plan.text.replace(str(tmp_path / "live.sqlite"), str(db)))
    return parse_plan(path.read_text()), path, segments


def corrupt(log: Path) -> None:
    """Its middle overwritten (a container that no longer inflates)."""
    data = bytearray(log.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 64] = b"\xff" * 64
    log.write_bytes(data)


def test_a_segment_changed_since_it_was_read_leaves_the_database_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plan, path, (a, b) = campaign(tmp_path)
    assert replay(plan, open_database(sqlite_url(plan.database)), [a, b]).outcome == "completed"
    before, listed = dump(plan.database), files(tmp_path)
    read = runner.check_replay_log

    def read_then_changed(log: Path) -> runner.ReplayLog:
        checked = read(log)
        if log == b:  # (another process writes it meanwhile)
            corrupt(log)
        return checked

    monkeypatch.setattr(runner, "check_replay_log", read_then_changed)
    result = CliRunner().invoke(app, ["replay", str(a), str(b), "--plan", str(path)])
    assert dump(plan.database) == before and files(tmp_path) == listed
    assert result.exit_code == 1
    (error,) = [line for line in result.stderr.splitlines() if "error" in line]
    assert error.startswith(f"gyrostand: error: replay of {b} failed: {b}: corrupt BLF container")
    assert error.endswith("(changed since it was read)") and "Traceback" not in result.output


def rows(sessions: sessionmaker[Session]) -> dict[str, list[tuple]]:
    """Every table's rows (either back end)."""
    with sessions() as session:
        return {
            t.name: sorted(map(tuple, session.execute(select(t)).all()), key=repr)
            for t in Base.metadata.sorted_tables
        }


def test_ctrl_c_part_way_leaves_the_database_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, db_url: str
) -> None:
    """Into a database that did not hold the instrument: it goes too. On both back ends."""
    plan, _, logs = campaign(tmp_path)
    sessions = open_database(db_url)  # (its schema, no campaign)
    before, listed = rows(sessions), files(tmp_path)
    feed, fed, observed = Engine.feed, [], CampaignStore.observation
    written: list[object] = []
    monkeypatch.setattr(
        CampaignStore, "observation", lambda s, o: observed(s, written.append(o) or o)
    )

    def interrupted(self: Engine, batch: object) -> None:
        fed.append(batch)
        if len(fed) == 2:  # the second segment: the first one's observations are written
            assert len(written) >= 3
            raise KeyboardInterrupt
        feed(self, batch)  # type: ignore[arg-type]

    monkeypatch.setattr(Engine, "feed", interrupted)
    with pytest.raises(KeyboardInterrupt):
        replay(plan, sessions, logs)
    assert rows(sessions) == before and files(tmp_path) == listed
    sessions.kw["bind"].dispose()


PROMPT = """
[[prompt]]
id = "mounted"
text = "compass mounted and powered?"
before = 2
"""
# what a run records of itself (prompts and answers, its raw log, how it ended) is not re-derived
RUN_ONLY = "('prompt', 'answer', 'raw log', 'resume', 'interrupted')"
RECORD = {
    "trial": 'SELECT "index", status, failure_reason, meas_direction_deg, meas_amplitude_cm, '
    "meas_period_s FROM trial WHERE campaign_id = {c} ORDER BY id",
    "observation": "SELECT k, value_deg, window_start_ms, window_end_ms, frames_used FROM "
    "observation o JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id "
    "WHERE campaign_id = {c} ORDER BY o.id",
    "event": "SELECT stand_time_ms, kind, severity, message FROM event WHERE campaign_id = {c} "
    f"AND kind NOT IN {RUN_ONLY} ORDER BY id",
}


def record(db: Path, campaign: int) -> dict[str, list[tuple]]:
    with sqlite3.connect(db) as conn:
        return {k: conn.execute(q.format(c=campaign)).fetchall() for k, q in RECORD.items()}


def test_a_campaign_stopped_at_a_prompt_replays_as_live(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The operator stops the campaign at the prompt before trial 2 rather than confirm (a
    "confirm" prompt has no other answer): the replay stops there too, trial 2 not begun."""
    db = tmp_path / "c.sqlite"
    plan = parse_plan(
        plan_text(database=str(db), raw_dir=str(tmp_path / "raw")) + FAST_SIM + PROMPT
    )
    sessions = open_database(sqlite_url(db))
    monkeypatch.setattr(OperatorLink, "_say", lambda self, line: self.stop.set())
    live = run_live(plan, CampaignStore.create(sessions, plan), quiet=True)
    assert live.outcome == "stopped" and live.raw_log is not None
    stopped = record(db, 1)
    assert [t[1] for t in stopped["trial"]] == ["completed", "pending"]
    assert replay(plan, sessions, [live.raw_log]).outcome == "stopped"
    assert record(db, 2) == stopped


def test_a_cia402_log_of_before_the_drives_traffic_was_logged_is_one_line(tmp_path: Path) -> None:
    """Before the RUN and STEP records, a CiA 402 stand's raw log held the acks and statuses
    its master derived (stand DBC frames) and the compass's frames, as a smart stand's log
    does: refused before the database is opened (none is made)."""
    _, _, (log, _) = campaign(tmp_path)
    plan = tmp_path / "cia402.toml"
    plan.write_text(cia402_plan(tmp_path / "new").text)
    db = tmp_path / "new" / "c.sqlite"
    result = CliRunner().invoke(app, ["replay", str(log), "--plan", str(plan)])
    assert result.exit_code == 2 and not db.exists()
    assert result.stderr.splitlines() == [
        f"gyrostand: error: cannot replay {log}: not a CiA 402 stand's raw log from its start "
        "(no RUN record first: another stand's, a later segment, or written before gyrostand "
        "logged the drive's traffic)"
    ]


TERMINATED = """
import os, signal, sys
from gyrostand.__main__ import main
from gyrostand.acquisition.engine import Engine

feed, fed = Engine.feed, []

def terminated(self, batch):  # SIGTERM after the first segment's observations are written
    fed.append(batch)
    if len(fed) == 2:
        os.kill(os.getpid(), signal.SIGTERM)
    feed(self, batch)

Engine.feed = terminated
sys.argv[1:] = ["replay", *sys.argv[1:]]
main()
"""


def test_sigterm_part_way_leaves_the_database_as_it_was(tmp_path: Path) -> None:
    """`gyrostand replay` told to terminate (a service stopped, a job's time limit)."""
    plan, path, logs = campaign(tmp_path)
    open_database(sqlite_url(plan.database))  # (its schema, no campaign)
    before, listed = dump(plan.database), files(tmp_path)
    args = [sys.executable, "-c", TERMINATED, *map(str, logs), "--plan", str(path)]
    done = subprocess.run(args, capture_output=True, text=True, timeout=120, check=False)
    assert (done.returncode, done.stderr.splitlines()[-1]) == (130, "gyrostand: interrupted")
    assert dump(plan.database) == before and files(tmp_path) == listed
