"""A campaign stopped (SIGINT) and resumed, in real time and in virtual time, is analysed and
reported: every run of a campaign has one campaign time. The simulated stand's clock goes on
across runs (as a stand controller's does), each resumed run marks its start (RUN_START) so the
compass's state is not carried over it, and the read side places a run whose stand clock
restarted (a power-cycled controller, a database from before) after the run before it."""

import json
import signal
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.queries import RUN_START
from tests.artefacts import copy_database

from .harness import FAST_SIM, plan_text
from .test_cli_campaign import start, wait_for_observations

TRIALS = [
    (45.0, 24.0, 6.0, "fit"),
    (315.0, 20.0, 5.0, "fit"),
    (30.0, 22.0, 8.0, "fit"),
    (60.0, 18.0, 4.5, "control"),
]
TIMING = {
    "realtime": 'timing = "realtime"\nspeedup = 1000',
    "virtual": 'timing = "virtual"',
}
OBSERVATIONS = (
    'SELECT t."index", s.j, o.k, o.window_start_ms, o.window_end_ms FROM observation o'
    " JOIN series s ON s.id = o.series_id JOIN trial t ON t.id = s.trial_id ORDER BY o.id"
)

FIRST_RUN = (
    'SELECT t."index", s.j, max(coalesce(max(o.window_end_ms), 0), coalesce(s.settle_done_ms, 0))'
    " FROM series s JOIN trial t ON t.id = s.trial_id"
    " LEFT JOIN observation o ON o.series_id = s.id GROUP BY s.id"
)


def write_plan(folder: Path, timing: str) -> Path:
    text = plan_text(
        TRIALS,
        n_obs=4,
        database=str(folder / "db.sqlite"),
        raw_dir=str(folder / "raw"),
        bus_extra=TIMING[timing],
    )
    text = text.replace("acquisition_only = true\n", "")
    # real time under load: 30 s of wall time for an ack, 20 s without a frame (2 s failed)
    text = text.replace("ack_s = 2.0", "ack_s = 30.0").replace(
        "bus_silence_s = 5.0", "bus_silence_s = 20000.0"
    )
    # the compass's transient model: the analysis fits it across every series of the campaign
    text = text.replace("max_wait_s = 3600.0", "max_wait_s = 3600.0\nundamped_period_s = 240.0")
    text = text.replace(
        "undamped_period_s = 240.0", "undamped_period_s = 240.0\ndamping_ratio = 0.8"
    )
    path = folder / "plan.toml"
    path.write_text(text + FAST_SIM)
    return path


def query(db: Path, sql: str) -> list[tuple]:
    with sqlite3.connect(db) as conn:
        return [tuple(r) for r in conn.execute(sql)]


