"""Ctrl-C outside a command's own handling (the start-up's imports, a command that does not
catch it): one line on stderr and exit code 130 (128 + SIGINT, as a shell reports it). Standard
library only: it is imported first, before anything a Ctrl-C could interrupt."""

import sys

EXIT_INTERRUPTED = 130


def interrupted() -> None:
    """Say so in one line and exit with code 130."""
    sys.stderr.write("gyrostand: interrupted\n")
    sys.exit(EXIT_INTERRUPTED)
