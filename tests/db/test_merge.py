"""`gyrostand db merge`: two stands' SQLite files (campaigns run on the simulated stand, in
virtual time) merged into one lab database, on both back ends. Ids change, the content does not
(value by value, and its SHA-256); `analyze` and `report` give the same C and T; merging again
adds nothing; an incomplete copy is replaced by the finished campaign; a conflict, or a campaign
being acquired, changes nothing."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import sqlite3
from collections.abc import Callable, Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import create_engine, func, select, text
from sqlalchemy.orm import Session
from typer.testing import CliRunner

from gyrostand.analysis.procedures import ProcedureResults
from gyrostand.cli import app
from gyrostand.db.merge import (
    COPIED,
    MATCHED,
    PER_DATABASE,
    campaign_rows,
    content_sha256,
    database_identity,
)
from gyrostand.db.models import AnalysisRun, Base, Campaign, ProcedureRun, SignOff
from gyrostand.db.session import open_database, sqlite_url
from tests.db.conftest import make_campaign, run_stands_at_once


@dataclass(frozen=True)
class Stands:
    """Two stands' databases, campaign 1 completed in each (labels stand=S1, stand=S2)."""

    s1: Path
    s2: Path

    def copy(self, which: Path, folder: Path, name: str) -> Path:
        """A private copy of a stand's file (the same database: its identity goes with it)."""
        return Path(shutil.copyfile(which, folder / name))


@pytest.fixture(scope="module")
def stands(tmp_path_factory: pytest.TempPathFactory) -> Stands:
    folder = tmp_path_factory.mktemp("stands")
    run_stands_at_once(folder, [str(folder / "s1.sqlite"), str(folder / "s2.sqlite")])
    return Stands(folder / "s1.sqlite", folder / "s2.sqlite")


@contextmanager
def edited(path: Path) -> Iterator[sqlite3.Connection]:
    """A change to PATH by another program, committed, checkpointed and closed (db.wal)."""
    with closing(sqlite3.connect(path)) as connection:
        with connection:
            yield connection
        connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")


def checkpointed(path: Path) -> None:
    """The commits of in-process commands moved from PATH-wal into PATH (db.wal)."""
    with closing(sqlite3.connect(path)) as connection:
        assert connection.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()[0] == 0


def merge(stand: Path | str, lab: str, *extra: str) -> Any:
    return CliRunner().invoke(app, ["db", "merge", str(stand), "--into", lab, *extra])


def row_counts(url: str) -> dict[str, int]:
    """Rows of every table of the database (made, if it is not yet)."""
    engine = open_database(url).kw["bind"]
    with engine.connect() as connection:
        counts = {
            t.name: connection.scalar(select(func.count()).select_from(t))
            for t in Base.metadata.sorted_tables
        }
    engine.dispose()
    return counts


def content(url: str, campaign_id: int) -> tuple[str, list[tuple[Any, ...]], list[tuple[Any, ...]]]:
    """The campaign's content SHA-256, its observations (by trial, attempt, j, k) and events."""
    engine = create_engine(url)
    with engine.connect() as connection:
        observations = connection.execute(
            text(
                'SELECT t."index", t.attempt, t.role, t.status, s.j, o.k, o.value_deg,'
                " o.window_start_ms, o.window_end_ms, o.frames_used, o.flags"
                " FROM observation o JOIN series s ON s.id = o.series_id"
                " JOIN trial t ON t.id = s.trial_id WHERE t.campaign_id = :c ORDER BY 1, 2, 5, 6"
            ),
            {"c": campaign_id},
        ).all()
        events = connection.execute(
            text(
                "SELECT kind, severity, message, stand_time_ms FROM event"
                " WHERE campaign_id = :c ORDER BY id"
            ),
            {"c": campaign_id},
        ).all()
    engine.dispose()
    sessions = open_database(url)
    with sessions() as session:
        digest = content_sha256(campaign_rows(session, campaign_id))
    sessions.kw["bind"].dispose()
    return digest, [tuple(r) for r in observations], [tuple(r) for r in events]


