"""Shared pytest set-up. The `socketcan` marker, its skip and the `socketcan_channel` fixture come
from gyrostand's own pytest plugin (`gyrostand.pytest_plugin`), as users' tests get them;
`pytester` runs users' test files against it (tests/plugin).

`db_url` runs a test against both database back ends: a fresh SQLite file, and a fresh database
on a PostgreSQL server started once per session (tests/postgres.py; skipped, with the reason,
where none can be started)."""

from __future__ import annotations

import itertools
import os
import signal
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests import postgres

pytest_plugins = ["pytester"]

# the report's figure cache (report.figure_cache) off: every test draws its figures, and none
# writes into the user's cache folder (tests/report/test_figure_cache.py turns it on)
os.environ.setdefault("GYROSTAND_FIGURE_CACHE", "off")

BACKENDS = ("sqlite", "postgresql")


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[postgres.Server]:
    server = postgres.start()
    if isinstance(server, str):
        pytest.skip(f"no PostgreSQL server: {server}")
    yield server
    server.stop()


@dataclass(frozen=True)
class NewDatabase:
    """Fresh, empty databases of one back end: each call, the URL of another one (a SQLite
    file in the test's folder, or a database on the session's PostgreSQL server)."""

    backend: str
    folder: Path
    server: postgres.Server | None
    _count: itertools.count[int] = field(default_factory=itertools.count)

    def __call__(self) -> str:
        if self.server is not None:
            return self.server.new_database()
        return f"sqlite:///{self.folder / f'lab-{next(self._count)}.sqlite'}"


@pytest.fixture(params=BACKENDS)
def new_db_url(request: pytest.FixtureRequest, tmp_path: Path) -> NewDatabase:
    server = None if request.param == "sqlite" else request.getfixturevalue("postgres_server")
    return NewDatabase(request.param, tmp_path, server)


@pytest.fixture
def db_url(new_db_url: NewDatabase) -> str:
    """The URL of a fresh, empty database, on each back end."""
    return new_db_url()


# Whole campaigns in real time, processes killed and resumed, servers, a browser: the test files
# that take most of the suite's time run in CI's second stage (`make test-slow`, marker `slow`),
# so that `make test` stays under 4 minutes on a loaded 2-core machine.
SLOW_FILES = frozenset(
    {
        "acquisition/test_cia402_campaign.py",
        "acquisition/test_cia402_live.py",
        "devices/test_cia402_processes.py",
        "acquisition/test_cia402_run.py",
        "acquisition/test_cia402_replay.py",
        "acquisition/test_cia402_resume.py",
        "acquisition/test_cli_campaign.py",
        "acquisition/test_identify_campaign.py",
        "acquisition/test_kill_resume.py",
        "acquisition/test_live.py",
        "procedures/test_campaign_procedures.py",
        "procedures/test_procedures_live.py",
        "acquisition/test_liveness.py",
        "acquisition/test_measured_amplitude_campaign.py",
        "acquisition/test_own_bus.py",
        "acquisition/test_raw_log_names.py",
        "acquisition/test_replay_failure.py",
        "acquisition/test_stop_resume_report.py",
        "validation/test_trial_one.py",
        "cli/test_bad_databases.py",
        "cli/test_demo.py",
        "cli/test_fleet_commands.py",
        "cli/test_progress.py",
        "cli/test_raw_log_full.py",
        "cli/test_retry.py",
        "cli/test_secrets.py",
        "db/test_concurrency.py",
        "db/test_merge.py",
        "db/test_wal.py",
        "devices/test_cia406_campaign.py",
        "report/test_figure_cache_cli.py",
        "devices/test_n2k_processes.py",
        "devices/test_serial_resume.py",
        "devices/test_serial_run.py",
        "devices/test_simulate_cia406_cli.py",
        "devices/test_source_cli.py",
        "plugin/test_pytest_plugin.py",
        "report/test_signal_early.py",
        "report/test_signal_report.py",
        "report/test_stored_reuse.py",
        "station/test_browser.py",
        "station/test_campaign_page.py",
        "station/test_operator.py",
        "station/test_security.py",
        "validation/test_end_to_end.py",
    }
)


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C as a user's terminal delivers it: a shell without job control starts a command
    put in the background (`.ci/run &`) with SIGINT ignored, which its children inherit, and
    the tests of Ctrl-C would then test nothing."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    here = Path(__file__).parent
    for item in items:
        if item.path.relative_to(here).as_posix() in SLOW_FILES:
            item.add_marker(pytest.mark.slow)