def invoke(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def stopped_and_resumed(folder: Path, timing: str) -> Path:
    """`campaign run` stopped by SIGINT after 10 of its 32 observations, then resumed to the end."""
    plan, db = write_plan(folder, timing), folder / "db.sqlite"
    proc = start("campaign", "run", str(plan), "--quiet", cwd=folder)
    wait_for_observations(db, 10, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1, err  # stopped (it did not finish before the signal)
    assert query(db, "SELECT status FROM campaign") == [("stopped",)]
    code, out, err = invoke("campaign", "resume", "1", "--db", str(db), "--quiet")
    assert code == 0, err
    assert query(db, "SELECT status FROM campaign") == [("completed",)]
    return db


@pytest.fixture(scope="module")
def virtual_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The campaign stopped and resumed in virtual time, once for the tests of this file (each
    works on a copy)."""
    return stopped_and_resumed(tmp_path_factory.mktemp("virtual"), "virtual")


@pytest.mark.parametrize("timing", ["realtime", "virtual"])
def test_stop_resume_analyse_report(
    tmp_path: Path, timing: str, request: pytest.FixtureRequest
) -> None:
    if timing == "virtual":
        db = copy_database(request.getfixturevalue("virtual_db"), tmp_path / "db.sqlite")
    else:
        db = stopped_and_resumed(tmp_path, timing)
    rows = query(db, OBSERVATIONS)
    assert len(rows) == 4 * 2 * 4
    # one campaign time: in the order they were stored, the windows follow one another
    ends = [(start_ms, end_ms) for *_, start_ms, end_ms in rows]
    assert all(a[1] <= b[0] for a, b in zip(ends, ends[1:], strict=False)), ends
    # the resumed run starts where the stored record stops, and says so
    (run_start,) = query(db, f"SELECT stand_time_ms FROM event WHERE kind = '{RUN_START}'")
    stopped_at = query(db, "SELECT max(stand_time_ms) FROM event WHERE kind = 'interrupted'")
    assert run_start[0] >= stopped_at[0][0] > 0

    code, out, err = invoke("analyze", "1", "--db", str(db), "--json")
    assert code == 0, err
    result = json.loads(out)
    transient = result["transient"]
    assert len(transient["series"]) == 8
    code, out, err = invoke(
        "report", "1", "--db", str(db), "--out", str(tmp_path / "r"), "--format", "html,json"
    )
    assert code == 0, err
    assert (tmp_path / "r").is_dir() and any((tmp_path / "r").glob("*.html"))


def restart_clock(db: Path, t0_ms: int) -> None:
    """Make `db` what a stand whose clock restarts at 0 on every run gives (the simulated stand
    before its clock went on; a power-cycled controller): the resumed run's stand times from
    `t0_ms` on, minus `t0_ms`, and no RUN_START event."""
    with sqlite3.connect(db) as conn:

        def back(t: int | None) -> int | None:
            return t - t0_ms if t is not None and t >= t0_ms else t

        conn.create_function("back", 1, back)
        conn.execute(
            "UPDATE observation SET window_start_ms = back(window_start_ms),"
            " window_end_ms = back(window_end_ms)"
        )
        conn.execute(
            "UPDATE series SET settle_started_ms = back(settle_started_ms),"
            " settle_done_ms = back(settle_done_ms)"
        )
        conn.execute("UPDATE event SET stand_time_ms = back(stand_time_ms)")
        conn.execute(f"DELETE FROM event WHERE kind = '{RUN_START}'")
        for sid, text in conn.execute("SELECT id, settle_outcome FROM series").fetchall():
            if text is None:
                continue
            outcome = json.loads(text)
            outcome["step_ms"] = back(outcome["step_ms"])
            outcome["blocks"] = [[back(a), back(b), v] for a, b, v in outcome["blocks"]]
            conn.execute(
                "UPDATE series SET settle_outcome = ? WHERE id = ?", (json.dumps(outcome), sid)
            )


def test_a_stand_clock_that_restarted_is_placed_after_the_run_before(
    virtual_db: Path, tmp_path: Path
) -> None:
    """The database a stand clock restarting at 0 gives (as before) is analysed: the resumed
    run is placed after the first, and the series the first run acquired whole get the same
    transient left as with the clock going on (their record is the same)."""
    db = copy_database(virtual_db, tmp_path / "db.sqlite")
    ((t0,),) = query(db, f"SELECT stand_time_ms FROM event WHERE kind = '{RUN_START}'")
    first_run = [  # the series the first run acquired whole
        (i, j) for i, j, end in query(db, FIRST_RUN) if end is not None and end < t0
    ]
    assert len(first_run) >= 2  # (stopped after 10 observations)
    code, out, err = invoke("analyze", "1", "--db", str(db), "--json")
    assert code == 0, err
    continued = {(s["trial"], s["j"]): s for s in json.loads(out)["transient"]["series"]}
    restart_clock(db, t0)
    code, out, err = invoke("analyze", "1", "--db", str(db), "--json")
    assert code == 0, err
    restarted = {(s["trial"], s["j"]): s for s in json.loads(out)["transient"]["series"]}
    assert restarted.keys() == continued.keys() and len(restarted) == 8
    for key in first_run:
        assert restarted[key]["left_deg"] == pytest.approx(continued[key]["left_deg"], abs=1e-9)
