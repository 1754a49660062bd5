"""`campaign retry` and `campaign resume --retry-failed` on a campaign two of whose trials a fault
knob of the simulated stand failed: the failed attempts stay with their observations and events,
the new attempts are acquired as an uninterrupted run of the same trials would be (observation for
observation), the analysis uses them and names every attempt it leaves out; bad input is one line,
exit code 2 and the database byte-identical."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import sqlite3
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gyrostand.acquisition.retry import RetriedTrial, retry_trials
from gyrostand.acquisition.runner import resume_start
from gyrostand.acquisition.store import CampaignStore
from gyrostand.cli import app
from gyrostand.db.queries import RUN_START
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.logfile import read_segments
from gyrostand.plan.model import parse_plan
from gyrostand.stand.protocol import load_dbc
from tests.acquisition.harness import FAST_SIM, plan_text

from .conftest import checkpointed, db_state

TRIALS = [
    (45.0, 24.0, 6.0, "fit"),
    (315.0, 20.0, 5.0, "fit"),
    (135.0, 24.0, 8.0, "fit"),
    (225.0, 20.0, 7.0, "control"),
]
# The first run (virtual time, seed 1) reaches trial 3's still series at ~1350 s of stand time and
# trial 4's rocking observations at ~1820 s: the bus falls silent in the first, the angle sensor
# sticks for a whole window in the second. Every live run starts the simulation at 0 (the fault
# windows count from there; its stand clock goes on from the campaign's last stored stand time)
# and a retry run acquires only the retried trials (~600 s each), so it ends before either
# window opens: the retried trials meet the stand without the fault.
FAULTS = """
[bus.simulator.faults]
silence_at_s = 1400.0
silence_for_s = 10.0
stuck_at_s = 1845.0
stuck_for_s = 40.0
"""
SILENCE = "bus silence: no heading frame for 5.5 s of stand time"
STUCK = "stuck sensor: 56 identical readings in observation window 2"
OBSERVATION = (
    'SELECT t."index", t.attempt, s.j, o.k, o.value_deg, o.window_start_ms, o.window_end_ms,'
    " o.frames_used, o.frames_lost, o.flags FROM observation o"
    " JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id"
)


@dataclass(frozen=True)
class Runs:
    """The campaign with trials 3 and 4 failed, and an uninterrupted run of trials 3 and 4 alone
    (a campaign of their own, as trials 1 and 2) on the same simulated stand without faults."""

    failed: Path
    failed_out: str  # what `campaign run` printed
    reference: Path
    reference_log: Path


def run(plan: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan), "--quiet"],
        cwd=plan.parent,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Runs:
    procs = []
    for name, trials, faults in (("failed", TRIALS, FAULTS), ("reference", TRIALS[2:], "")):
        folder = tmp_path_factory.mktemp(name)
        plan = folder / "plan.toml"
        text = plan_text(
            trials,
            database=str(folder / "db.sqlite"),
            raw_dir=str(folder / "raw"),
            bus_extra=faults,
        )
        plan.write_text(text + FAST_SIM)
        procs.append((folder, run(plan)))
    for _, proc in procs:
        proc.wait(timeout=300)
    (failed, first), (reference, second) = procs
    assert first.returncode == 0 and second.returncode == 0, first.stderr.read()
    return Runs(
        failed / "db.sqlite",
        first.stdout.read(),
        reference / "db.sqlite",
        reference_log=Path(second.stdout.read().split("raw frames: ")[1].split(" (sha256")[0]),
    )


def invoke(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def query(db: Path, sql: str, *params: object) -> list[tuple]:
    with sqlite3.connect(db) as conn:
        return [tuple(row) for row in conn.execute(sql, params)]


def copy(runs: Runs, folder: Path) -> Path:
    db = folder / "copy.sqlite"
    shutil.copyfile(runs.failed, db)
    return db


def attempt_rows(db: Path, index: int, attempt: int) -> list[tuple]:
    """The observations of one attempt of trial `index`."""
    where = ' WHERE t."index" = ? AND t.attempt = ? ORDER BY s.j, o.k'
    return query(db, OBSERVATION + where, index, attempt)


def attempt_events(db: Path, index: int, attempt: int) -> list[tuple]:
    """(kind, message) of the events of one attempt of trial `index`."""
    sql = (
        "SELECT e.kind, e.message FROM event e JOIN trial t ON t.id = e.trial_id"
        ' WHERE t."index" = ? AND t.attempt = ? ORDER BY e.id'
    )
    return query(db, sql, index, attempt)


def reference_rows(runs: Runs, index: int, clock_ms: int) -> list[tuple]:
    """The reference run's observations of trial `index` of the campaign (its index - 2), on a
    stand clock starting at `clock_ms` (`run_clock`)."""
    rows = query(runs.reference, OBSERVATION + ' WHERE t."index" = ? ORDER BY s.j, o.k', index - 2)
    return [(index, 2, *row[2:5], row[5] + clock_ms, row[6] + clock_ms, *row[7:]) for row in rows]


def run_clock(db: Path) -> int:
    """Where the stand clock of the (one) retry run started: its RUN_START event's stand time
    (its first heading), past every stand time stored before it."""
    ((first_heading,),) = query(db, f"SELECT stand_time_ms FROM event WHERE kind = '{RUN_START}'")
    ((before,),) = query(
        db,
        f"SELECT max(stand_time_ms) FROM event WHERE kind != '{RUN_START}' AND id < "
        f"(SELECT id FROM event WHERE kind = '{RUN_START}')",
    )
    assert first_heading == -(-before // 1000) * 1000  # the next whole second
    return first_heading


def frames_unclocked(logs: list[Path], clock_ms: int) -> list[tuple]:
    """Every frame of the logs decoded (gyrostand's DBC), STAND_TIME less `clock_ms` (and without
    the CRC, which covers it)."""
    database = load_dbc()
    out: list[tuple] = []
    for batch in read_segments(logs):
        for i in range(len(batch)):
            frame_id = int(batch.arbitration_id[i])
            data = bytes(batch.data[i][: batch.dlc[i]]) if not batch.is_error[i] else b"error"
            try:
                values = dict(database.decode_message(frame_id, data, decode_choices=False))
            except (KeyError, ValueError):
                out.append((frame_id, data))
                continue
            if "STAND_TIME" in values:
                values["STAND_TIME"] -= clock_ms
                values.pop("CRC", None)
            out.append((frame_id, tuple(sorted(values.items()))))
    return out


def delta_and_variance(rows: list[tuple]) -> tuple[float, float]:
    """<delta_i> and S^2{<delta_i>} (Potemkin 1982 eqs 2.1-2.3) of one trial's observations."""
    before = np.array([r[4] for r in rows if r[2] == 1])
    under = np.array([r[4] for r in rows if r[2] == 2])
    return under.mean() - before.mean(), before.var(ddof=1) + under.var(ddof=1)


