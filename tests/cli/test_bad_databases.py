"""Databases that cannot be used, given to every command that opens one: a file that is not
SQLite, a truncated SQLite file, a folder, a URL of an unknown dialect or whose port is no
number (bad input: exit code 2; its password not shown);
a URL naming a SQLite file that does not exist, to the commands that only read (no database is
made); a database in a read-only folder, and a disk that fills up during a campaign (the
environment: exit code 1). Each gets one line on stderr and leaves the database as it was."""

from __future__ import annotations

import json
import os
import random
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from ..acquisition.harness import ROOT
from .cases import Case, Make, args_of, check, folder, ids, state, text_file
from .conftest import Stand, checkpointed, write_plan

PAPER_CSV = str(ROOT / "examples" / "paper.csv")
SQLITE_PAGE = 4096


def truncated_sqlite(stand: Stand, tmp: Path) -> Path:
    """The stand's database cut after its first pages (the schema is there, the data not)."""
    path = tmp / "truncated.sqlite"
    path.write_bytes(stand.db.read_bytes()[: 3 * SQLITE_PAGE])
    return path


KINDS: list[tuple[str, Make | None, str, str]] = [  # what, made by, --db, message
    (
        "random bytes",
        text_file("random.sqlite", bytes(random.Random(1).randrange(256) for _ in range(8192))),
        "{file}",
        "is not a SQLite database or is damaged (file is not a database)",
    ),
    (
        "truncated sqlite",
        truncated_sqlite,
        "{file}",
        "is not a SQLite database or is damaged (database disk image is malformed)",
    ),
    ("folder", folder("db.sqlite"), "{file}", "is a folder, not a database file"),
    ("bogus dialect", None, "nosuchdialect://host/db", "unknown database dialect 'nosuchdialect'"),
    (
        "url port no number",
        None,
        "postgresql+psycopg://lab:s3cretpw@db.lab:port/gyro",
        "'postgresql+psycopg://lab:***@db.lab:port/gyro' is neither a file path nor a database URL",
    ),
]
COMMANDS: list[tuple[str, ...]] = [
    ("campaign", "run", "{plan}", "--quiet"),
    ("campaign", "status", "1"),
    ("campaign", "list"),
    ("campaign", "resume", "1", "--quiet"),
    ("analyze", "1"),
    ("import", PAPER_CSV),
    ("export", "1", "--out", "{tmp}/export.csv"),
    ("report", "1", "-f", "json", "--out", "{tmp}/report"),
    ("replay", "{blf}", "--plan", "{plan}"),
]


def name(command: tuple[str, ...]) -> str:
    return " ".join(command[:2] if command[0] == "campaign" else command[:1])


READERS = [c for c in COMMANDS if name(c) in ("campaign status", "campaign list")]
READERS += [c for c in COMMANDS if name(c) == "campaign resume"]
READERS += [c for c in COMMANDS if name(c) in ("analyze", "export", "report")]
MAKERS = [c for c in COMMANDS if name(c) in ("campaign run", "import", "replay")]  # a new db


NOT_DATABASES = [
    Case(f"{name(command)} {what}", (*command, "--db", db), message, 2, make)
    for what, make, db, message in KINDS
    for command in COMMANDS
]
MISSING = [  # a command that only reads makes no database, whatever names it
    Case(
        f"{name(command)} missing sqlite url",
        (*command, "--db", "sqlite:///{tmp}/none/new.sqlite"),
        "no database at",
    )
    for command in READERS
]


@pytest.mark.parametrize("case", NOT_DATABASES + MISSING, ids=ids(NOT_DATABASES + MISSING))
def test_no_usable_database(case: Case, stand: Stand, tmp_path: Path) -> None:
    check(case, stand, tmp_path, stand.db_copy(tmp_path))
    assert not (tmp_path / "none").exists()


# ------------------------------------------------------------------------ a read-only folder
READ_ONLY = [  # in folder ro/: db-N.sqlite (a copy of the stand's database), nothing else
    *(
        Case(
            f"{name(command)} in a read-only folder",
            (*command, "--db", "{ro}/db-{n}.sqlite"),
            "unable to open database file",
            1,
        )
        for command in READERS
    ),
    *(
        Case(
            f"{name(command)} new db in a read-only folder",
            (*command, "--db", "{ro}/new.sqlite"),
            "unable to open database file",
            1,
        )
        for command in MAKERS
    ),
    Case(
        "import new db in a folder of a read-only folder",
        ("import", PAPER_CSV, "--db", "{ro}/sub/new.sqlite"),
        "cannot make its folder",
        1,
    ),
    Case(
        "run raw log folder in a read-only folder",
        ("campaign", "run", "{ro_plan}", "--db", "{tmp}/rw.sqlite", "--quiet"),
        "cannot write raw CAN logs in",
        1,
    ),
]


