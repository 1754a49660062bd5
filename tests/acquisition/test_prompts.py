"""Operator prompts before a trial and stop requests, through the database (acquisition.operator):
the engine waits at a fixed point of the stream, so in virtual time the stand clock is held and
the campaign ends as an unprompted one; a stop request stops it safely."""

from __future__ import annotations

import sqlite3
import threading
import time
from collections.abc import Callable
from contextlib import closing
from pathlib import Path

from gyrostand.acquisition.runner import RunResult, run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.models import Event
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.plan.model import parse_plan
from gyrostand.plan.prompts import ANSWER, STOP_REQUEST

from .harness import plan_text

FAST_SIM = """
[bus.simulator.compass]
undamped_period_s = 240.0
damping_ratio = 0.8
"""
PROMPT = """
[[prompt]]
id = "mounted"
text = "compass mounted and powered?"
before = 2
"""
WAIT_S = 120.0


def rows(db: Path, query: str) -> list[tuple]:
    with closing(sqlite3.connect(db)) as conn:
        return conn.execute(query).fetchall()


def until(condition: Callable[[], object], what: str) -> None:
    """Poll `condition` until it holds (a failure after WAIT_S of wall time)."""
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def start(folder: Path, extra: str = "") -> tuple[threading.Thread, list[RunResult], Path]:
    """The small plan in virtual time, acquired in a thread; its database."""
    folder.mkdir()
    db = folder / "db.sqlite"
    text = plan_text(database=str(db), raw_dir=str(folder / "raw")) + FAST_SIM + extra
    plan = parse_plan(text)
    store = CampaignStore.create(open_database(sqlite_url(db)), plan)
    results: list[RunResult] = []
    thread = threading.Thread(target=lambda: results.append(run_live(plan, store, quiet=True)))
    thread.start()
    return thread, results, db


def add_event(db: Path, kind: str, message: str) -> None:
    sessions = open_database(sqlite_url(db))
    with sessions.begin() as session:
        session.add(Event(campaign_id=1, kind=kind, severity="info", message=message))


def observations(db: Path) -> list[tuple]:
    return rows(
        db,
        'SELECT t."index", s.j, o.k, o.value_deg, o.window_end_ms FROM observation o '
        "JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id ORDER BY o.id",
    )


def test_prompt_before_a_trial_holds_virtual_time_until_answered(tmp_path: Path) -> None:
    plain, results, plain_db = start(tmp_path / "plain")
    plain.join(WAIT_S)
    thread, prompted, db = start(tmp_path / "prompted", PROMPT)
    asked = "SELECT message FROM event WHERE kind = 'prompt'"
    until(lambda: rows(db, asked), "the prompt")
    assert rows(db, asked) == [("mounted: compass mounted and powered?",)]
    trial_2 = 'SELECT status FROM trial WHERE "index" = 2'
    held = observations(db)
    assert rows(db, trial_2) == [("pending",)] and {o[0] for o in held} == {1}
    assert len(held) == 6  # trial 1 complete, 2 series x N = 3
    add_event(db, ANSWER, "mounted: yes")
    thread.join(WAIT_S)
    assert results[0].outcome == prompted[0].outcome == "completed"
    assert observations(db) == observations(plain_db)  # no stand time passed, no frame lost
    kinds = [k for (k,) in rows(db, "SELECT kind FROM event ORDER BY id")]
    assert kinds.index("answer") == kinds.index("prompt") + 1
    first_trial_2 = rows(db, "SELECT MIN(id) FROM event WHERE trial_id = 2")[0][0]
    answer_id = rows(db, "SELECT id FROM event WHERE kind = 'answer'")[0][0]
    assert first_trial_2 > answer_id  # trial 2 began after the answer


def test_stop_request_in_the_database_stops_the_run_safely(tmp_path: Path) -> None:
    thread, results, db = start(tmp_path / "run", PROMPT)
    until(lambda: rows(db, "SELECT 1 FROM event WHERE kind = 'prompt'"), "the prompt")
    add_event(db, STOP_REQUEST, "safe stop requested at the station")
    thread.join(WAIT_S)
    assert results[0].outcome == "stopped" and results[0].observations == 6
    assert rows(db, "SELECT status FROM campaign") == [("stopped",)]
    last = rows(db, "SELECT kind, message FROM event WHERE kind IN ('interrupted', 'command') "
                    "ORDER BY id DESC LIMIT 2")  # fmt: skip
    assert last == [
        ("command", "stop"),
        ("interrupted", "safe stop requested at the station: stand told to stop rocking"),
    ]
