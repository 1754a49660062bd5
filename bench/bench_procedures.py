"""The type-approval campaign (examples/type-approval.toml) end to end in virtual time: the
standard's procedures (settling from switch-on, settle point, three run-ups, rolling points; about
32 h of stand time) and the paper's six trials by `gyrostand campaign run`, then
`gyrostand report` (JSON). Prints the wall and CPU seconds of each command and the report's one
decision per clause.

Target (issue 35): the campaign under 60 s of wall time on this machine. A loaded machine
stretches the wall time, hardly the CPU time, so both are printed with the load average (the
1-minute one before and after): a wall time measured at a load above the cores counts only
beside its CPU time.

Run: .venv/bin/python bench/bench_procedures.py"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 60.0


def timed(args: list[str], cwd: Path) -> tuple[float, float]:
    """Wall and CPU seconds of one gyrostand command (fails loudly)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "gyrostand", *args], cwd=cwd, check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def load() -> str:
    """The 1-, 5- and 15-minute load averages and the cores."""
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} cores"


def main() -> int:
    print(f"before: {load()}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        shutil.copy(ROOT / "examples" / "type-approval.toml", folder)
        run = timed(["campaign", "run", "type-approval.toml", "--quiet"], folder)
        db = "runs/type-approval.sqlite"
        report = timed(["report", "1", "--db", db, "--out", "out", "-f", "json"], folder)
        doc = json.loads(next((folder / "out").glob("*.json")).read_text())
    print(f"campaign run (procedures + 6 trials): {run[0]:.1f} s wall, {run[1]:.1f} s CPU")
    print(f"report (JSON): {report[0]:.1f} s wall, {report[1]:.1f} s CPU")
    for item in doc["compliance"]["items"]:
        value = item["value_deg"]
        shown = "-"
        if value is not None:
            shown = f"{value:.3f} +/- {item['uncertainty_deg']:.3f} {item['unit']}"
        print(f"  {item['id']:<22} {item['verdict']:<13} {shown:<22} limit {item['limit_text']}")
    print(f"after: {load()}")
    ok = run[0] < TARGET_S
    verdict = "OK" if ok else "NOT"
    print(
        f"{verdict}: campaign {run[0]:.1f} s wall ({run[1]:.1f} s CPU) against the target of "
        f"{TARGET_S:g} s wall"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
