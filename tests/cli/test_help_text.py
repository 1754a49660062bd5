"""`--help` reads well: flags without a type, arguments named in the usage line as FILE not
{file}, every command summed up in one sentence on one line, shell completion offered."""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import typer
from typer.testing import CliRunner

from gyrostand.cli import app

runner = CliRunner()
SENTENCE_END = re.compile(r"[.!?]\s+[A-Z]")  # a full stop, then the next sentence


def _commands(command: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


COMMANDS = list(_commands(typer.main.get_command(app)))


def help_of(path: tuple[str, ...], width: int = 200) -> str:
    result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": str(width)})
    assert result.exit_code == 0, result.output
    return result.output


def command_rows(output: str) -> list[tuple[str, str]]:
    """(name, description) per row of the help's Commands panel; a continuation row has no
    name."""
    rows, inside = [], False
    for line in output.splitlines():
        if "─ Commands ─" in line:
            inside = True
            continue
        if inside and line.startswith("╰"):
            break
        if inside:
            cells = line.strip("│ ").split(None, 1)
            name = cells[0] if line[2:3] != " " else ""
            text = line.strip("│ ")[len(name) :].strip()
            rows.append((name, text))
    return rows


def test_no_type_for_flags_and_no_braces_in_usage() -> None:
    for path, _ in COMMANDS:
        output = help_of(path)
        assert "<bool>" not in output, f"{' '.join(path)} --help shows <bool>"
        assert not re.search(r"\{[A-Za-z_]+\}", output), f"{' '.join(path)} --help: {{...}}"
    assert "Usage: gyrostand replay [OPTIONS] LOG" in help_of(("replay",))
    assert "[CAMPAIGN]" in help_of(("analyze",))


def test_every_command_is_one_sentence_on_one_line() -> None:
    groups = [path for path, command in COMMANDS if getattr(command, "commands", None)]
    assert len(groups) >= 3  # gyrostand, campaign, plan
    checked = 0
    for path in groups:
        rows = command_rows(help_of(path))
        assert rows, path
        for name, text in rows:
            assert name, f"{' '.join(path)}: description cut onto a second line: {text!r}"
            assert text.endswith("."), f"{name}: {text!r}"
            assert not SENTENCE_END.search(text), f"{name}: more than one sentence: {text!r}"
            checked += 1
    assert checked >= 12


def test_shell_completion_is_offered() -> None:
    output = help_of(())
    assert "--install-completion" in output and "--show-completion" in output


def test_paragraphs_are_wrapped_to_the_terminal_not_where_the_source_breaks() -> None:
    wide = help_of(("fleet", "simulate"))
    assert "drawn from the type's distribution" in wide  # on one line at 200 columns
