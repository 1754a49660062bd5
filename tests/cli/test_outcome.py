"""A campaign that ends with too few trials completed to be analysed ends "failed", exit code 1
and one line on stderr, and `campaign status` and `campaign list` (the station's query) say so;
`campaign resume --retry-failed` takes it up again."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from typer.testing import CliRunner

from gyrostand.cli import app
from tests.acquisition.harness import FAST_SIM, plan_text

from .test_retry import TRIALS

# the bus falls silent in trial 3's still series (tests/cli/test_retry.py: ~1350 s)
SILENCE = "\n[bus.simulator.faults]\nsilence_at_s = 1400.0\nsilence_for_s = 10.0\n"
NO_ACK = "\n[bus.simulator.faults]\nno_ack = true\n"


def invoke(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def run(folder: Path, trials: list, faults: str, *, analysed: bool) -> tuple[int, str, str, Path]:
    db = folder / "db.sqlite"
    text = plan_text(trials, database=str(db), raw_dir=str(folder / "raw"), bus_extra=faults)
    if analysed:
        text = text.replace("acquisition_only = true\n", "")
    plan = folder / "plan.toml"
    plan.write_text(text + FAST_SIM)
    return (*invoke("campaign", "run", str(plan), "--quiet"), db)


def query(db: Path, sql: str) -> list[tuple]:
    with sqlite3.connect(db) as conn:
        return [tuple(r) for r in conn.execute(sql)]


def test_a_campaign_whose_every_trial_failed_fails(tmp_path: Path) -> None:
    code, out, err, db = run(tmp_path, TRIALS[:2], NO_ACK, analysed=False)
    assert code == 1
    assert err.splitlines() == [
        "gyrostand: error: campaign 1 failed: it cannot be analysed (0 trials completed, 2 failed)"
    ]
    assert out.splitlines()[0].startswith("campaign 1 failed: 0 trials completed, 2 failed")
    assert "continue with" not in out and "--retry-failed" in out
    assert query(db, "SELECT status FROM campaign") == [("failed",)]
    assert query(db, "SELECT severity, message FROM event WHERE kind = 'campaign failed'") == [
        ("error", "the campaign cannot be analysed: no trial completed")
    ]
    code, out, _ = invoke("campaign", "status", "1", "--db", str(db))
    assert code == 0 and out.startswith("campaign 1 (stand): failed (too few trials completed")
    code, out, _ = invoke("campaign", "list", "--status", "failed", "--db", str(db), "--json")
    assert code == 0 and [c["status"] for c in json.loads(out)["campaigns"]] == ["failed"]


def test_too_few_fit_trials_to_analyse_fails_and_a_retry_completes_it(tmp_path: Path) -> None:
    code, out, err, db = run(tmp_path, TRIALS, SILENCE, analysed=True)
    assert code == 1, out
    assert err.splitlines() == [
        "gyrostand: error: campaign 1 failed: it cannot be analysed (3 trials completed, 1 failed)"
    ]
    assert query(db, "SELECT message FROM event WHERE kind = 'campaign failed'") == [
        ("the campaign cannot be analysed: 2 fit trials completed: the analysis needs 3",)
    ]
    assert query(db, 'SELECT "index", status FROM trial ORDER BY "index"') == [
        (1, "completed"),
        (2, "completed"),
        (3, "failed"),
        (4, "completed"),
    ]
    code, out, err = invoke("campaign", "resume", "1", "--retry-failed", "--db", str(db), "--quiet")
    assert code == 0, err
    assert query(db, "SELECT status FROM campaign") == [("completed",)]
    code, _, err = invoke("analyze", "1", "--db", str(db))
    assert code == 0, err
