"""A raw log on a full disk: the run stops the stand as it does when the database refuses writes
(one line, exit code 1, resumable), and its segment is recorded with the frames the file really
holds, never "closed" (that is for a log with every frame of its run). The disk: a 32 KiB tmpfs
for the raw log folder alone, in a mount namespace of its own (root and util-linux `unshare`;
skipped with the reason elsewhere)."""

from __future__ import annotations

import json
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.frames.logfile import read_raw_frames, sha256_of
from tests.acquisition.harness import FAST_SIM, plan_text

from .test_retry import TRIALS

ROOT = Path(__file__).resolve().parents[2]


def full_disk_for_root(folder: Path, size: str) -> list[str]:
    """How to run a command with `folder` a tmpfs of `size` (ENOSPC past it), its files copied
    to `folder`-saved/ when the command has ended (the tmpfs goes with the namespace)."""
    if shutil.which("unshare") is None:
        pytest.skip("no util-linux unshare: no small disk for the raw log")
    prefix = ["unshare", "--mount", "--propagation", "private", "sh", "-c"]
    mount = f'mount -t tmpfs -o size={size} tmpfs "{folder}"'
    probe = subprocess.run([*prefix, mount], capture_output=True, text=True, timeout=60)
    if probe.returncode != 0:
        pytest.skip(f"no tmpfs mount here (root in a mount namespace): {probe.stderr.strip()}")
    save = f'cp -a "{folder}/." "{folder}-saved/"'
    return [*prefix, f'{mount} && "$@"; code=$?; {save}; exit $code', "sh"]


def test_raw_log_on_a_full_disk_stops_the_campaign_resumably(tmp_path: Path) -> None:
    db, raw = tmp_path / "db.sqlite", tmp_path / "raw"
    raw.mkdir()
    (tmp_path / "raw-saved").mkdir()
    plan = tmp_path / "plan.toml"
    plan.write_text(plan_text(TRIALS, database=str(db), raw_dir=str(raw)) + FAST_SIM)
    lines = json.dumps([["campaign", "run", str(plan), "--quiet"]])
    command = [*full_disk_for_root(raw, "32k"), sys.executable, "-m", "tests.cli.run_commands"]
    proc = subprocess.run([*command, lines], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    ((code, err),) = json.loads(proc.stdout)
    assert code == 1 and len(err.splitlines()) == 1, err
    log = raw / "db-campaign-1.blf"
    assert err.startswith(
        f"gyrostand: error: campaign 1 stopped: the raw log {log} cannot be written: "
        "[Errno 28] No space left on device; what was committed is kept: resume it "
        f"(gyrostand campaign resume 1 --db {db}) once the disk has room"
    ), err
    saved = tmp_path / "raw-saved" / "db-campaign-1.blf"
    in_file = sum(len(r) for r in read_raw_frames(saved))  # up to its last complete block
    with sqlite3.connect(db) as conn:
        status = conn.execute("SELECT status FROM campaign").fetchone()
        segment = conn.execute("SELECT frames, sha256, ending FROM raw_log_segment").fetchall()
        interrupted = conn.execute(
            "SELECT message FROM event WHERE kind = 'interrupted'"
        ).fetchall()
        observations = conn.execute("SELECT count(*) FROM observation").fetchone()[0]
    assert status == ("stopped",)
    assert segment == [(in_file, sha256_of(saved), "killed")] and in_file > 0
    assert interrupted == [("the raw log cannot be written: [Errno 28] No space left on device",)]
    assert 0 < observations < 4 * 2 * 3

    # the disk has room again (the tmpfs is gone): the campaign is resumed to its end
    result = CliRunner().invoke(app, ["campaign", "resume", "1", "--db", str(db), "--quiet"])
    assert result.exit_code == 0, result.stderr
    with sqlite3.connect(db) as conn:
        assert conn.execute("SELECT status FROM campaign").fetchone() == ("completed",)
        starts = conn.execute("SELECT start, ending FROM raw_log_segment ORDER BY seq").fetchall()
    assert starts == [("new", "killed"), ("restarted", "closed")]
