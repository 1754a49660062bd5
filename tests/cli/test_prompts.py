"""`campaign run --answer ID=VALUE`: the plan's prompts answered on the command line (stored as
events, trial prompts when the trial comes); a bad or missing answer without a terminal is one
line, exit code 2, before anything is written."""

from __future__ import annotations

import sqlite3
from contextlib import closing
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app

from .conftest import write_plan

PROMPTS = """
[[prompt]]
id = "plate"
text = "serial number on the plate?"
kind = "text"
before = "campaign"

[[prompt]]
id = "mounted"
text = "compass mounted and powered?"
before = 2
"""


@pytest.fixture
def plan(tmp_path: Path) -> Path:
    path = write_plan(tmp_path)
    path.write_text(path.read_text() + PROMPTS)
    return path


def run(plan: Path, *answers: str):
    args = [a for answer in answers for a in ("--answer", answer)]
    return CliRunner().invoke(app, ["campaign", "run", str(plan), "--quiet", *args])


@pytest.mark.parametrize(
    ("answers", "error"),
    [
        ((), "the plan asks before the campaign: serial number on the plate? "
             "(give --answer plate=...)"),
        (("plate=GY-7", "mounted=no"),
         "--answer mounted: answer yes to confirm (compass mounted and powered?)"),
        (("plate=GY-7", "oil=yes"),
         "--answer oil: the plan has no such prompt (its prompts: plate, mounted)"),
        (("plate",), "--answer 'plate': give ID=VALUE"),
        (("plate=  ",), "--answer plate: the answer is empty (serial number on the plate?)"),
    ],
)  # fmt: skip
def test_bad_or_missing_answers_are_one_line_and_nothing_is_written(
    plan: Path, answers: tuple[str, ...], error: str
) -> None:
    result = run(plan, *answers)
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == [f"gyrostand: error: {error}"]
    assert not (plan.parent / "db.sqlite").exists()


def test_answers_on_the_command_line_are_stored_as_events(plan: Path) -> None:
    result = run(plan, "plate=<b>GY-7</b>", "mounted=Y")
    assert result.exit_code == 0, result.stderr
    with closing(sqlite3.connect(plan.parent / "db.sqlite")) as conn:
        events = conn.execute(
            "SELECT kind, message, trial_id FROM event WHERE kind IN ('prompt', 'answer') "
            "ORDER BY id"
        ).fetchall()
        first_of_trial_2 = conn.execute("SELECT MIN(id) FROM event WHERE trial_id = 2").fetchone()
        mounted = conn.execute("SELECT id FROM event WHERE message = 'mounted: yes'").fetchone()
    assert events == [
        ("prompt", "plate: serial number on the plate?", None),
        ("answer", "plate: <b>GY-7</b>", None),
        ("prompt", "mounted: compass mounted and powered?", None),
        ("answer", "mounted: yes", None),
    ]
    assert mounted[0] < first_of_trial_2[0]  # asked when trial 2 came, before it began