def read_only_for_root(ro: Path) -> list[str]:
    """How to run a command with `ro` read-only for root, whom modes do not stop: in a mount
    namespace of its own (util-linux `unshare`), with a read-only bind mount of it. Skips the
    test when that cannot be done here."""
    mount = f'mount --bind -o ro "{ro}" "{ro}"'
    prefix = ["unshare", "--mount", "--propagation", "private", "sh", "-c"]
    if shutil.which("unshare") is None:
        pytest.skip("root without util-linux unshare: no read-only folder for root")
    probe = subprocess.run([*prefix, mount], capture_output=True, text=True, timeout=60)
    if probe.returncode != 0:
        pytest.skip(f"root, but no read-only bind mount here: {probe.stderr.strip()}")
    return [*prefix, f'{mount} && exec "$@"', "sh"]


@pytest.fixture(scope="module")
def read_only(stand: Stand, tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """Every READ_ONLY case run in one other process for which folder ro/ is read-only (mode
    0555, and a read-only bind mount for root): their outcomes by case id, and the folder's
    files (names and bytes) before and after."""
    tmp = tmp_path_factory.mktemp("read-only")
    ro = tmp / "ro"
    ro.mkdir()
    ro_plan = write_plan(tmp, "ro-plan.toml", raw_dir=str(ro / "raw"))
    lines = []
    for n, case in enumerate(READ_ONLY):
        shutil.copyfile(stand.db, ro / f"db-{n}.sqlite")
        args, _ = args_of(case, stand, tmp, tmp / "unused", ro=ro, n=n, ro_plan=ro_plan)
        lines.append(args)
    before = state(ro)
    prefix = read_only_for_root(ro) if os.geteuid() == 0 else []
    command = [*prefix, sys.executable, "-m", "tests.cli.run_commands", json.dumps(lines)]
    ro.chmod(0o555)
    try:
        proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    finally:
        ro.chmod(0o755)
    assert proc.returncode == 0, proc.stderr
    outcomes = json.loads(proc.stdout)
    return {
        "outcomes": dict(zip(ids(READ_ONLY), outcomes, strict=True)),
        "files": (before, state(ro)),
    }


@pytest.mark.parametrize("case", READ_ONLY, ids=ids(READ_ONLY))
def test_read_only_folder(case: Case, read_only: dict) -> None:
    code, err = read_only["outcomes"][case.id]
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("gyrostand: error: "), err
    assert case.message in lines[0] and code == case.code, (code, err)
    before, after = read_only["files"]
    assert after == before  # no database, journal or raw log made in ro/, none changed


# ------------------------------------------------------------------------- a disk that fills up
def test_full_disk_during_a_campaign_is_one_line_and_keeps_what_was_committed(
    stand: Stand, tmp_path: Path
) -> None:
    """The campaign runs in a process whose files may not grow past 100 kB (RLIMIT_FSIZE, as
    a full disk: the database's write-ahead log stops growing in the middle of the campaign).
    One line, exit code 1, the observations committed before are intact and the campaign can
    be resumed: it is marked stopped with an event, or (when not even that could be written)
    left running, which `campaign status` tells as interrupted."""
    plan = write_plan(tmp_path)
    db = tmp_path / "db.sqlite"
    shutil.copyfile(stand.db, db)  # campaign 1 there already; this one is campaign 2
    limit = 150_000  # bytes: the log takes the first observations, not all 12
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "tests.cli.run_commands",
            "--max-file-size",
            str(limit),
            json.dumps([["campaign", "run", str(plan), "--db", str(db), "--quiet"]]),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    ((code, err),) = json.loads(proc.stdout)
    lines = err.splitlines()
    assert code == 1 and len(lines) == 1, err
    assert lines[0].startswith("gyrostand: error: campaign 2 stopped: "), lines[0]
    assert "disk I/O error" in lines[0] and "campaign resume 2" in lines[0], lines[0]
    connection = sqlite3.connect(checkpointed(db))
    try:
        assert connection.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        status = connection.execute("SELECT status FROM campaign WHERE id = 2").fetchone()
        kept = connection.execute(
            "SELECT COUNT(*) FROM observation JOIN series ON series.id = observation.series_id "
            "JOIN trial ON trial.id = series.trial_id WHERE trial.campaign_id = 2"
        ).fetchone()[0]
        events = connection.execute(
            "SELECT kind, severity FROM event WHERE campaign_id = 2 AND kind = 'database'"
        ).fetchall()
    finally:
        connection.close()
    assert 0 < kept < 12  # some observations of the campaign's 12, not all
    assert (status, events) in ((("stopped",), [("database", "error")]), (("running",), []))
