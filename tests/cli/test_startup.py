"""Start-up: a light command imports only what it uses. Each runs in a process of its own under
`python -X importtime` (every module imported is named); the heavy packages a command does not
need must not be among them (their wall time: bench/bench_cli_startup.py)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LINE = re.compile(r"^import time:\s+\d+ \|\s+\d+ \| *(\S+)$", re.MULTILINE)
ANALYSIS = {"numpy", "scipy", "pandas", "matplotlib", "pyarrow", "openpyxl", "jinja2"}
DATABASE = {"sqlalchemy", "alembic", "gyrostand.db.models"}
BUS = {"can", "cantools"}
MIGRATIONS = {"alembic", "mako"}  # a database at the code's schema is read without them


def imported(*args: str, cwd: Path) -> set[str]:
    """Every module `gyrostand ARGS` imported (and each of its parent packages)."""
    run = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "gyrostand", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    names = set(LINE.findall(run.stderr))
    return names | {name.rsplit(".", i)[0] for name in names for i in range(name.count(".") + 1)}


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("startup") / "db.sqlite"
    paper = ROOT / "examples" / "paper.csv"
    run = subprocess.run(
        [sys.executable, "-m", "gyrostand", "import", str(paper), "--db", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    return path


# (command line, the packages it must not import)
LIGHT = [
    (("--version",), ANALYSIS | DATABASE | BUS | {"pydantic", "rich", "gyrostand.plan"}),
    (("--help",), ANALYSIS | DATABASE | BUS | {"pydantic", "gyrostand.plan"}),
    (("plan", "check", str(ROOT / "examples" / "paper.toml")), ANALYSIS | DATABASE),
    (("campaign", "status", "1", "--db", "{db}"), ANALYSIS | BUS | MIGRATIONS),
    (("campaign", "list", "--db", "{db}"), ANALYSIS | BUS | MIGRATIONS),
]


@pytest.mark.parametrize(("args", "unneeded"), LIGHT, ids=[" ".join(a[:2]) for a, _ in LIGHT])
def test_a_light_command_does_not_import_what_it_does_not_use(
    args: tuple[str, ...], unneeded: set[str], db: Path, tmp_path: Path
) -> None:
    """Before: `--version` imported numpy, python-can and cantools; `plan check` scipy and
    SQLAlchemy, later still numpy; `campaign status` numpy, scipy and pandas, later still
    Alembic (and its reading of every migration file)."""
    modules = imported(*(a.format(db=db) for a in args), cwd=tmp_path)
    assert "gyrostand.cli" in modules  # (the command ran)
    assert sorted(unneeded & modules) == []