def fit_of(args: list[str]) -> dict[str, Any]:
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)["fit"]["estimates"]


def test_every_table_is_handled_by_merge() -> None:
    """A new table in models.py fails here until db/merge.py says what merging does with it."""
    handled = {"campaign"} | {m.__tablename__ for m in COPIED + MATCHED + PER_DATABASE}
    assert set(Base.metadata.tables) == handled


def test_two_stands_merge_whole_and_once(stands: Stands, db_url: str, tmp_path: Path) -> None:
    s1 = stands.copy(stands.s1, tmp_path, "s1.sqlite")  # signed and analysed on the stand
    sessions = open_database(sqlite_url(s1))
    with sessions.begin() as session:
        session.add(SignOff(campaign_id=1, role="tested_by", name="A. Tester"))
        # the standard's procedures' results (a JSON row; tests/procedures runs them for real)
        none = ProcedureResults(None, None, None, (), None, 46.5).to_dict()
        session.add(ProcedureRun(campaign_id=1, results_json=none, software_version="t"))
    sessions.kw["bind"].dispose()
    stand_fit = fit_of(["analyze", "1", "--json", "--db", str(s1)])
    checkpointed(s1)  # as the analyze process's exit does (db.wal): in this process, by hand

    first = merge(s1, db_url)
    assert first.exit_code == 0, first.output
    assert first.output.splitlines() == [
        "campaign 1 (stand S1): merged as lab campaign 1",
        "1 merged, 0 replaced, 0 already merged, 0 skipped",
    ]
    second = merge(stands.s2, db_url)
    assert second.output.splitlines()[0] == "campaign 1 (stand S2): merged as lab campaign 2"

    stand_counts = [row_counts(sqlite_url(s)) for s in (s1, stands.s2)]
    lab_counts = row_counts(db_url)
    for model in COPIED:  # every table of a campaign has rows here, all of them copied
        name = model.__tablename__
        assert stand_counts[0][name] > 0, name
        assert lab_counts[name] == stand_counts[0][name] + stand_counts[1][name], name
    assert lab_counts["campaign_origin"] == 2
    assert lab_counts["instrument"] == 1  # the same model, serial and constants on both stands
    for stand, lab_id in ((s1, 1), (stands.s2, 2)):
        assert content(db_url, lab_id) == content(sqlite_url(stand), 1)

    again = [merge(s, db_url) for s in (s1, stands.s2)]
    assert [r.output.splitlines() for r in again] == [
        [
            f"campaign 1 (stand {stand}): already merged (identical), lab campaign {lab_id}",
            "0 merged, 0 replaced, 1 already merged, 0 skipped",
        ]
        for stand, lab_id in (("S1", 1), ("S2", 2))
    ]
    assert row_counts(db_url) == lab_counts

    listed = CliRunner().invoke(app, ["campaign", "list", "--json", "--db", db_url])
    origins = [c["merged_from"] for c in json.loads(listed.output)["campaigns"]]
    assert origins == [{"from": sqlite_url(s), "id": 1} for s in (s1, stands.s2)]
    text = CliRunner().invoke(app, ["campaign", "list", "--db", db_url]).output
    assert f"merged from {sqlite_url(stands.s2)} #1" in text.splitlines()[2]

    assert fit_of(["analyze", "1", "--json", "--db", db_url]) == stand_fit
    out = tmp_path / "reports"
    reported = CliRunner().invoke(
        app, ["report", "1", "--db", db_url, "--out", str(out), "--format", "json"]
    )
    assert reported.exit_code == 0, reported.output
    document = json.loads((out / "campaign-1.json").read_text())
    assert document["analysis"]["fit"]["estimates"] == stand_fit


