"""Campaign leases: one process at a time acquires into a campaign, and a campaign left "running"
by a process that is gone can be told from a live one. The lease is a lock that the operating
system or the database server drops when its holder dies, so a kill -9 never leaves it behind:
on a SQLite file an exclusive flock on `<file>.campaign-<id>.lock` beside it (removed by its
holder on release: a taker checks that the path still names the file it locked, else it opens
the new one); on PostgreSQL a session advisory lock on a connection the lease keeps open."""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import os
from pathlib import Path

from sqlalchemy import Connection, text
from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.url import shown_url

_ADVISORY_NAMESPACE = 0x6779  # "gy": first key of PostgreSQL's two-key advisory locks
_HELD: dict[tuple[str, int], Lease] = {}  # the leases this process holds


class CampaignBusy(RuntimeError):
    """Another process holds the campaign's lease (it is acquiring into it now)."""


class Lease:
    """This process's right to acquire into one campaign (see the module doc)."""

    def __init__(
        self,
        key: tuple[str, int],
        fd: int | None,
        connection: Connection | None,
        path: Path | None = None,
    ):
        self._key, self._fd, self._connection, self._path = key, fd, connection, path
        self._pid = os.getpid()  # a forked child inherits the lease, not the right to remove it

    def release(self) -> None:
        _HELD.pop(self._key, None)
        if self._fd is not None:
            self.remove_file()
            os.close(self._fd)  # closing the file drops the flock
            self._fd = None
        if self._connection is not None:
            # unlocked first: the server drops a closed session's locks only once its backend
            # has noticed, a moment later, and a taker (or held_elsewhere just after) would
            # find it still held; then the DBAPI connection is closed, not returned to the pool
            with contextlib.suppress(DBAPIError):  # a lost connection has dropped the lock
                self._connection.execute(
                    text("SELECT pg_advisory_unlock(:a, :b)"),
                    {"a": _ADVISORY_NAMESPACE, "b": self._key[1]},
                )
                self._connection.commit()
            self._connection.invalidate()
            self._connection = None

    def remove_file(self) -> None:
        """Remove the lock file while it is locked (a taker that opened it then sees that the
        path names another file), so that no lock file is left behind; a read-only folder
        keeps it."""
        if self._path is not None and self._fd is not None and self._pid == os.getpid():
            with contextlib.suppress(OSError):
                self._path.unlink()


@atexit.register
def _remove_files_at_exit() -> None:
    """A process that ends holding leases (a command's normal exit) leaves no lock file: the
    operating system drops the locks just after. A killed process leaves its file unlocked;
    the next holder takes it over and removes it."""
    for lease in _HELD.values():
        lease.remove_file()


def _key(sessions: sessionmaker[Session], campaign_id: int) -> tuple[str, int]:
    return shown_url(sessions.kw["bind"].url), campaign_id


def _try(sessions: sessionmaker[Session], campaign_id: int) -> Lease | None:
    engine = sessions.kw["bind"]
    key = _key(sessions, campaign_id)
    if engine.dialect.name == "postgresql":
        connection = engine.connect()
        got = connection.execute(
            text("SELECT pg_try_advisory_lock(:a, :b)"),
            {"a": _ADVISORY_NAMESPACE, "b": campaign_id},
        ).scalar()
        connection.commit()
        if not got:
            connection.close()
            return None
        return Lease(key, None, connection)
    database = engine.url.database
    if engine.dialect.name != "sqlite" or database in (None, "", ":memory:"):
        return Lease(key, None, None)  # a private database: nobody else can reach it
    path = Path(f"{database}.campaign-{campaign_id}.lock")
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        if _names(path, fd):
            break
        os.close(fd)  # its holder removed the file we opened on release: take the path's new one
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())  # for people: who holds it
    return Lease(key, fd, None, path)


def _names(path: Path, fd: int) -> bool:
    """Whether `path` still names the file open as `fd`."""
    try:
        named, opened = os.stat(path), os.fstat(fd)
    except FileNotFoundError:
        return False
    return (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino)


def take_lease(sessions: sessionmaker[Session], campaign_id: int) -> Lease:
    """The campaign's lease for this process (the same one when it already holds it);
    CampaignBusy when another process holds it."""
    key = _key(sessions, campaign_id)
    if key in _HELD:
        return _HELD[key]
    lease = _try(sessions, campaign_id)
    if lease is None:
        raise CampaignBusy(
            f"campaign {campaign_id} is being acquired by another process; "
            "wait for it to end or stop it first"
        )
    _HELD[key] = lease
    return lease


def held_elsewhere(sessions: sessionmaker[Session], campaign_id: int) -> bool:
    """Whether another process holds the campaign's lease now (a live run)."""
    if _key(sessions, campaign_id) in _HELD:
        return False
    lease = _try(sessions, campaign_id)
    if lease is None:
        return True
    lease.release()
    return False
