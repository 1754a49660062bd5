"""A station database holding campaigns acquired by `gyrostand campaign run` (in process,
virtual time: ~2 s each), and station apps on it."""

import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest
from starlette.testclient import TestClient
from typer.testing import CliRunner

from gyrostand.cli import app as cli
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.station.app import create_app
from gyrostand.station.security import Access
from tests.acquisition.harness import FAST_SIM, plan_text

SERIAL = "<script>alert('serial')</script>"


def write_plan(folder: Path, name: str = "plan.toml", text: str | None = None, **kw) -> Path:
    """The small simulated plan (tests/acquisition/harness.py) in `folder`."""
    kw.setdefault("database", str(folder / "db.sqlite"))
    kw.setdefault("raw_dir", str(folder / "raw"))
    path = folder / name
    path.write_text((text or plan_text(**kw)) + FAST_SIM)
    return path


@pytest.fixture(scope="session")
def station_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One completed campaign (1) of an instrument whose serial is markup."""
    folder = tmp_path_factory.mktemp("station")
    plan = write_plan(folder)
    plan.write_text(plan.read_text().replace('serial = "T-1"', f'serial = "{SERIAL}"'))
    result = CliRunner().invoke(cli, ["campaign", "run", str(plan), "--quiet"])
    assert result.exit_code == 0, result.stderr
    return folder / "db.sqlite"


@pytest.fixture
def client_for(station_db: Path, tmp_path: Path) -> Callable[..., TestClient]:
    """A test client of a station on `station_db` bound to `host` (its token, if any)."""

    def make(host: str = "127.0.0.1", token: str | None = None) -> TestClient:
        db = tmp_path / "db.sqlite"
        with sqlite3.connect(station_db) as src, sqlite3.connect(db) as dst:
            src.backup(dst)  # with what is still in the WAL
        sessions = open_database(sqlite_url(db))
        access = Access.for_host(host, token, ["testserver"])  # TestClient's Host
        client = TestClient(create_app(str(db), sessions, access, tmp_path / "reports"))
        client.access = access  # type: ignore[attr-defined]
        return client

    return make
