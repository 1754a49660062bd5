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
from gyrostand.db.url import shown_url
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
                "(GYROSTAND_STATION_TOKEN, or a new one printed at start) and, so that it "
                "does not cross the network in clear, --tls-cert and --tls-key."
            ),
        ] = "127.0.0.1",
        port: Annotated[int, typer.Option(help="TCP port.", min=1, max=65535)] = 8000,
        db: DbOption = DEFAULT_DB,
        reports: Annotated[
            Path,
            typer.Option(
                help="Folder of the reports: written there at the station as `gyrostand report "
                "--out` does, and every campaign-ID report file in it linked on its page."
            ),
        ] = DEFAULT_OUT,
        allow_host: Annotated[
            list[str] | None,
            typer.Option(
                "--allow-host",
                metavar="NAME",
                help="Another name the browser may use for this machine (a DNS name, an "
                "address); repeatable. Loopback's names, and the bound address's, are allowed; "
                "any other Host is refused (400).",
            ),
        ] = None,
        tls_cert: Annotated[
            Path | None,
            typer.Option(
                metavar="FILE", help="Serve HTTPS with this certificate (PEM; with --tls-key)."
            ),
        ] = None,
        tls_key: Annotated[
            Path | None, typer.Option(metavar="FILE", help="The certificate's private key (PEM).")
        ] = None,
    ) -> None:
        """Serve the operator station: campaigns, live progress, start/stop/resume, reports
        and sign-off in the browser. Acquisitions run as `gyrostand campaign` processes of
        their own; the database is the source of truth."""
        try:
            import uvicorn

            from gyrostand.station.app import create_app
            from gyrostand.station.security import TOKEN_ENV, Access, is_loopback
        except ImportError as exc:
            fail(
                f"the station needs {exc.name}: pip install 'gyrostand[station]'",
                code=EXIT_FAILED,
            )
        if (tls_cert is None) != (tls_key is None):
            fail("--tls-cert and --tls-key go together: give both, or neither")
        if tls_cert is not None and tls_key is not None:
            check_tls(tls_cert, tls_key)
        sessions = open_db(db, must_exist=False)
        access = Access.for_host(host, os.environ.get(TOKEN_ENV) or None, allow_host or ())
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            listening = socket.create_server((host, port), family=family)
        except OSError as exc:  # in use, not an address of this machine, a port below 1024
            fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}", code=EXIT_FAILED)
        scheme = "http" if tls_cert is None else "https"
        address = f"{scheme}://{'[' + host + ']' if ':' in host else host}:{port}/"
        if access.token is not None:
            address += f"?token={access.token}"
        typer.echo(f"gyrostand station on {printable(shown_url(db))}: open {address}", err=True)
        if tls_cert is None and not is_loopback(host):
            typer.echo(
                "warning: plain HTTP beyond loopback: the token and every page cross the "
                "network in clear; serve it with --tls-cert and --tls-key",
                err=True,
            )
        app = create_app(db, sessions, access, reports)
        config = uvicorn.Config(
            app,
            log_level="warning",
            timeout_graceful_shutdown=2,
            ssl_certfile=tls_cert,
            ssl_keyfile=tls_key,
        )
        # uvicorn shuts down on SIGTERM, then raises it again: as an exit (143), so that the
        # database's write-ahead log is checkpointed into the file (db.wal) as at Ctrl-C
        signal.signal(signal.SIGTERM, _terminated)
        uvicorn.Server(config).run(sockets=[listening])


def check_tls(cert: Path, key: Path) -> None:
    """A certificate and key that cannot serve TLS: one line (exit code 2)."""
    import ssl

    try:
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(cert, key)
    except ssl.SSLError as exc:  # (an OSError too)
        fail(
            f"--tls-cert {cert} with --tls-key {key}: not a PEM certificate and its key "
            f"({exc.reason or exc})"
        )
    except OSError as exc:
        fail(f"--tls-cert/--tls-key: cannot read {exc.filename or cert}: {exc.strerror or exc}")
