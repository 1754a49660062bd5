"""Ctrl-C at any point of `campaign run` and `campaign resume` before the acquisition loop: no
campaign written at all, or the campaign marked "stopped" with an event saying so, never one left
"running" without a word. The signal is raised (`signal.raise_signal`, delivered at once in this
main thread) from inside a function on the command's path; no sleeps, no clocks."""

from __future__ import annotations

import signal
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from gyrostand.acquisition import runner, store
from gyrostand.db import session

from .cases import invoke
from .conftest import Stand, checkpointed, db_state


def interrupted(function: Callable[..., Any], before: bool = False) -> Callable[..., Any]:
    """`function`, with a SIGINT arriving just before it runs or just after it returned."""

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if before:
            signal.raise_signal(signal.SIGINT)
        value = function(*args, **kwargs)
        if not before:
            signal.raise_signal(signal.SIGINT)
        return value

    return wrapper


def campaign(db: Path, campaign_id: int) -> tuple[str, list[tuple[str, str, str]], int] | None:
    """(status, events other than commands as (kind, severity, message), observations)."""
    connection = sqlite3.connect(db)
    try:
        row = connection.execute("SELECT status FROM campaign WHERE id = ?", (campaign_id,))
        status = row.fetchone()
        if status is None:
            return None
        events = connection.execute(
            "SELECT kind, severity, message FROM event WHERE campaign_id = ? AND kind != 'command'"
            " ORDER BY id",
            (campaign_id,),
        ).fetchall()
        observations = connection.execute(
            "SELECT COUNT(*) FROM observation JOIN series ON series.id = observation.series_id "
            "JOIN trial ON trial.id = series.trial_id WHERE trial.campaign_id = ?",
            (campaign_id,),
        ).fetchone()[0]
    finally:
        connection.close()
    return status[0], events, observations


def run(stand: Stand, db: Path) -> tuple[int, str, str]:
    outcome = invoke("campaign", "run", str(stand.plan), "--db", str(db), "--quiet")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # handler given back
    return outcome


@pytest.mark.parametrize("before", [True, False], ids=["while opening", "once opened"])
def test_sigint_while_the_database_opens_writes_no_campaign(
    stand: Stand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, before: bool
) -> None:
    db = checkpointed(stand.db_copy(tmp_path))
    state = db_state(db)
    monkeypatch.setattr(session, "open_database", interrupted(session.open_database, before))
    code, out, err = run(stand, db)
    assert (code, out) == (1, "")
    assert err == "gyrostand: error: interrupted before the campaign was stored: nothing written\n"
    assert campaign(db, 2) is None and db_state(db) == state


STOPPED_BEFORE = ("interrupted", "warning", "stopped by signal before acquiring")


