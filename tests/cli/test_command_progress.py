"""Commands that take seconds say on stderr what they are doing, a plain line per stage when
stderr is not a terminal (here: captured), and close with a summary and the time taken; their
results stay on stdout. (`campaign run`: tests/cli/test_progress.py; `fleet simulate`:
tests/cli/test_fleet_commands.py.)"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from tests.acquisition.harness import ROOT

from .conftest import Stand

TOOK = r" \(\d+\.\d s\)"  # the summary's wall time


@pytest.fixture(scope="module")
def paper(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("progress") / "paper.sqlite"
    result = CliRunner().invoke(
        app, ["import", str(ROOT / "examples" / "paper.csv"), "--db", str(db)]
    )
    assert result.exit_code == 0, result.output
    return db


def progress(command: str, *args: str) -> tuple[list[str], str]:
    """The command's progress lines (stderr lines starting `COMMAND: `) and its stdout."""
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    assert "\x1b" not in result.stderr  # plain text: no cursor movement, no colour
    lines = [line for line in result.stderr.splitlines() if line.startswith(f"{command}: ")]
    return lines, result.stdout


def test_analyze_a_stored_campaign(paper: Path) -> None:
    lines, out = progress("analyze", "analyze", "1", "--db", str(paper))
    assert lines[0] == f"analyze: campaign 1 in {paper}: analysing it (the run is recorded)"
    assert re.fullmatch(
        f"analyze: campaign 1: 4 trials fitted, the analysis recorded{TOOK}", lines[1]
    )
    assert len(lines) == 2 and "COCHRAN" in out and "analyze:" not in out


def test_export(paper: Path, tmp_path: Path) -> None:
    out_file = tmp_path / "c1.csv"
    lines, out = progress("export", "export", "1", "--db", str(paper), "--out", str(out_file))
    # the paper as imported: its 6 trials, no observations or series of their own
    assert len(lines) == 1
    assert re.fullmatch(f"export: campaign 1: 6 rows in 3 tables written{TOOK}", lines[0])
    assert f"wrote {out_file}: 0 observations" in out


def test_report_closes_with_a_summary(paper: Path, tmp_path: Path) -> None:
    args = ("report", "1", "--db", str(paper), "--out", str(tmp_path), "-f", "json")
    lines, out = progress("report", *args)
    assert lines[0].startswith("report: campaign 1 in ")  # its stages: test_progress.py
    assert re.fullmatch(f"report: campaign 1: 1 files written in {tmp_path}{TOOK}", lines[-1])
    assert out == f"wrote json: {tmp_path / 'campaign-1.json'}\n"


def test_replay(stand: Stand, tmp_path: Path) -> None:
    db = tmp_path / "replayed.sqlite"
    args = ("replay", str(stand.blf), "--plan", str(stand.plan), "--db", str(db))
    lines, out = progress("replay", *args)
    assert lines[0] == f"replay: logs read; re-deriving the observations into {db}"
    # the plan's 2 trials, 2 series each, N = 3
    assert re.fullmatch(f"replay: campaign 1: 12 observations{TOOK}", lines[1]) and len(lines) == 2
    assert "campaign 1" in out
