"""The `gyrostand` command line: a thin composition root over stand, db, acquisition, analysis.

Each command lives in its own `cmd_*` module (`COMMANDS`), imported when the command line names
one of its commands (or `--help` lists them all): `gyrostand plan check` neither imports the
other commands' modules nor has typer convert their parameters (~20 % of its start-up). The
command modules import the analysis, database and acquisition layers inside the commands, so
`--help` does not wait for scipy, matplotlib, pandas and SQLAlchemy (~2 s).

Here too, for every command: how `--help` reads (`HelpCommand`, `HelpGroup`), and the CLI's
one error boundary (`RootGroup`): a command line that does not parse is one line on stderr
(exit code 2), an unexpected exception one line and a traceback file (exit code 1)."""

from __future__ import annotations

import importlib
import re
import sys
from collections.abc import Iterator, Mapping, MutableMapping, Sequence
from functools import cache
from typing import Annotated, Any

import typer
import typer.main
from typer.core import TyperArgument, TyperCommand, TyperGroup
from typer.models import DefaultPlaceholder

from gyrostand.errors import unexpected, usage_error
from gyrostand.interrupt import interrupted

# Each top-level command and the `gyrostand.cmd_*` module whose `register(app)` adds it, in the
# order `--help` lists them (tests/cli/test_cli.py checks it against what each module adds).
COMMANDS = {
    "simulate": "cmd_simulate",
    "simulate-drive": "cmd_simulate_drive",
    "replay": "cmd_campaign",
    "analyze": "cmd_analyze",
    "report": "cmd_report",
    "import": "cmd_data",
    "export": "cmd_data",
    "demo": "cmd_demo",
    "station": "cmd_station",
    "plan": "cmd_plan",
    "campaign": "cmd_campaign",
    "db": "cmd_db",
    "fleet": "cmd_fleet",
}

_NEXT_SENTENCE = re.compile(r"(?<=[.!?])\s+(?=[A-Z`\[(])")


def first_sentence(text: str) -> str:
    """The first sentence of a help text, on one line (docstrings break lines anywhere)."""
    paragraph = text.strip().split("\n\n", 1)[0]
    return _NEXT_SENTENCE.split(" ".join(paragraph.split()), 1)[0]


class _HelpLayout:
    """How a command's `--help` reads: its paragraphs wrapped to the terminal; its line in the
    command list is the first sentence of its help; flags show no value type (they take none);
    arguments are named in capitals in the usage line, optional ones in brackets (`replay
    [OPTIONS] LOG`, `analyze [CAMPAIGN]`)."""

    params: list[Any]
    help: str | None
    short_help: str | None

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if self.help:  # paragraphs re-wrapped to the terminal, not broken where the source is
            paragraphs = self.help.strip().split("\n\n")
            self.help = "\n\n".join(" ".join(p.split()) for p in paragraphs)
        if self.short_help is None and self.help:
            self.short_help = first_sentence(self.help)
        for param in self.params:
            if isinstance(param, TyperArgument) and param.metavar is None:
                param.metavar = (param.name or "").upper()

    def get_params(self, ctx: Any) -> list[Any]:
        params = super().get_params(ctx)  # type: ignore[misc]
        for param in params:  # --help and the completion options are added late
            if getattr(param, "is_flag", False) and param.metavar is None:
                param.metavar = ""
        return params

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        pieces = super().collect_usage_pieces(ctx)  # type: ignore[misc]
        return [re.sub(r"^\{(.+)\}((\.\.\.)?)$", r"\1\2", piece) for piece in pieces]


class HelpCommand(_HelpLayout, TyperCommand):
    """A command with the CLI's help layout."""


class HelpGroup(_HelpLayout, TyperGroup):
    """A command group with the CLI's help layout."""


@cache
def commands_of(module: str) -> dict[str, Any]:
    """The click commands that `gyrostand.<module>` registers, by name (imported once)."""
    typer_app = typer.Typer()
    importlib.import_module(f"gyrostand.{module}").register(typer_app)
    use_help_layout(typer_app)
    return dict(typer.main.get_group(typer_app).commands)


