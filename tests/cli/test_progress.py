"""Progress when the output is not a terminal (CI, nohup, a pipe): plain lines on stderr for a
campaign (observations, trials, ETA in stand time) and one line per stage of `report`."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

from rich.console import Console
from typer.testing import CliRunner

from gyrostand.acquisition.engine import Phase, Snapshot
from gyrostand.acquisition.progress import PlainProgress
from gyrostand.cli import app

from .conftest import Stand, write_plan

OBSERVATION = re.compile(
    r"^trial (\d)/2, j=([12]) \((before rocking|rocking)\): observation (\d)/3 done; "
    r"stand time \d+:\d\d:\d\d, ETA stand \d+:\d\d:\d\d$"
)


def test_campaign_progress_lines_on_a_pipe(tmp_path: Path) -> None:
    plan = write_plan(tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "gyrostand", "campaign", "run", str(plan)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert "\x1b" not in proc.stderr  # plain text, no cursor movement or colour
    observations = [m.groups() for line in lines if (m := OBSERVATION.match(line))]
    # every observation of both series of both trials, in order, once
    assert [(t, j, k) for t, j, _, k in observations] == [
        (t, j, k) for t in "12" for j in "12" for k in "123"
    ], lines
    assert any(re.match(r"^trial 1/2 ended; stand time", line) for line in lines), lines
    assert any(re.match(r"^trial 2/2 ended; stand time", line) for line in lines), lines
    assert any("settling" in line for line in lines), lines
    assert "campaign 1 completed" in proc.stdout


def test_quiet_prints_no_progress(tmp_path: Path) -> None:
    plan = write_plan(tmp_path)
    result = CliRunner().invoke(app, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 0 and result.stderr == ""


def test_report_says_what_it_is_doing(stand: Stand, tmp_path: Path) -> None:
    db = stand.db_copy(tmp_path)
    result = CliRunner().invoke(
        app, ["report", "1", "--db", str(db), "--out", str(tmp_path), "-f", "json,csv"]
    )
    assert result.exit_code == 0, result.output
    stages = [line for line in result.stderr.splitlines() if line.startswith("report: ")]
    assert len(stages) >= 2, result.stderr
    assert "campaign 1" in stages[0] and "analys" in stages[0]
    assert "json, csv" in stages[-2] and str(tmp_path) in stages[-2]
    assert stages[-1].startswith(f"report: campaign 1: 2 files written in {tmp_path} (")
    assert "wrote json" in result.stdout


def snap(trial: int, j: int, k: int, phase: Phase, values: int = 0, now_s: int = 0) -> Snapshot:
    return Snapshot(
        trial=trial,
        n_trials=2,
        j=j,
        k=k,
        n_obs=3,
        phase=phase,
        now_ms=now_s * 1000,
        values_deg=(0.5,) * values,
        settle_spread_deg=None,
        remaining_ms=600_000 - now_s * 1000,
    )


def plain_lines(snapshots: list[Snapshot], heartbeat_s: float = 3600) -> list[str]:
    console = Console(file=io.StringIO(), width=40)  # narrow: lines are never wrapped
    progress = PlainProgress(console, heartbeat_s=heartbeat_s)
    for s in snapshots:
        progress.update(s)
    assert isinstance(console.file, io.StringIO)
    return console.file.getvalue().splitlines()


def test_plain_progress_infers_what_a_batch_skipped() -> None:
    """A resumed trial 1 (j=1 had 1 observation), then batches that each hold several steps:
    the series the engine left were complete; a trial left is 'ended'."""
    lines = plain_lines(
        [
            snap(1, 1, 2, Phase.SETTLE, 0, 10),  # resume: observation 1 was taken before
            snap(1, 1, 3, Phase.OBSERVE, 1, 70),  # observation 2 taken
            snap(1, 2, 1, Phase.COMMANDS, 0, 100),  # observation 3 and the series: one batch
            snap(1, 2, 3, Phase.COMMANDS, 3, 300),  # all of j=2 in one batch, stop sent
            snap(2, 1, 1, Phase.SETTLE, 0, 320),
            snap(0, 1, 1, Phase.DONE, 0, 330),  # trial 2 failed or ended
        ]
    )
    tail = "; stand time 0:01:40, ETA stand 0:08:20"
    assert lines == [
        "trial 1/2, j=1 (before rocking): settling; stand time 0:00:10, ETA stand 0:09:50",
        "trial 1/2, j=1 (before rocking): observation 2/3 done; stand time 0:01:10, ETA stand "
        "0:08:50",
        f"trial 1/2, j=1 (before rocking): observation 3/3 done{tail}",
        f"trial 1/2, j=2 (rocking): waiting for the stand's acknowledgement{tail}",
        *(
            f"trial 1/2, j=2 (rocking): observation {k}/3 done; stand time 0:05:00, ETA stand "
            "0:05:00"
            for k in (1, 2, 3)
        ),
        "trial 1/2 ended; stand time 0:05:20, ETA stand 0:04:40",
        "trial 2/2, j=1 (before rocking): settling; stand time 0:05:20, ETA stand 0:04:40",
        "trial 2/2 ended; stand time 0:05:30, ETA stand 0:04:30",
    ]


def test_plain_progress_repeats_the_state_after_a_quiet_while() -> None:
    same = [snap(1, 1, 1, Phase.SETTLE, 0, t) for t in (0, 10, 20)]
    assert len(plain_lines(same)) == 1
    assert plain_lines(same, heartbeat_s=0)[1:] == [
        f"trial 1/2, j=1 (before rocking): settling; stand time 0:00:{t}, ETA stand 0:09:{60 - t}"
        for t in (10, 20)
    ]
