"""The campaign CLI as an operator uses it: bad plans refused before anything is touched,
SIGTERM stops cleanly, SIGKILL at random moments loses nothing that was committed, and resume
finishes the campaign."""

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sqlalchemy import create_engine, text
from typer.testing import CliRunner

from gyrostand.cli import app

from .harness import FAST_SIM, plan_text


def write_plan(tmp: Path, name: str = "plan.toml", *, extra: str = FAST_SIM, **kw) -> Path:
    kw.setdefault("database", str(tmp / "db.sqlite"))
    kw.setdefault("raw_dir", str(tmp / "raw"))
    path = tmp / name
    path.write_text(plan_text(**kw) + extra)
    return path


def cli(*args: str) -> tuple[int, str]:
    """In-process CLI call: exit code and stderr."""
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.stderr


def start(*args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gyrostand", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def rows(db: Path) -> list[tuple]:
    engine = create_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        result = conn.execute(
            text(
                'SELECT t."index", s.j, o.k, o.value_deg, o.window_start_ms, o.window_end_ms,'
                " o.frames_used, o.frames_lost, o.flags FROM observation o"
                " JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id"
                ' ORDER BY t."index", s.j, o.k'
            )
        ).all()
    engine.dispose()
    return [tuple(r) for r in result]


def statuses(db: Path) -> tuple[str, list[tuple]]:
    engine = create_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        campaign = conn.execute(text("SELECT status FROM campaign")).scalar_one()
        trials = conn.execute(
            text('SELECT "index", status, failure_reason FROM trial ORDER BY "index"')
        ).all()
    engine.dispose()
    return campaign, [tuple(t) for t in trials]


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda t: t.replace("n_obs = 3", "n_obs = 0"), "[campaign] n_obs: must be >= 2"),
        (
            lambda t: t.replace("period_s = 5.0", "period_s = 0"),
            "[[trials]] 2 period_s: must be > 0",
        ),
        (lambda t: t + '\n[signals]\nheading = "NOPE.HEADING"\n', "no message 'NOPE'"),
        (lambda t: t + "\n[bus.simulator.faults]\ndrop = 1\n", "[bus.simulator.faults] drop"),
        (lambda t: t.replace("hold_s = 60.0", "hold_s = -1"), "[settle] hold_s: must be >= 0"),
    ],
)
def test_bad_plan_is_one_clear_error_and_touches_nothing(tmp_path: Path, edit, expected) -> None:
    plan = write_plan(tmp_path, extra="")
    plan.write_text(edit(plan.read_text()))
    code, err = cli("campaign", "run", str(plan), "--quiet")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gyrostand: error:") and expected in lines[0]
    assert not (tmp_path / "db.sqlite").exists() and not (tmp_path / "raw").exists()


def test_bad_options(tmp_path: Path) -> None:
    plan = write_plan(tmp_path)
    code, err = cli("campaign", "run", str(plan), "--interface", "virtual", "--speedup", "5")
    assert code == 2 and "--speedup and --seed apply" in err
    code, err = cli("campaign", "status", "1", "--db", str(tmp_path / "none.sqlite"))
    assert code == 2 and "no database at" in err
    code, err = cli("replay", str(tmp_path / "x.blf"), "--plan", str(plan))
    assert code == 2 and "no log file" in err
    code, err = cli("campaign", "run", str(tmp_path / "missing.toml"))
    assert code == 2 and "cannot read" in err
    assert not (tmp_path / "db.sqlite").exists()


HANG_S = 300.0
"""A hang guard only: in virtual time a busy machine slows a campaign (a resume re-simulates the
stand up to where the database stops), it never fails it; 60 s was not enough under load."""


def wait_for_observations(db: Path, n: int, proc: subprocess.Popen) -> None:
    """Until `n` observations are committed or the process has ended (the caller tells which);
    AssertionError only when neither happens within HANG_S of wall time."""
    deadline = time.monotonic() + HANG_S
    while time.monotonic() < deadline:
        ended = proc.poll() is not None
        if db.exists():
            try:
                if len(rows(db)) >= n:
                    return
            except Exception:  # the schema may not be there yet
                pass
        if ended:
            return
        time.sleep(0.05)
    raise AssertionError(f"fewer than {n} observations after {HANG_S:g} s: a hang")


