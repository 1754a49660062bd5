"""Run gyrostand command lines in this process and print their outcomes as JSON, one
[exit code, stderr] per command line: for the bad-input tests that need a process of their own
(a read-only folder in a mount namespace, a limit on the size of the files it writes).

    python -m tests.cli.run_commands [--max-file-size BYTES] '[["campaign", "status", ...]]'
"""

from __future__ import annotations

import json
import resource
import signal
import sys

from typer.testing import CliRunner

from gyrostand.cli import app


def main(argv: list[str]) -> None:
    if argv[0] == "--max-file-size":  # a write past it fails (EFBIG), as one on a full disk
        limit = int(argv[1])
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        argv = argv[2:]
    outcomes = []
    for args in json.loads(argv[0]):
        result = CliRunner().invoke(app, args)
        outcomes.append([result.exit_code, result.stderr])
    print(json.dumps(outcomes))


if __name__ == "__main__":
    main(sys.argv[1:])