def test_the_fault_knobs_fail_trials_3_and_4(runs: Runs) -> None:
    lines = runs.failed_out.splitlines()
    assert (
        lines[0]
        == f"campaign 1 completed: 2 trials completed, 2 failed, 17 observations in {runs.failed}"
    )
    assert lines[2] == (
        "retry the failed trials with: gyrostand campaign resume 1 --retry-failed "
        f"--db {runs.failed}"
    )
    assert query(runs.failed, 'SELECT "index", attempt, status, failure_reason FROM trial') == [
        (1, 1, "completed", None),
        (2, 1, "completed", None),
        (3, 1, "failed", SILENCE),
        (4, 1, "failed", STUCK),
    ]


def test_retry_acquires_a_new_attempt_and_keeps_the_failed_one(runs: Runs, tmp_path: Path) -> None:
    db = copy(runs, tmp_path)
    first_attempt = attempt_rows(db, 3, 1)
    assert len(first_attempt) == 1  # the bus fell silent in the second still window
    failed_events = attempt_events(db, 3, 1)
    assert ("bus silence", SILENCE) in failed_events

    code, out, err = invoke("campaign", "retry", "1", "--trial", "3", "--db", str(db), "--quiet")

    assert code == 0, err
    lines = out.splitlines()
    assert lines[:2] == [
        f"trial 3: attempt 2 (attempt 1 failed: {SILENCE})",
        f"campaign 1 completed: 3 trials completed, 1 failed, 22 observations in {db}",
    ]
    assert lines[3:] == [
        f"retry the failed trials with: gyrostand campaign resume 1 --retry-failed --db {db}"
    ]
    assert query(db, 'SELECT "index", attempt, status, failure_reason FROM trial') == [
        (1, 1, "completed", None),
        (2, 1, "completed", None),
        (3, 1, "failed", SILENCE),
        (4, 1, "failed", STUCK),  # resume does not retry it: only --trial 4 or --retry-failed
        (3, 2, "completed", None),
    ]
    assert attempt_rows(db, 3, 1) == first_attempt
    assert attempt_events(db, 3, 1) == failed_events
    assert attempt_events(db, 3, 2)[0] == (
        "retry",
        f"trial 3: attempt 2 supersedes attempt 1, which failed: {SILENCE}",
    )
    new = attempt_rows(db, 3, 2)
    assert [(r[2], r[3]) for r in new] == [(j, k) for j in (1, 2) for k in (1, 2, 3)]
    # as the uninterrupted run of trial 3, on the campaign's clock
    assert new == reference_rows(runs, 3, run_clock(db))

    code, out, _ = invoke("campaign", "status", "1", "--db", str(db))
    assert code == 0 and f"trial 3: attempt 2 completed (attempt 1 failed: {SILENCE})\n" in out

    code, out, err = invoke("analyze", "1", "--db", str(db), "--json")
    assert code == 0, err
    analysis = json.loads(out)
    assert [t["index"] for t in analysis["trials"]] == [1, 2, 3]
    delta, variance = delta_and_variance(new)
    assert analysis["trials"][2]["delta_deg"] == pytest.approx(delta, rel=1e-12, abs=1e-12)
    assert analysis["trials"][2]["var_deg2"] == pytest.approx(variance, rel=1e-9)
    superseded = {
        "index": 3,
        "attempt": 1,
        "role": "fit",
        "status": "failed",
        "reason": f"superseded by attempt 2 (retry); it failed: {SILENCE}",
        "superseded_by": 2,
    }
    failed = {
        "index": 4,
        "attempt": 1,
        "role": "control",
        "status": "failed",
        "reason": f"trial failed: {STUCK}",
        "superseded_by": None,
    }
    assert analysis["left_out"] == [superseded, failed]
    warnings = [line for line in err.splitlines() if not line.startswith("analyze: ")]
    assert warnings == [f"warning: trial 4 left out of the analysis (trial failed: {STUCK})"]
    # the analysis says so first (a superseded attempt is replaced, not missing)
    assert analysis["warnings"][0] == (
        f"not analysed: trial 4 (control): trial failed: {STUCK}; the fit uses 3 fit trials "
        f"({analysis['fit']['dof']} residual degrees of freedom)"
    )

    code, out, _ = invoke("analyze", "1", "--db", str(db))
    assert code == 0
    assert (
        "TRIALS LEFT OUT OF THE ANALYSIS\n"
        f"trial 3 attempt 1 (fit, failed): superseded by attempt 2 (retry); it failed: {SILENCE}\n"
        f"trial 4 attempt 1 (control, failed): trial failed: {STUCK}\n\n"
    ) in out

    code, _, err = invoke("report", "1", "--db", str(db), "-f", "html,json", "--out", str(tmp_path))
    assert code == 0, err
    document = json.loads((tmp_path / "campaign-1.json").read_text())
    assert document["acquisition"]["left_out"] == [superseded, failed]
    assert document["analysis"]["left_out"] == [superseded, failed]
    # the retry restarted the stand (its stand times start again): no trace from the raw logs
    records = document["acquisition"]["records"]
    assert [r["trace"] for r in records] == [None] * 4
    assert document["acquisition"]["raw_log_note"].startswith(
        "The raw CAN logs are not read for the plots (a resume restarted the stand"
    )
    html = (tmp_path / "campaign-1.html").read_text()
    assert "<h3>Trials left out of the analysis</h3>" in html
    assert (
        '<tr><td class="n">3</td><td class="n">1</td><td>fit</td><td>failed</td>'
        f'<td class="t">superseded by attempt 2 (retry); it failed: {SILENCE}</td></tr>'
    ) in html
    assert "<td>completed, attempt 2</td>" in html