def test_sigint_while_the_campaign_is_stored_stops_it_with_an_event(
    stand: Stand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The campaign row is committed, then its lease taken: the signal comes in between."""
    db = stand.db_copy(tmp_path)
    monkeypatch.setattr(store, "take_lease", interrupted(store.take_lease))
    code, out, err = run(stand, db)
    assert (code, err) == (1, "")
    assert out.startswith("campaign 2 stopped: 0 trials completed, 0 failed, 0 observations")
    assert "gyrostand campaign resume 2" in out
    assert campaign(db, 2) == ("stopped", [STOPPED_BEFORE], 0)
    # the run's own event is no acquisition write: a resume that re-runs skips none for it
    with sqlite3.connect(db) as connection:
        row = connection.execute("SELECT engine_writes FROM campaign WHERE id = 2").fetchone()
    assert row == (0,)


def test_sigint_while_the_bus_opens_stops_the_campaign_with_an_event(
    stand: Stand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Inside the acquisition, before its loop: the loop stops on it at once (the stand told
    to stop rocking), the raw log kept."""
    db = stand.db_copy(tmp_path)
    monkeypatch.setattr(runner, "LiveBus", interrupted(runner.LiveBus))
    code, out, err = run(stand, db)
    assert (code, err) == (1, "") and out.startswith("campaign 2 stopped: ")
    status, events, observations = campaign(db, 2) or ("", [], -1)
    assert (status, observations) == ("stopped", 0)
    assert events[0] == ("interrupted", "warning", "stopped by signal: stand told to stop rocking")
    assert [e[0] for e in events[1:]] == ["raw log"]


def test_keyboard_interrupt_where_no_handler_is_stops_the_campaign_with_an_event(
    stand: Stand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A KeyboardInterrupt raised on the way (Ctrl-C in a process whose handler is python's):
    the campaign, stored and marked running, is marked stopped with an event."""

    def broken(*_args: object, **_kwargs: object) -> None:
        raise KeyboardInterrupt

    db = stand.db_copy(tmp_path)
    monkeypatch.setattr(runner, "LiveBus", broken)
    code, out, err = run(stand, db)
    assert (code, err) == (1, "") and out.startswith("campaign 2 stopped: ")
    interrupted_event = ("interrupted", "warning", "interrupted before acquiring (Ctrl-C)")
    assert campaign(db, 2) == ("stopped", [interrupted_event], 0)


@pytest.fixture
def stopped(stand: Stand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A database whose campaign 2 was stopped before it acquired anything."""
    db = stand.db_copy(tmp_path)
    with monkeypatch.context() as patch:
        patch.setattr(store, "take_lease", interrupted(store.take_lease))
        assert run(stand, db)[0] == 1
    return checkpointed(db)


def resume(db: Path) -> tuple[int, str, str]:
    outcome = invoke("campaign", "resume", "2", "--db", str(db), "--quiet")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    return outcome


def test_sigint_while_resume_opens_the_database_writes_nothing(
    stopped: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    state = db_state(stopped)
    monkeypatch.setattr(session, "open_database", interrupted(session.open_database))
    code, out, err = resume(stopped)
    assert (code, out) == (1, "")
    assert (
        err == "gyrostand: error: interrupted before campaign 2 was taken over: nothing written\n"
    )
    assert db_state(stopped) == state


def test_sigint_while_resume_takes_the_campaign_over_stops_it_with_an_event(
    stopped: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(runner, "resume_store", interrupted(runner.resume_store))
    code, out, err = resume(stopped)
    assert (code, err) == (1, "") and out.startswith("campaign 2 stopped: 0 trials completed")
    status, events, observations = campaign(stopped, 2) or ("", [], -1)
    assert (status, observations) == ("stopped", 0)
    resumed = [e for e in events if e[0] == "resume"]
    assert len(resumed) == 1 and resumed[0][2].startswith("resumed by process")
    assert events == [STOPPED_BEFORE, resumed[0], STOPPED_BEFORE]


# --------------------------------------------------------------------- Ctrl-C during start-up
SIGINT_AT_IMPORT = '''
import os, signal, sys

class SigintAt:
    """SIGINT delivered (to this main thread, at once) when the named module is imported."""

    def find_spec(self, name, path=None, target=None):
        if name == os.environ["GYROSTAND_TEST_SIGINT_AT"]:
            sys.meta_path.remove(self)
            signal.raise_signal(signal.SIGINT)
        return None

sys.meta_path.insert(0, SigintAt())
'''


@pytest.mark.parametrize(
    ("program", "module", "args"),
    [
        ("-m", "typer", ["--version"]),  # the CLI's first third-party import
        ("-m", "gyrostand.cmd_simulate", ["--help"]),  # one of the command modules
        ("-m", "gyrostand.plan.model", ["plan", "check", "plan.toml"]),  # inside the command
        ("script", "gyrostand.cli", ["--version"]),  # the installed `gyrostand` command
    ],
)
def test_ctrl_c_during_start_up_is_one_line_and_exit_code_130(
    tmp_path: Path, program: str, module: str, args: list[str]
) -> None:
    """Before: a KeyboardInterrupt traceback from the imports (exit code 1). The SIGINT is
    raised by an import hook (a sitecustomize on PYTHONPATH) as the module is imported."""
    import os
    import subprocess
    import sys

    (tmp_path / "sitecustomize.py").write_text(SIGINT_AT_IMPORT)
    (tmp_path / "plan.toml").write_text("")
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "GYROSTAND_TEST_SIGINT_AT": module}
    command = (
        [sys.executable, "-m", "gyrostand"]
        if program == "-m"
        else [str(Path(sys.executable).with_name("gyrostand"))]
    )
    run = subprocess.run(
        [*command, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
    assert (run.returncode, run.stdout, run.stderr) == (130, "", "gyrostand: interrupted\n")
