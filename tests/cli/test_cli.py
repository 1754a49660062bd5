"""The CLI skeleton: version, help, and honest non-zero exits for what is not built."""

import re
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import typer
from typer.testing import CliRunner

from gyrostand import __version__
from gyrostand.cli import app

runner = CliRunner()


def test_module_version() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "gyrostand", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == f"gyrostand {__version__}"
    assert __version__ == "0.1.0"


def test_help_lists_command_groups() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for group in (
        "simulate",
        "campaign",
        "analyze",
        "report",
        "import",
        "export",
        "replay",
        "demo",
    ):
        assert group in result.output


def _commands(command: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


def test_help_keeps_bracketed_words() -> None:
    """Rich reads "[word]" as markup and drops it: every bracketed word of a command's or an
    option's help (plan tables such as [acceptance]) must reach the rendered --help."""
    checked = 0
    for path, command in _commands(typer.main.get_command(app)):
        texts = [command.help or "", *(getattr(p, "help", None) or "" for p in command.params)]
        wanted = [word for text in texts for word in re.findall(r"\[[a-z_]+\]", text)]
        if not wanted:
            continue
        output = runner.invoke(app, [*path, "--help"], terminal_width=200).output
        for word in wanted:
            assert word in output, f"{' '.join(path)} --help lost {word}"
            checked += 1
    assert checked > 0


def test_help_does_not_load_the_heavy_libraries() -> None:
    """`gyrostand --help` stays quick: the commands import the layers when they run, so the CLI
    module alone loads neither scipy, matplotlib, pandas nor SQLAlchemy (about 2 s together)."""
    heavy = ("scipy", "matplotlib", "pandas", "sqlalchemy", "alembic")
    code = f"import sys, gyrostand.cli; print([m for m in {heavy!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_each_command_is_loaded_from_the_module_that_registers_it() -> None:
    """`cli.COMMANDS` (a command line imports only its command's module) names exactly the
    commands each `cmd_*` module's `register` adds, and `--help` lists them all."""
    import importlib
    from pathlib import Path

    from gyrostand.cli import COMMANDS, use_help_layout

    folder = Path(importlib.import_module("gyrostand.cli").__file__ or "").parent
    modules = {
        path.stem
        for path in folder.glob("cmd_*.py")
        if "\ndef register(app: typer.Typer)" in path.read_text(encoding="utf-8")
    }
    assert modules == set(COMMANDS.values())
    registered: dict[str, str] = {}
    for module in modules:
        typer_app = typer.Typer()
        importlib.import_module(f"gyrostand.{module}").register(typer_app)
        use_help_layout(typer_app)
        names = typer.main.get_group(typer_app).commands
        registered.update(dict.fromkeys(names, module))
    assert registered == COMMANDS
    assert list(typer.main.get_command(app).commands) == list(COMMANDS)
    output = runner.invoke(app, ["--help"], terminal_width=200).output
    assert [name for name in COMMANDS if f"│ {name} " in output] == list(COMMANDS)
