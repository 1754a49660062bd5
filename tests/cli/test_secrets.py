"""A database password is never printed or written: every command that names its database runs
on a PostgreSQL URL with a known password (the session's throwaway server trusts the socket, so
any password connects), and every output is searched for it: stdout, stderr, the files written
(reports in HTML and JSON, raw logs, the merged lab), every row of both databases (events,
origins) and the station's start line and pages."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from sqlalchemy import create_engine, select
from sqlalchemy.schema import MetaData
from typer.testing import CliRunner

from gyrostand.cli import app
from gyrostand.db.url import shown_url
from tests.acquisition.harness import FAST_SIM, plan_text
from tests.db.conftest import TRIALS
from tests.postgres import Server

PASSWORD = "s3cretpw"
SILENT = "\n[bus.simulator.faults]\nsilence_at_s = 60.0\nsilence_for_s = 10.0\n"
"""The bus falls silent in trial 1: a failed trial, so `campaign run` prints how to retry it."""


def with_password(url: str) -> str:
    return url.replace("postgres@", f"postgres:{PASSWORD}@", 1)


def rows_as_text(url: str) -> str:
    """Every row of every table of the database, as text."""
    engine = create_engine(url)
    metadata = MetaData()
    metadata.reflect(engine)
    with engine.connect() as connection:
        found = [
            repr(row)
            for table in metadata.sorted_tables
            for row in connection.execute(select(table))
        ]
    engine.dispose()
    return "\n".join(found)


def test_shown_url_hides_the_password_and_nothing_else() -> None:
    assert shown_url("runs/lab.sqlite") == "runs/lab.sqlite"
    assert shown_url("sqlite:////tmp/a b.sqlite") == "sqlite:////tmp/a b.sqlite"
    assert (
        shown_url("postgresql+psycopg://lab@db.lab/gyro") == "postgresql+psycopg://lab@db.lab/gyro"
    )
    assert (
        shown_url(f"postgresql+psycopg://lab:{PASSWORD}@/gyro?host=/run/pg")
        == "postgresql+psycopg://lab:***@/gyro?host=/run/pg"
    )
    assert shown_url("postgresql://u:p@ss:w@rd@db:5432/g") == "postgresql://u:***@db:5432/g"
    assert shown_url("postgresql://u:pw@db:port/g") == "postgresql://u:***@db:port/g"  # no URL
    assert shown_url("postgresql://db/g?sslmode=require&Password=pw&x=1") == (
        "postgresql://db/g?sslmode=require&Password=***&x=1"
    )
    from sqlalchemy.engine import make_url

    assert shown_url(make_url("postgresql://u:pw@db/g")) == "postgresql://u:***@db/g"


def test_no_command_prints_or_writes_the_password(postgres_server: Server, tmp_path: Path) -> None:
    url = with_password(postgres_server.new_database())
    outputs: list[str] = []

    def gyrostand(*args: str, code: int = 0) -> str:
        result = CliRunner().invoke(app, list(args))
        outputs.extend((result.stdout, result.stderr))
        assert result.exit_code == code, (args, result.output)
        return result.stdout + result.stderr

    plan = tmp_path / "plan.toml"
    text_ = plan_text(TRIALS, n_obs=3, database="unused.sqlite", raw_dir=str(tmp_path / "raw"))
    plan.write_text(text_.replace("acquisition_only = true", "acquisition_only = false") + FAST_SIM)
    said = gyrostand(
        *("fleet", "simulate", "--db", url, "--plan", str(plan), "--model", "secret compass"),
        *("--groups", "2", "--units-per-group", "2", "--seed", "3"),
    )
    assert "--db 'postgresql+psycopg://postgres:***@" in said  # the hint, runnable with PGPASSWORD
    fleet = ("--model", "secret compass", "--by", "factory", "--db", url)
    gyrostand("fleet", "analyze", *fleet, "--json")
    for name in ("fleet.json", "fleet.html"):
        gyrostand("fleet", "report", *fleet, "-o", str(tmp_path / "out" / name))
    assert "postgres:***@" in (tmp_path / "out" / "fleet.json").read_text()
    gyrostand("report", "1", "--db", url, "--out", str(tmp_path / "out"), "--format", "json")
    gyrostand("analyze", "1", "--db", url)
    gyrostand("campaign", "status", "1", "--db", url)
    gyrostand("campaign", "list", "--db", url)
    failing = tmp_path / "failing.toml"
    failing.write_text(plan.read_text().replace("[bus.simulator]", SILENT + "[bus.simulator]", 1))
    said = gyrostand("campaign", "run", str(failing), "--db", url, "--quiet", code=1)
    assert "retry the failed trials with" in said and "postgres:***@" in said
    gyrostand("db", "upgrade", url)
    lab = tmp_path / "lab.sqlite"
    gyrostand("db", "merge", url, "--into", str(lab), "--dry-run")
    gyrostand("db", "merge", url, "--into", str(lab), "--json")
    gyrostand("db", "merge", str(lab), "--into", url)
    in_plan = tmp_path / "in-plan.toml"
    in_plan.write_text(plan.read_text().replace('"unused.sqlite"', f'"{url}"'))
    assert "postgres:***@" in gyrostand("plan", "check", str(in_plan))
    gone = url.replace("/test_", "/nothing_")  # a database the server does not have
    assert "postgres:***@" in gyrostand("analyze", "1", "--db", gone, code=1)
    gyrostand("report", "1", "--db", f"{url}&port=x", code=1)  # the driver's own error
    gyrostand("db", "merge", "postgresql://postgres:s3cretpw@host:port/x", "--into", url, code=2)
    outputs.append(station_output(url))
    for traceback in re.findall(r"traceback written to (\S+)", "\n".join(outputs)):
        outputs.append(Path(traceback).read_text())  # (none expected: any would fail above)

    leaks = [i for i, output in enumerate(outputs) if PASSWORD in output]
    assert leaks == [], [outputs[i] for i in leaks]
    for path in tmp_path.rglob("*"):
        if path.is_file() and path != in_plan:
            assert PASSWORD.encode() not in path.read_bytes(), path
    assert "postgres:***@" in rows_as_text(f"sqlite:///{lab}")  # where it was merged from
    assert PASSWORD not in rows_as_text(f"sqlite:///{lab}") + rows_as_text(url)


def station_output(url: str) -> str:
    """The station's start line and its campaign pages, served on `url`."""
    import http.client

    from tests.station.test_browser import free_port

    port = free_port()
    command = [sys.executable, "-m", "gyrostand", "station", "--db", url, "--port", str(port)]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    try:
        said = process.stderr.readline()
        assert "postgres:***@" in said, said + process.stderr.read()
        pages = []
        for path in ("/", "/campaigns/1", "/campaigns/5"):
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
            conn.request("GET", path)
            response = conn.getresponse()
            assert response.status == 200, path
            pages.append(response.read().decode())
            conn.close()
    finally:
        process.terminate()
        process.wait(30)
        process.stderr.close()
    return said + "\n".join(pages)