def test_conflict_merges_nothing(stands: Stands, db_url: str, tmp_path: Path) -> None:
    # a stand file holding campaign 1 of S1 and a merged copy of S2's (origin S2, campaign 1)
    mixed = stands.copy(stands.s1, tmp_path, "mixed.sqlite")
    assert merge(stands.s2, sqlite_url(mixed)).exit_code == 0
    assert merge(stands.s2, db_url).exit_code == 0
    with edited(mixed) as connection:  # S2's campaign changed after the lab merged it
        connection.execute("UPDATE observation SET value_deg = value_deg + 0.001 WHERE k = 2")
    before = row_counts(db_url)
    refused = merge(mixed, db_url)
    assert refused.exit_code == 1
    assert refused.stderr.strip() == (
        f"gyrostand: error: conflict: campaign 2 of sqlite:///{mixed} (merged as lab campaign "
        "1) has changed since it was merged, and the lab's copy is completed; nothing merged"
    )
    assert row_counts(db_url) == before  # S1's campaign 1, merged before the conflict, too


def test_incomplete_copy_is_replaced_by_the_finished_campaign(
    stands: Stands, db_url: str, tmp_path: Path
) -> None:
    early = stands.copy(stands.s1, tmp_path, "early.sqlite")  # as it was in mid-campaign
    with edited(early) as connection:
        connection.execute("UPDATE campaign SET status = 'paused', finished_at = NULL")
        connection.execute(
            "DELETE FROM observation WHERE series_id IN (SELECT s.id FROM series s"
            ' JOIN trial t ON t.id = s.trial_id WHERE t."index" = 2)'
        )
    assert merge(stands.s2, db_url).exit_code == 0  # lab campaign 1
    assert "merged as lab campaign 2" in merge(early, db_url).output
    replaced = merge(stands.s1, db_url)
    assert replaced.exit_code == 0, replaced.output
    assert replaced.output.splitlines()[0] == (
        "campaign 1 (stand S1): replaced its earlier, incomplete copy, lab campaign 2"
    )
    assert content(db_url, 2) == content(sqlite_url(stands.s1), 1)
    assert "already merged (identical), lab campaign 2" in merge(stands.s1, db_url).output
    assert row_counts(db_url)["campaign"] == 2


def edit(session: Session) -> None:
    session.get(Campaign, 1).operator = "lab"  # type: ignore[union-attr]


def analyse(session: Session) -> None:
    session.add(
        AnalysisRun(campaign_id=1, inputs_hash="0" * 64, results_json={}, software_version="x")
    )


@pytest.mark.parametrize(
    ("work", "problem"),
    [(edit, "and so has the lab's copy"), (analyse, "and the lab has analysed its copy")],
)
def test_incomplete_copy_worked_on_in_the_lab_is_not_replaced(
    stands: Stands, db_url: str, tmp_path: Path, work: Callable[[Session], None], problem: str
) -> None:
    early = stands.copy(stands.s1, tmp_path, "early.sqlite")
    with edited(early) as connection:
        connection.execute("UPDATE campaign SET status = 'stopped'")
        connection.execute("DELETE FROM observation WHERE k = 3")
    assert merge(early, db_url).exit_code == 0
    sessions = open_database(db_url)
    with sessions.begin() as session:
        work(session)
    sessions.kw["bind"].dispose()
    refused = merge(stands.s1, db_url)
    assert refused.exit_code == 1
    assert f"has changed since it was merged, {problem}; nothing merged" in refused.stderr


@pytest.fixture
def lease_held(tmp_path: Path) -> Iterator[Path]:
    """The file of a campaign's lease, locked as a live acquisition holds it."""
    path = tmp_path / "leased.sqlite.campaign-1.lock"
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX)
    yield path
    os.close(fd)


def test_campaigns_running_are_skipped(
    stands: Stands, db_url: str, tmp_path: Path, lease_held: Path
) -> None:
    leased = stands.copy(stands.s1, tmp_path, "leased.sqlite")
    left = stands.copy(stands.s2, tmp_path, "left.sqlite")
    with edited(left) as connection:
        connection.execute("UPDATE campaign SET status = 'running'")
    outputs = [merge(s, db_url).output.splitlines() for s in (leased, left)]
    assert outputs == [
        [
            "campaign 1 (stand S1): skipped: being acquired (a live process holds its lease)",
            "0 merged, 0 replaced, 0 already merged, 1 skipped",
        ],
        [
            "campaign 1 (stand S2): skipped: left running by a process that is gone: resume or "
            "stop it on the stand first",
            "0 merged, 0 replaced, 0 already merged, 1 skipped",
        ],
    ]
    assert row_counts(db_url)["campaign"] == 0


