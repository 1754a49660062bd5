"""The lease of a campaign on a SQLite file (db/lease.py): the flock file beside the database is
removed by its holder on release and at its process's normal exit (no `*.campaign-N.lock` left
behind by runs or by the probes of `held_elsewhere`); a killed holder's file is taken over and
removed; a file removed under a process that had opened it cannot split the lease."""

import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gyrostand.db.lease import CampaignBusy, held_elsewhere, take_lease
from gyrostand.db.session import open_database, sqlite_url
from tests.db.conftest import make_campaign

HOLD = """
import sys
from gyrostand.db.lease import take_lease
from gyrostand.db.session import open_database
take_lease(open_database(sys.argv[1]), 1)
print("held", flush=True)
sys.stdin.read()
"""


def hold(url: str) -> subprocess.Popen:
    """Another process holding campaign 1's lease until its stdin closes."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, url], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline() == "held\n"
    return holder


def lock_files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("*.lock"))


def test_no_lock_file_is_left_and_a_removed_one_splits_nothing(tmp_path: Path) -> None:
    url = sqlite_url(tmp_path / "lab.sqlite")
    sessions = open_database(url)
    with sessions.begin() as session:
        make_campaign(session)
    assert not held_elsewhere(sessions, 1)
    assert lock_files(tmp_path) == []  # the probe took the lease and gave it back
    lease = take_lease(sessions, 1)
    path = tmp_path / "lab.sqlite.campaign-1.lock"
    assert lock_files(tmp_path) == [path.name]
    assert path.read_text() == f"{os.getpid()}\n"
    stale = os.open(path, os.O_RDWR)  # opened just before the holder releases
    lease.release()
    assert lock_files(tmp_path) == []
    # a process that locks the removed file holds nothing: the path names a new file
    fcntl.flock(stale, fcntl.LOCK_EX | fcntl.LOCK_NB)
    holder = hold(url)
    try:
        assert held_elsewhere(sessions, 1)
        with pytest.raises(CampaignBusy):
            take_lease(sessions, 1)
        assert path.read_text() == f"{holder.pid}\n"
    finally:
        holder.communicate("")  # its stdin closed: it ends, its lease with it
        os.close(stale)
    assert holder.returncode == 0
    assert lock_files(tmp_path) == []  # its normal exit removed its file
    killed = hold(url)
    killed.kill()  # kill -9: the file stays, unlocked; the next taker removes it
    killed.wait()
    assert lock_files(tmp_path) == [path.name]
    assert not held_elsewhere(sessions, 1)
    assert lock_files(tmp_path) == []
    sessions.kw["bind"].dispose()


def test_a_released_lease_is_free_at_once(db_url: str) -> None:
    """On PostgreSQL the lock is dropped by the release itself, not when the server's backend of
    the closed connection has noticed (a taker just after found it held: a flaky CampaignBusy)."""
    sessions = open_database(db_url)
    for _ in range(20):
        take_lease(sessions, 1).release()
        assert not held_elsewhere(sessions, 1)  # (its probe takes and releases it too)
