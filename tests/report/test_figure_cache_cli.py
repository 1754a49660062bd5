"""A report made again in a fresh process takes its figures from the cache (`report.figure_cache`):
it imports no matplotlib and writes the same figures (two `gyrostand report` processes: slow
stage)."""

import os
import re
import subprocess
import sys
from pathlib import Path

from gyrostand.report import figure_cache

from .conftest import import_paper

IMPORTED = re.compile(r"^import time:\s+\d+ \|\s+\d+ \| *(\S+)$", re.MULTILINE)


def test_a_report_made_again_draws_nothing(tmp_path: Path) -> None:
    """`gyrostand report` twice in fresh processes: the second imports no matplotlib and writes
    the same HTML."""
    stored = import_paper(tmp_path)
    env = os.environ | {figure_cache.ENV: str(tmp_path / "figures")}
    figures = []
    for run in ("first", "again"):
        out = tmp_path / run
        done = subprocess.run(
            [sys.executable, "-X", "importtime", "-m", "gyrostand", "report", "1"]
            + ["--db", stored.url, "--out", str(out), "-f", "html"],
            capture_output=True,
            text=True,
            env=env,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr[-2000:]
        modules = set(IMPORTED.findall(done.stderr))
        assert ("matplotlib" in modules) == (run == "first")
        figures.append(re.findall(r"<img [^>]*>", (out / "campaign-1.html").read_text()))
    assert figures[0] == figures[1] and len(figures[0]) == 4  # measured, residuals, path, forecast