def test_sigterm_stops_the_stand_and_resume_finishes(tmp_path: Path) -> None:
    db = tmp_path / "db.sqlite"
    plan = write_plan(tmp_path)  # virtual time: as fast as the machine, at any load
    proc = start("campaign", "run", str(plan), "--quiet", cwd=tmp_path)
    wait_for_observations(db, 2, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 1, err
    campaign, _ = statuses(db)
    assert campaign == "stopped"
    before = rows(db)
    engine = create_engine(f"sqlite:///{db}")
    with engine.connect() as conn:
        kinds = [r[0] for r in conn.execute(text("SELECT kind FROM event ORDER BY id"))]
        messages = [r[0] for r in conn.execute(text("SELECT message FROM event ORDER BY id"))]
    engine.dispose()
    assert kinds[-3:-1] == ["interrupted", "command"] and messages[-2] == "stop"
    status = CliRunner().invoke(app, ["campaign", "status", "1", "--db", str(db)])
    assert status.exit_code == 0 and "stopped" in status.stdout and "next: trial" in status.stdout
    code, err = cli("campaign", "resume", "1", "--db", str(db), "--quiet")
    assert code == 0, err
    after = rows(db)
    assert set(before) <= set(after) and len(after) == 2 * 2 * 3
    assert statuses(db)[0] == "completed"
    again = CliRunner().invoke(app, ["campaign", "resume", "1", "--db", str(db)])
    assert again.exit_code == 0 and "nothing left to acquire" in again.stdout
    assert rows(db) == after


def test_sigkill_at_random_moments_loses_nothing(tmp_path: Path) -> None:
    reference_dir, killed_dir = tmp_path / "reference", tmp_path / "killed"
    reference_dir.mkdir()
    killed_dir.mkdir()
    # virtual time: the stand runs as fast as the machine lets it, whatever the load; each kill
    # lands 1-3 observations after the last one and a random fraction of an observation later
    ref_plan = write_plan(reference_dir, n_obs=4)
    code, err = cli("campaign", "run", str(ref_plan), "--quiet")
    assert code == 0, err
    reference = rows(reference_dir / "db.sqlite")

    db = killed_dir / "db.sqlite"
    plan = write_plan(killed_dir, n_obs=4)
    rng = random.Random(2024)
    committed: set[tuple] = set()
    args = ["campaign", "run", str(plan), "--quiet"]
    kills = 0
    for _ in range(3):
        proc = start(*args, cwd=killed_dir)
        wait_for_observations(db, len(committed) + rng.randint(1, 3), proc)
        time.sleep(rng.uniform(0.0, 0.1))
        if proc.poll() is not None:
            break
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        kills += 1
        now = set(rows(db))
        assert committed <= now  # nothing committed earlier went missing or changed
        committed = now
        args = ["campaign", "resume", "1", "--db", str(db), "--quiet"]
    assert kills >= 2
    code, err = cli("campaign", "resume", "1", "--db", str(db), "--quiet")
    assert code == 0, err
    final = rows(db)
    assert committed <= set(final)
    # the same campaign as the uninterrupted run, to the last bit: no gap, no duplicate, the
    # same values (in virtual time a resumed simulation re-runs the stand and continues where
    # the database stops, `acquisition.runner.resume_start`)
    assert final == reference
    assert statuses(db) == statuses(reference_dir / "db.sqlite")


def test_command_line_bus_options_are_stored_with_the_plan(tmp_path: Path) -> None:
    """`campaign run --seed` is part of what ran: the stored plan says so (a resume re-runs the
    same simulation, the report names the seed), the rest of the file's text as it was."""
    from gyrostand.plan.model import parse_plan

    plan = write_plan(tmp_path)
    code, err = cli("campaign", "run", str(plan), "--quiet", "--seed", "5")
    assert code == 0, err
    engine = create_engine(f"sqlite:///{tmp_path / 'db.sqlite'}")
    with engine.connect() as conn:
        stored = conn.execute(text("SELECT plan_toml FROM campaign")).scalar_one()
        runs = conn.execute(text("SELECT count(*) FROM analysis_run")).scalar_one()
    engine.dispose()
    assert parse_plan(stored).bus.seed == 5
    assert runs == 0  # an acquisition-only campaign: no analysis recorded when it completes
    file_lines, stored_lines = plan.read_text().splitlines(), stored.splitlines()
    changed = [(a, b) for a, b in zip(file_lines, stored_lines, strict=True) if a != b]
    assert changed == [("seed = 1", "seed = 5")]