def test_resume_retry_failed_retries_every_failed_trial(runs: Runs, tmp_path: Path) -> None:
    db = copy(runs, tmp_path)
    code, out, err = invoke("campaign", "resume", "1", "--retry-failed", "--db", str(db), "--quiet")
    assert code == 0, err
    lines = out.splitlines()
    assert lines[:3] == [
        f"trial 3: attempt 2 (attempt 1 failed: {SILENCE})",
        f"trial 4: attempt 2 (attempt 1 failed: {STUCK})",
        f"campaign 1 completed: 4 trials completed, 0 failed, 24 observations in {db}",
    ]
    assert len(lines) == 4  # nothing left to retry
    # the retry run is the uninterrupted run of trials 3 and 4 on the campaign's stand clock:
    # the same frames, their stand times shifted (all else the same)
    clock_ms = run_clock(db)
    retry_log = Path(lines[3].removeprefix("raw frames: ").split(" (sha256")[0])
    assert frames_unclocked([retry_log], clock_ms) == frames_unclocked([runs.reference_log], 0)
    for index in (3, 4):
        assert attempt_rows(db, index, 2) == reference_rows(runs, index, clock_ms)
    assert query(db, "SELECT count(*) FROM trial WHERE attempt = 1 AND status = 'failed'") == [(2,)]

    code, out, err = invoke("analyze", "1", "--db", str(db), "--json")
    assert code == 0 and all(line.startswith("analyze: ") for line in err.splitlines()), err
    analysis = json.loads(out)
    assert [(t["index"], t["attempt"], t["superseded_by"]) for t in analysis["left_out"]] == [
        (3, 1, 2),
        (4, 1, 2),
    ]
    control = analysis["controls"][0]
    delta, _ = delta_and_variance(reference_rows(runs, 4, clock_ms))
    assert control["index"] == 4
    assert control["observed_deg"] == pytest.approx(delta, rel=1e-12, abs=1e-12)

    code, out, err = invoke("campaign", "resume", "1", "--retry-failed", "--db", str(db))
    assert (code, out, err) == (0, "campaign 1: nothing left to acquire\n", "")