def sequences(url: str) -> list[tuple[Any, ...]]:
    """Where the database's id sequences stand (PostgreSQL's sequences, SQLite's
    sqlite_sequence if it has one): what the next inserted ids will be."""
    engine = create_engine(url)
    with engine.connect() as connection:
        if engine.dialect.name == "postgresql":
            query = "SELECT sequencename, last_value FROM pg_sequences ORDER BY 1"
        elif connection.scalar(
            text("SELECT count(*) FROM sqlite_master WHERE name = 'sqlite_sequence'")
        ):
            query = "SELECT name, seq FROM sqlite_sequence ORDER BY 1"
        else:
            query = "SELECT 'rowid', max(id) FROM campaign"
        found = [tuple(row) for row in connection.execute(text(query))]
    engine.dispose()
    return found


def test_dry_run_changes_nothing(stands: Stands, db_url: str) -> None:
    """... not even the sequences ids are drawn from (PostgreSQL's are not transactional): the
    campaign merged after the dry runs gets the next id."""
    assert "merged as lab campaign 1" in merge(stands.s2, db_url).output
    before, ids = row_counts(db_url), sequences(db_url)
    assert ids  # something to compare
    dry = merge(stands.s1, db_url, "--dry-run", "--json")
    assert dry.exit_code == 0, dry.output
    assert json.loads(dry.output)["campaigns"][0]["outcome"] == "merged"
    assert merge(stands.s1, db_url, "--dry-run").output.splitlines() == [
        "campaign 1 (stand S1): would be merged as a new lab campaign",
        "dry run, nothing changed: 1 merged, 0 replaced, 0 already merged, 0 skipped",
    ]
    assert row_counts(db_url) == before
    assert sequences(db_url) == ids
    assert "merged as lab campaign 2" in merge(stands.s1, db_url).output


def test_merged_campaign_keeps_its_first_origin(stands: Stands, db_url: str, tmp_path: Path):
    """A lab merged into another lab: S1's campaign is S1's, merged directly or through it."""
    first_lab = sqlite_url(tmp_path / "first-lab.sqlite")
    assert merge(stands.s1, first_lab).exit_code == 0
    assert "merged as lab campaign 1" in merge(first_lab, db_url).output
    assert "already merged (identical)" in merge(stands.s1, db_url).output


def test_the_labs_own_campaign_coming_back_is_not_copied(stands: Stands, tmp_path: Path) -> None:
    """A lab that records campaigns itself (a copy of stand S1) merged into another database,
    which is merged back: its campaign is its own, "already merged", no row added; changed
    there, it is skipped with the reason, and the lab keeps its own."""
    lab = stands.copy(stands.s1, tmp_path, "lab.sqlite")
    other = tmp_path / "other.sqlite"
    assert merge(lab, str(other)).exit_code == 0
    before = row_counts(sqlite_url(lab))
    back = merge(other, str(lab))
    assert back.exit_code == 0, back.output
    assert "already merged (identical), lab campaign 1" in back.output
    assert row_counts(sqlite_url(lab)) == before
    with edited(other) as connection:  # labelled there: its content differs now
        connection.execute(
            "INSERT INTO campaign_label (campaign_id, key, value) VALUES (1, 'site', 'B')"
        )
    back = merge(other, str(lab))
    assert back.exit_code == 0, back.output
    assert "skipped: lab campaign 1 itself, changed since it left the lab" in back.output
    assert row_counts(sqlite_url(lab)) == before


