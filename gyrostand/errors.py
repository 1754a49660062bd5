"""One-line error reporting for the CLI: a clear message on stderr and a non-zero exit code."""

from typing import NoReturn

import typer
from rich.console import Console

_err = Console(stderr=True, highlight=False, soft_wrap=True)

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def fail(message: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Print `gyrostand: error: <message>` to stderr and exit with `code`."""
    _err.print(f"gyrostand: error: {message}", markup=False)
    raise typer.Exit(code)
