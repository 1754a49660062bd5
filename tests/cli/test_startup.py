"""Start-up: a light command imports only what it uses. Each runs in a process of its own that
writes the names of its modules (`sys.modules`) when it exits; the heavy packages a command does
not need must not be among them (their wall time: bench/bench_cli_startup.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gyrostand.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[2]
ANALYSIS = {"numpy", "scipy", "pandas", "matplotlib", "pyarrow", "openpyxl", "jinja2"}
DATABASE = {"sqlalchemy", "alembic", "gyrostand.db.models"}
BUS = {"can", "cantools"}
MIGRATIONS = {"alembic", "mako"}  # a database at the code's schema is read without them
COMMAND_MODULES = {f"gyrostand.{module}" for module in COMMANDS.values()}
SHARED = {"gyrostand.cmd_data"}  # `open_db`, which the campaign commands share with import
# `python -m gyrostand ARGS` that writes its modules' names to the file $MODULES_OUT at exit
PROBE = """
import atexit, os, runpy, sys
atexit.register(lambda: open(os.environ["MODULES_OUT"], "w").write("\\n".join(sys.modules)))
sys.argv[0] = "gyrostand"
runpy.run_module("gyrostand", run_name="__main__", alter_sys=True)
"""


def imported(*args: str, cwd: Path) -> set[str]:
    """Every module `gyrostand ARGS` imported."""
    out = cwd / "modules.txt"
    run = subprocess.run(
        [sys.executable, "-c", PROBE, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "MODULES_OUT": str(out)},
        timeout=120,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    return set(out.read_text().split())


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
    (("--version",), ANALYSIS | DATABASE | BUS | COMMAND_MODULES | {"pydantic", "rich"}),
    (("--help",), ANALYSIS | DATABASE | BUS | {"pydantic", "gyrostand.plan"}),
    (
        ("plan", "check", str(ROOT / "examples" / "paper.toml")),
        ANALYSIS | DATABASE | COMMAND_MODULES - {"gyrostand.cmd_plan"},
    ),
    (
        ("campaign", "status", "1", "--db", "{db}"),
        ANALYSIS | BUS | MIGRATIONS | COMMAND_MODULES - {"gyrostand.cmd_campaign", *SHARED},
    ),
    (
        ("campaign", "list", "--db", "{db}"),
        ANALYSIS | BUS | MIGRATIONS | COMMAND_MODULES - {"gyrostand.cmd_campaign", *SHARED},
    ),
]


@pytest.mark.parametrize(("args", "unneeded"), LIGHT, ids=[" ".join(a[:2]) for a, _ in LIGHT])
def test_a_light_command_does_not_import_what_it_does_not_use(
    args: tuple[str, ...], unneeded: set[str], db: Path, tmp_path: Path
) -> None:
    """Before: `--version` imported numpy, python-can and cantools; `plan check` scipy and
    SQLAlchemy, later still numpy; `campaign status` numpy, scipy and pandas, later still
    Alembic (and its reading of every migration file); each imported every command's module."""
    modules = imported(*(a.format(db=db) for a in args), cwd=tmp_path)
    assert "gyrostand.cli" in modules  # (the command ran)
    assert sorted(unneeded & modules) == []
