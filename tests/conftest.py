"""Shared pytest set-up. The `socketcan` marker, its skip and the `socketcan_channel` fixture come
from gyrostand's own pytest plugin (`gyrostand.pytest_plugin`), as users' tests get them;
`pytester` runs users' test files against it (tests/plugin).

`db_url` runs a test against both database back ends: a fresh SQLite file, and a fresh database
on a PostgreSQL server started once per session (tests/postgres.py; skipped, with the reason,
where none can be started)."""

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests import postgres

pytest_plugins = ["pytester"]

BACKENDS = ("sqlite", "postgresql")


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[postgres.Server]:
    server = postgres.start()
    if isinstance(server, str):
        pytest.skip(f"no PostgreSQL server: {server}")
    yield server
    server.stop()


@pytest.fixture(params=BACKENDS)
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """The URL of a fresh, empty database: a SQLite file, or a database on the session's
    PostgreSQL server."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'lab.sqlite'}"
    server: postgres.Server = request.getfixturevalue("postgres_server")
    return server.new_database()