def identity_of(path: Path) -> str | None:
    sessions = open_database(sqlite_url(path))
    with sessions() as session:
        identity = database_identity(session)
    sessions.kw["bind"].dispose()
    return identity


def test_database_identity_survives_copies_and_merges(stands: Stands, tmp_path: Path) -> None:
    """A copy of a stand's file names the same database, also after campaigns were merged into
    it; another stand's, another; a database without a campaign of its own, none."""
    s1 = identity_of(stands.s1)
    copy = stands.copy(stands.s1, tmp_path, "copy.sqlite")
    assert merge(stands.s2, str(copy)).exit_code == 0
    assert identity_of(copy) == s1
    assert identity_of(stands.s2) not in (s1, None)
    lab = tmp_path / "lab.sqlite"
    assert merge(stands.s2, str(lab)).exit_code == 0
    assert identity_of(lab) is None
    sessions = open_database(sqlite_url(lab))
    with sessions.begin() as session:  # a campaign run into the lab gives it an identity
        make_campaign(session)
    sessions.kw["bind"].dispose()
    assert identity_of(lab) not in (s1, identity_of(stands.s2), None)


def lab_raw_logs(url: str) -> list[tuple[str, str]]:
    engine = create_engine(url)
    with engine.connect() as connection:
        rows = connection.execute(text("SELECT path, sha256 FROM raw_log_segment ORDER BY id"))
        found = [tuple(row) for row in rows]
    engine.dispose()
    return found


def test_raw_logs_copied_into_the_lab_folder(stands: Stands, db_url: str, tmp_path: Path) -> None:
    folder = tmp_path / "lab-raw"
    first = merge(stands.s2, db_url, "--raw-dir", str(folder))
    assert first.exit_code == 0, first.output
    assert first.output.splitlines()[0] == (
        "campaign 1 (stand S2): merged as lab campaign 1; 1 raw log in the lab's raw folder"
    )
    ((path, sha256),) = lab_raw_logs(db_url)
    copy = Path(path)
    assert copy.parent.parent == folder.resolve() and sha256[:12] in copy.name
    assert hashlib.sha256(copy.read_bytes()).hexdigest() == sha256
    (stand_log,) = lab_raw_logs(sqlite_url(stands.s2))
    assert stand_log == (stand_log[0], sha256) and Path(stand_log[0]) != copy
    # the lab's report reads the copy: the record names only it, and it verifies
    out = tmp_path / "reports"
    args = ["report", "1", "--db", db_url, "--out", str(out), "--format", "json"]
    assert CliRunner().invoke(app, args).exit_code == 0
    document = json.loads((out / "campaign-1.json").read_text())
    assert document["acquisition"]["raw_log_note"].startswith("Heading from the raw CAN log")
    # where a file is kept is no part of the content: merging again, either way, adds nothing
    for extra in ((), ("--raw-dir", str(folder))):
        again = merge(stands.s2, db_url, *extra)
        assert "already merged (identical)" in again.output, again.output
    assert [p.name for p in folder.rglob("*") if p.is_file()] == [copy.name]


def test_a_raw_log_not_as_recorded_merges_nothing(
    stands: Stands, db_url: str, tmp_path: Path
) -> None:
    stand = stands.copy(stands.s2, tmp_path, "s2.sqlite")
    ((path, _),) = lab_raw_logs(sqlite_url(stand))
    changed = tmp_path / "changed.blf"
    changed.write_bytes(Path(path).read_bytes() + b"\0")
    with edited(stand) as connection:
        connection.execute("UPDATE raw_log_segment SET path = ?", (str(changed),))
    before = row_counts(db_url)
    folder = tmp_path / "lab-raw"
    refused = merge(stand, db_url, "--raw-dir", str(folder))
    assert refused.exit_code == 1
    assert refused.stderr.strip() == (
        f"gyrostand: error: raw log {changed} is not the file its campaign recorded (its "
        "SHA-256 differs); nothing merged"
    )
    assert row_counts(db_url) == before
    assert not [p for p in folder.rglob("*") if p.is_file()]
