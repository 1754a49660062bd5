"""CLI: station -- the operator station, a web page to start, watch, stop and sign off
campaigns (`gyrostand.station`)."""

from __future__ import annotations

import os
import signal
import socket
from pathlib import Path
from typing import Annotated

import typer

from gyrostand.cmd_data import DEFAULT_DB, DbOption, open_db
from gyrostand.cmd_report import DEFAULT_OUT
from gyrostand.errors import EXIT_FAILED, fail, printable


def _terminated(signum: int, _frame: object) -> None:
    """SIGTERM as a normal exit (128 + 15): the exit handlers run."""
    raise SystemExit(128 + signum)


def register(app: typer.Typer) -> None:
    """Add the station command to the CLI."""

    @app.command()
    def station(
        host: Annotated[
            str,
            typer.Option(
                help="Address to listen on. Anything but loopback requires the token "
                "(GYROSTAND_STATION_TOKEN, or a new one printed at start)."
            ),
        ] = "127.0.0.1",
        port: Annotated[int, typer.Option(help="TCP port.", min=1, max=65535)] = 8000,
        db: DbOption = DEFAULT_DB,
        reports: Annotated[
            Path, typer.Option(help="Folder for the reports generated at the station.")
        ] = DEFAULT_OUT,
    ) -> None:
        """Serve the operator station: campaigns, live progress, start/stop/resume, reports
        and sign-off in the browser. Acquisitions run as `gyrostand campaign` processes of
        their own; the database is the source of truth."""
        try:
            import uvicorn

            from gyrostand.station.app import create_app
            from gyrostand.station.security import TOKEN_ENV, Access
        except ImportError as exc:
            fail(
                f"the station needs {exc.name}: pip install 'gyrostand[station]'",
                code=EXIT_FAILED,
            )
        sessions = open_db(db, must_exist=False)
        access = Access.for_host(host, os.environ.get(TOKEN_ENV) or None)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            listening = socket.create_server((host, port), family=family)
        except OSError as exc:  # in use, not an address of this machine, a port below 1024
            fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}", code=EXIT_FAILED)
        address = f"http://{'[' + host + ']' if ':' in host else host}:{port}/"
        if access.token is not None:
            address += f"?token={access.token}"
        typer.echo(f"gyrostand station on {printable(db)}: open {address}", err=True)
        app = create_app(db, sessions, access, reports)
        config = uvicorn.Config(app, log_level="warning", timeout_graceful_shutdown=2)
        # uvicorn shuts down on SIGTERM, then raises it again: as an exit (143), so that the
        # database's write-ahead log is checkpointed into the file (db.wal) as at Ctrl-C
        signal.signal(signal.SIGTERM, _terminated)
        uvicorn.Server(config).run(sockets=[listening])
