"""What a command that takes seconds is doing, on stderr (its results stay on stdout): a line per
stage, `COMMAND: what`, and a closing summary with the wall time it took. On a terminal the
current stage also turns as a rich spinner until the next; off one (CI, a pipe, nohup) the
lines are plain text."""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING

import typer

from gyrostand.errors import printable

if TYPE_CHECKING:
    from rich.status import Status


class Stages:
    """`with Stages("analyze") as stage: stage("reading campaign 1"); ...; stage.done("...")`."""

    def __init__(self, command: str) -> None:
        self.command = command
        self._started = time.monotonic()
        self._spinner: Status | None = None

    def __enter__(self) -> Stages:
        if sys.stderr.isatty():
            from rich.console import Console

            console = Console(stderr=True, highlight=False, markup=False, emoji=False)
            self._spinner = console.status("", spinner="line")
            self._spinner.start()
        return self

    def __call__(self, what: str) -> None:
        """A stage begins."""
        line = f"{self.command}: {printable(what)}"
        if self._spinner is None:
            typer.echo(line, err=True)
        else:
            self._spinner.console.print(line)
            self._spinner.update(f"{line} ...")

    def done(self, summary: str) -> None:
        """The closing line: what came of it, and how long it took."""
        self._stop()
        elapsed = time.monotonic() - self._started
        typer.echo(f"{self.command}: {printable(summary)} ({elapsed:.1f} s)", err=True)

    def _stop(self) -> None:
        if self._spinner is not None:
            self._spinner.stop()
            self._spinner = None

    def __exit__(self, *exc: object) -> None:
        self._stop()
