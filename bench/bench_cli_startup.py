"""Start-up of the light commands: `--version`, `--help`, `plan check`, `campaign status` and
`campaign list` (on a database holding the paper's campaign, imported from examples/paper.csv).
Prints, per command, the wall time of `python -m gyrostand ...` (best and median of --runs), its
CPU time (user + system, best), and the `python -X importtime` total (the sum of every module's
own import time, best run), with the heaviest top-level packages it imported.

Target (issue 36): each <= 0.3 s on an idle machine: OK or NOT per command, on the best wall
time (the load average is printed: on a busy machine the figures are not the idle ones).
What the commands cannot do without (each command line imports only its command's module):
Python and typer (typer coerces a command's arguments with pydantic TypeAdapters, so every
command but `--version` and `--help` imports pydantic); `--help` typer's rich help, whose module
imports rich.markdown (markdown_it, pygments) and rich.traceback (attrs) though they are not
used; `plan check` pydantic (the plan model's ~35 classes) and cantools (which imports
python-can) for the DBC's ranges; `campaign status` and `campaign list` SQLAlchemy with its ORM
(the models and their mapper configuration). A current database's schema version is read
without Alembic. A development install (`pip install -e`) adds its import finder's start-up.

The commands run with the bytecode cache allowed (PYTHONDONTWRITEBYTECODE removed from their
environment, and each command run once before it is timed, which writes the cache), as on a
user's install: without it every process compiles gyrostand's own modules.

Run: .venv/bin/python bench/bench_cli_startup.py [--runs 7]"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 0.3
GYROSTAND = [sys.executable, "-m", "gyrostand"]
LINE = re.compile(r"^import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)$")
# a user's install writes .pyc files; this environment may forbid it (PYTHONDONTWRITEBYTECODE)
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def commands(db: Path) -> dict[str, list[str]]:
    return {
        "--version": ["--version"],
        "--help": ["--help"],
        "plan check": ["plan", "check", str(ROOT / "examples" / "paper.toml")],
        "campaign status": ["campaign", "status", "1", "--db", str(db)],
        "campaign list": ["campaign", "list", "--db", str(db)],
    }


def wall_s(args: list[str]) -> tuple[float, float]:
    """The command's wall time and CPU time (user + system, s): on a busy machine the CPU time
    is the steadier of the two, though still above the idle one."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([*GYROSTAND, *args], capture_output=True, check=True, env=ENV)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def import_times(args: list[str]) -> tuple[float, Counter[str]]:
    """The `-X importtime` total (s) and each top-level package's own time summed (s)."""
    err = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "gyrostand", *args],
        capture_output=True,
        text=True,
        check=True,
        env=ENV,
    ).stderr
    own: Counter[str] = Counter()
    for line in err.splitlines():
        if m := LINE.match(line):
            own[m[4].split(".")[0]] += int(m[1]) / 1e6
    return sum(own.values()), own


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=7)
    runs = parser.parse_args().runs
    with tempfile.TemporaryDirectory() as folder:
        db = Path(folder) / "bench.sqlite"
        subprocess.run(
            [*GYROSTAND, "import", str(ROOT / "examples" / "paper.csv"), "--db", str(db)],
            capture_output=True,
            check=True,
            env=ENV,
        )
        for args in commands(db).values():  # writes the bytecode cache of what each imports
            wall_s(args)
        load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
        print(f"load average {load}; target: each <= {TARGET_S} s on an idle machine")
        print("bytecode cache allowed and warmed (PYTHONDONTWRITEBYTECODE unset), as installed")
        print(
            f"{'command':<16} {'wall best':>9} {'median':>7} {'cpu best':>8} {'imports':>8} "
            f"{'':>4}  "
            "heaviest packages"
        )
        for name, args in commands(db).items():
            walls, cpus = zip(*(wall_s(args) for _ in range(runs)), strict=True)
            total, own = min((import_times(args) for _ in range(3)), key=lambda r: r[0])
            heavy = ", ".join(f"{p} {s * 1000:.0f} ms" for p, s in own.most_common(4))
            verdict = "OK" if min(walls) <= TARGET_S else "NOT"
            print(
                f"{name:<16} {min(walls):>8.3f}s {statistics.median(walls):>6.3f}s "
                f"{min(cpus):>7.3f}s {total:>7.3f}s {verdict:>4}  {heavy}"
            )


if __name__ == "__main__":
    main()
