"""A throwaway PostgreSQL server for the test session: Debian's `postgresql` binaries (installed
by `tools/system-deps`), `initdb` into a temporary folder, `pg_ctl` listening on a unix socket
only (no TCP port to collide with), one fresh database per test. As root the server runs as the
`postgres` user (PostgreSQL refuses to run as root). When no server can be started, `start`
says why and the PostgreSQL half of the parametrised tests is skipped with that reason."""

from __future__ import annotations

import glob
import itertools
import os
import pwd
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

# durability off: a test server's data dies with the session anyway
SERVER_OPTIONS = "-c listen_addresses='' -c fsync=off -c synchronous_commit=off"
SERVER_OPTIONS += " -c full_page_writes=off -c max_connections=100"


def _binaries() -> Path | None:
    """The folder of `initdb` and `pg_ctl`: on PATH, else Debian's newest
    /usr/lib/postgresql/<version>/bin."""
    on_path = shutil.which("pg_ctl")
    if on_path and shutil.which("initdb"):
        return Path(os.path.realpath(on_path)).parent
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"), key=lambda p: p.split("/")[4])
    return Path(found[-1]).parent if found else None


@dataclass
class Server:
    """A running server: its folder (data and socket) and how to run its binaries."""

    folder: Path
    bin_dir: Path
    as_user: tuple[str, ...]
    _names: itertools.count[int] = field(default_factory=itertools.count)

    def url(self, database: str) -> str:
        return f"postgresql+psycopg://postgres@/{database}?host={self.folder}"

    def new_database(self) -> str:
        """A fresh, empty database; its SQLAlchemy URL."""
        import psycopg

        name = f"test_{next(self._names)}"
        with psycopg.connect(host=str(self.folder), user="postgres", dbname="postgres") as conn:
            conn.autocommit = True
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)

    def stop(self) -> None:
        subprocess.run(
            [*self.as_user, str(self.bin_dir / "pg_ctl"), "-D", str(self.folder / "data")]
            + ["-m", "immediate", "stop"],
            capture_output=True,
            check=False,
        )
        shutil.rmtree(self.folder, ignore_errors=True)


def start() -> Server | str:
    """A running server, or why none could be started (one line)."""
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return "psycopg is not installed (pip install -e '.[dev]')"
    bin_dir = _binaries()
    if bin_dir is None:
        return "no PostgreSQL server binaries (initdb, pg_ctl): run `make system-deps` as root"
    folder = Path(tempfile.mkdtemp(prefix="gyrostand-pg-"))
    as_user: tuple[str, ...] = ()
    if os.geteuid() == 0:
        try:
            user = pwd.getpwnam("postgres")
        except KeyError:
            return "running as root and there is no `postgres` user to run the server as"
        os.chown(folder, user.pw_uid, user.pw_gid)
        as_user = ("runuser", "-u", "postgres", "--")
    server = Server(folder, bin_dir, as_user)
    steps = [
        [str(bin_dir / "initdb"), "-D", str(folder / "data"), "-A", "trust", "-U", "postgres"]
        + ["-E", "UTF8", "--locale=C.UTF-8", "--no-sync"],
        [str(bin_dir / "pg_ctl"), "-D", str(folder / "data"), "-l", str(folder / "log"), "-w"]
        + ["-o", f"-k {folder} {SERVER_OPTIONS}", "start"],
    ]
    for step in steps:
        done = subprocess.run([*as_user, *step], capture_output=True, text=True, check=False)
        if done.returncode != 0:
            log = folder / "log"
            tail = log.read_text(errors="replace")[-300:] if log.exists() else done.stderr[-300:]
            server.stop()
            reason = " ".join(tail.split())
            return f"{Path(step[0]).name} failed (exit {done.returncode}): {reason}"
    return server
