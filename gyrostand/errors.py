"""What the CLI writes about itself: one-line errors on stderr with an exit code, the one way
stored or user-given strings reach the terminal (`printable`), and the boundary for the
unexpected (`unexpected`: a database failing under a command is one line; anything else an
`internal_error`: one line, the traceback in a file)."""

from __future__ import annotations

import datetime
import functools
import os
import sys
import tempfile
import traceback
from typing import TYPE_CHECKING, NoReturn

import typer

from gyrostand.db.url import shown_url

if TYPE_CHECKING:
    from rich.console import Console


@functools.cache
def _err() -> Console:
    """stderr as text (rich: imported when an error is printed)."""
    from rich.console import Console

    return Console(stderr=True, highlight=False, soft_wrap=True, markup=False, emoji=False)


EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
EXIT_INTERNAL = 1


def printable(value: object) -> str:
    """`value` as text for the terminal: characters that are not printable (control characters
    such as NUL, ESC and newline, bidirectional overrides) as Python escapes (\\x00, \\x1b,
    \\n, \\u202e), so a stored string can neither move the cursor, change colours nor break
    a line. Print the result with markup off (or as a rich `Text`): it is text, not markup."""
    text = str(value)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


def printable_lines(text: str) -> str:
    """A multi-line text (a rendered analysis) with `printable` applied to each line."""
    return "\n".join(printable(line) for line in text.split("\n"))


def fail(message: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Print `gyrostand: error: <message>` (one line) to stderr and exit with `code`."""
    _err().print(f"gyrostand: error: {printable(message)}")
    raise typer.Exit(code)


def say(text: str) -> None:
    """A line of plain text on stderr (what a command reports while it runs)."""
    _err().print(text)


def warn(message: str) -> None:
    """Print `gyrostand: warning: <message>` (one line) to stderr; the command goes on."""
    _err().print(f"gyrostand: warning: {printable(message)}")


def usage_error(message: str, help_hint: str | None, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """A command line that does not parse: one line, with where to find the command's help."""
    hint = f"; see '{help_hint}'" if help_hint else ""
    fail(f"{message.strip().rstrip('.')}{hint}", code)


def unexpected(exc: Exception, argv: list[str]) -> NoReturn:
    """An exception that escaped a command: a database that failed under it (a full or
    read-only disk, a lock held too long, a damaged file met mid-way) is one line (exit code 1,
    2 for a file that is no database); anything else is an `internal_error`."""
    if "sqlalchemy" in sys.modules:  # (no database error without it; not imported for it)
        from sqlalchemy.exc import DatabaseError, OperationalError

        if isinstance(exc, OperationalError) or type(exc) is DatabaseError:
            from gyrostand.db.session import unusable

            problem = unusable(exc)
            fail(str(problem), EXIT_BAD_INPUT if problem.bad_input else EXIT_FAILED)
    internal_error(exc, argv)


def internal_error(exc: BaseException, argv: list[str]) -> NoReturn:
    """An exception nobody expected: one line naming it and a file with the traceback (in the
    system's temporary folder), exit code 1."""
    what = printable(f"{type(exc).__name__}: {exc}")
    try:
        fd, path = tempfile.mkstemp(prefix="gyrostand-traceback-", suffix=".txt")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(f"gyrostand {' '.join(shown_url(arg) for arg in argv)}\n")
            f.write(f"at {datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}")
            f.write(f" with Python {sys.version.split()[0]}\n\n")
            f.write("".join(traceback.format_exception(exc)))
        where = f"traceback written to {printable(path)}"
    except OSError as write_error:
        where = f"the traceback could not be written ({printable(write_error)})"
    _err().print(f"gyrostand: internal error: {what}; {where}")
    raise typer.Exit(EXIT_INTERNAL)
