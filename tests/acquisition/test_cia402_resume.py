"""Resume of a campaign on the simulated CiA 402 stand (virtual time, SYNC in stand time): a
killed run's resume re-runs the simulation from its start (a new drive, at rest and enabled by
the master's setup) and skips what the database holds, so that the campaign ends as the
uninterrupted one, row for row and frame for frame (`killing.kill_and_resume`); a stopped run's
resume goes on at its first incomplete series, the campaign clock going on from its last stored
time."""

import sqlite3
import threading
from functools import partial
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.acquisition import bus, cia402_run
from gyrostand.acquisition.cia402_sim import SimulatedCia402
from gyrostand.acquisition.runner import run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.cli import app
from gyrostand.db.queries import RUN_START
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.plan.model import parse_plan

from .harness import FAST_SIM, plan_text
from .killing import kill_and_resume, small_containers
from .test_cia402_campaign import SERVO, STAND

COMPASS = '\n[compass]\nprotocol = "nmea2000"\n'
STOP_AT_S = 120.0  # stand time: trial 1 rocks (from about 100 s)
OBSERVATIONS = "SELECT window_start_ms, window_end_ms FROM observation ORDER BY id"


def query(db: Path, sql: str) -> list[tuple]:
    with sqlite3.connect(db) as conn:
        return [tuple(r) for r in conn.execute(sql)]


def test_kill_9_then_resume_equals_the_uninterrupted_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(bus, "raw_log_writer", small_containers)
    # the servo integrated in 5 ms steps: quicker (the forked runs inherit the patches)
    monkeypatch.setattr(cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO))
    plan = {"trials": [(45.0, 24.0, 6.0, "fit")], "n_obs": 2, "hold_s": 30.0}
    answers = ("k_trial1=yes",)  # K set by hand
    run = kill_and_resume(tmp_path, 1, 3, compass=STAND + COMPASS, answers=answers, plan=plan)
    assert run.problems == ()
    assert run.kills >= 1


def test_stop_then_resume_goes_on_with_the_campaign_clock(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Stopped mid-roll (the axis brought to rest), resumed: the trial's series are acquired
    again by a new run whose clock goes on from the last stored stand time (RUN_START after
    the stop), and the campaign completes with its windows in one campaign time."""
    db = tmp_path / "db.sqlite"
    monkeypatch.setattr(cia402_run, "SimulatedCia402", partial(SimulatedCia402, servo=SERVO))
    plan = parse_plan(
        plan_text(
            [(45.0, 24.0, 6.0, "fit")],
            n_obs=2,
            hold_s=30.0,
            database=str(db),
            raw_dir=str(tmp_path / "raw"),
        )
        + FAST_SIM
        + STAND
        + COMPASS
    )
    stop = threading.Event()
    advance = SimulatedCia402.advance_to

    def advance_then_stop(self: SimulatedCia402, t_s: float) -> list:
        if t_s >= STOP_AT_S:  # (the signal handler's `stop`, at a stand time)
            stop.set()
        return advance(self, t_s)

    with monkeypatch.context() as m:
        m.setattr(SimulatedCia402, "advance_to", advance_then_stop)
        sessions = open_database(sqlite_url(db))
        store = CampaignStore.create(sessions, plan)
        first = run_live(plan, store, quiet=True, stop=stop, answers={"k_trial1": "yes"})
    assert first.outcome == "stopped" and first.trials_completed == 0
    rest = query(db, "SELECT stand_time_ms, message FROM event WHERE kind = 'stand'")
    assert len(rest) == 1 and rest[0][1].startswith("the axis at rest and disabled")

    result = CliRunner().invoke(app, ["campaign", "resume", "1", "--db", str(db), "--quiet"])
    assert result.exit_code == 0, result.output
    assert query(db, "SELECT status FROM campaign") == [("completed",)]
    ((run_start,),) = query(db, f"SELECT stand_time_ms FROM event WHERE kind = '{RUN_START}'")
    ((stopped,),) = query(db, "SELECT max(stand_time_ms) FROM event WHERE kind = 'interrupted'")
    assert run_start > stopped > STOP_AT_S * 1000 - 5000
    windows = query(db, OBSERVATIONS)
    assert len(windows) == 2 * 2
    assert all(a[1] <= b[0] for a, b in zip(windows, windows[1:], strict=False)), windows
    # the still series kept from the first run, the rocking one acquired after the resume
    assert windows[1][1] < stopped and windows[2][0] > run_start