class _Commands(MutableMapping[str, Any]):
    """The root group's commands by name: a command's module is imported (and converted by
    typer) when the command is first looked up (`COMMANDS`)."""

    def __init__(self, added: Mapping[str, Any]) -> None:
        self._added = dict(added)

    def __getitem__(self, name: str) -> Any:
        if name in self._added:
            return self._added[name]
        module = COMMANDS[name]
        try:
            return commands_of(module)[name]
        except KeyboardInterrupt:  # in the module's imports: as in the start-up's (__main__)
            interrupted()
            raise  # (interrupted() exits)

    def __setitem__(self, name: str, command: Any) -> None:
        self._added[name] = command

    def __delitem__(self, name: str) -> None:
        del self._added[name]

    def __iter__(self) -> Iterator[str]:
        yield from COMMANDS
        yield from (name for name in self._added if name not in COMMANDS)

    def __len__(self) -> int:
        return len(COMMANDS.keys() | self._added.keys())


class RootGroup(HelpGroup):
    """`gyrostand` itself: the one error boundary of every command. A command line that does
    not parse is one line (exit code 2, as click's own), an unexpected exception one line and a
    traceback file (exit code 1); a command's own `fail` already is one line. Its commands are
    loaded when named (`_Commands`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.commands = _Commands(self.commands)

    def format_help(self, ctx: Any, formatter: Any) -> None:
        """The help, once every command is loaded (a Ctrl-C meanwhile prints no half help)."""
        for name in self.commands:
            self.commands[name]
        super().format_help(ctx, formatter)

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        argv = list(sys.argv[1:] if args is None else args)
        try:
            try:
                result = super().main(
                    argv, prog_name, complete_var, False, windows_expand_args, **extra
                )
            except typer.TyperException as exc:  # click's usage errors
                if not standalone_mode:
                    raise
                if type(exc).__name__ == "NoArgsIsHelpError":  # its help is printed already
                    raise typer.Exit(exc.exit_code) from None
                ctx = getattr(exc, "ctx", None)
                hint = None if ctx is None else f"{ctx.command_path} --help"
                usage_error(exc.format_message(), hint, exc.exit_code)
            except typer.Abort:
                if not standalone_mode:
                    raise
                typer.echo("gyrostand: aborted", err=True)
                raise typer.Exit(1) from None
            except Exception as exc:  # SystemExit and KeyboardInterrupt are not Exceptions
                unexpected(exc, argv)
        except typer.Exit as stop:
            if not standalone_mode:
                return stop.exit_code
            sys.exit(stop.exit_code)
        if standalone_mode:  # super().main returned the exit code of a typer.Exit, or None
            sys.exit(result if isinstance(result, int) else 0)
        return result

    def invoke(self, ctx: Any) -> Any:
        """Ctrl-C in a command that does not handle it (typer would exit 130 without a word):
        one line, exit code 130, as during the start-up (`gyrostand.__main__`)."""
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            interrupted()


def use_help_layout(typer_app: typer.Typer) -> None:
    """Give every command and group registered on `typer_app` (and below) the help layout,
    unless it chose its own class."""
    for command in typer_app.registered_commands:
        if command.cls in (None, TyperCommand):
            command.cls = HelpCommand
    for group in typer_app.registered_groups:
        chosen = [
            cls.value if isinstance(cls, DefaultPlaceholder) else cls
            for cls in (group.cls, group.typer_instance and group.typer_instance.info.cls)
        ]
        if all(cls in (None, TyperGroup) for cls in chosen):
            group.cls = HelpGroup
        if group.typer_instance is not None:
            use_help_layout(group.typer_instance)


app = typer.Typer(
    name="gyrostand",
    cls=RootGroup,
    help="Rolling-stand tests of marine gyrocompasses: simulate, acquire, analyse, report.",
    no_args_is_help=True,
    add_completion=True,
)


def _version(value: bool) -> None:
    if value:  # (read from the package's metadata only here: importlib.metadata costs)
        from gyrostand import SOFTWARE_VERSION

        typer.echo(SOFTWARE_VERSION)
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """Rolling-stand tests of marine gyrocompasses."""