@dataclass(frozen=True)
class Case:
    id: str
    args: tuple[str, ...]
    message: str


BAD = [
    Case("unknown campaign", ("campaign", "retry", "99", "--trial", "3"), "no campaign 99"),
    Case(
        "imported campaign",
        ("campaign", "retry", "2", "--trial", "1"),
        "campaign 2 was imported from a file (source 'import'): only a campaign run on the stand "
        "can be resumed or retried",
    ),
    Case(
        "no such trial",
        ("campaign", "retry", "1", "--trial", "9"),
        "campaign 1 has no trial 9 (its trials are 1 to 4)",
    ),
    Case(
        "completed trial, with a failed one",
        ("campaign", "retry", "1", "--trial", "3", "--trial", "2"),
        "trial 2 is completed: only a failed trial can be retried",
    ),
    Case("no trial", ("campaign", "retry", "1"), "Missing option '--trial'"),
    Case("trial not a number", ("campaign", "retry", "1", "--trial", "x"), "valid integer"),
    Case(
        "bad bus option",
        ("campaign", "retry", "1", "--trial", "3", "--speedup", "0"),
        "--speedup must be > 0",
    ),
    Case(
        "retry failed of an imported campaign",
        ("campaign", "resume", "2", "--retry-failed"),
        "only a campaign run on the stand can be resumed or retried",
    ),
]


@pytest.mark.parametrize("case", BAD, ids=[c.id for c in BAD])
def test_bad_retry_is_one_line_and_touches_nothing(case: Case, runs: Runs, tmp_path: Path):
    db = copy(runs, tmp_path)
    code, _, _ = invoke("import", str(Path("examples/paper.csv").resolve()), "--db", str(db))
    assert code == 0  # campaign 2
    before = db_state(checkpointed(db))
    code, out, err = invoke(*case.args, "--db", str(db))
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("gyrostand: error: "), err
    assert case.message in lines[0] and code == 2 and out == ""
    assert db_state(db) == before


def test_retry_while_another_process_holds_the_campaign(runs: Runs, tmp_path: Path) -> None:
    db = copy(runs, tmp_path)
    before = db_state(checkpointed(db))
    fd = os.open(f"{db}.campaign-1.lock", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a running campaign holds it
        code, out, err = invoke("campaign", "retry", "1", "--trial", "3", "--db", str(db))
    finally:
        os.close(fd)
    assert (code, out) == (1, "")
    assert err == (
        "gyrostand: error: campaign 1 is being acquired by another process; "
        "wait for it to end or stop it first\n"
    )
    assert db_state(db) == before


def test_a_retried_campaign_is_not_re_run_from_its_start(runs: Runs, tmp_path: Path) -> None:
    """A killed simulated campaign is resumed by re-running it from its start (the database
    holds a prefix of that run); a retry departs from it, so the resume restarts instead."""
    db = copy(runs, tmp_path)
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE raw_log_segment SET ending = 'killed'")  # as a kill -9 leaves it
        conn.execute("UPDATE campaign SET status = 'running'")
    sessions = open_database(sqlite_url(db))
    plan = parse_plan(query(db, "SELECT plan_toml FROM campaign")[0][0])
    store = CampaignStore(sessions, 1)
    assert resume_start(store, plan, plan) == "continued"
    assert retry_trials(sessions, 1, [3]) == (RetriedTrial(3, 2, SILENCE),)
    assert resume_start(store, plan, plan) == "restarted"
    sessions.kw["bind"].dispose()
