"""CLI: db -- the lab database: merge a stand's database into it (`db merge`), and bring a
database to this gyrostand's schema (`db upgrade`)."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from gyrostand.cmd_data import JsonOption, open_db
from gyrostand.db.url import shown_url
from gyrostand.errors import EXIT_BAD_INPUT, EXIT_FAILED, fail, printable, warn

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

    from gyrostand.db.merge import CampaignMerge, MergeResult


@dataclass(frozen=True)
class RawLogFolder:
    """The lab's folder of merged raw logs (`db.merge.RawLogs`): each stand database's logs in a
    folder named by its identity, each file named with the start of its SHA-256, so a copy is
    never overwritten by other content and merging again finds it in place."""

    folder: Path
    copied: list[Path] = field(default_factory=list)

    def lab_path(self, origin: str, path: str, sha256: str) -> str:
        name = Path(path)
        return str(self.folder.resolve() / origin / f"{name.stem}-{sha256[:12]}{name.suffix}")

    def copy(self, files: Sequence[tuple[str, str, str]]) -> None:
        from gyrostand.db.merge import MergeRefused

        try:
            for source, target, sha256 in files:
                self._copy(Path(source), Path(target), sha256)
        except OSError as error:
            self.remove_copies()
            raise MergeRefused(
                f"cannot copy raw log {error.filename}: {error.strerror}; nothing merged"
            ) from None
        except MergeRefused:
            self.remove_copies()
            raise

    def _copy(self, source: Path, lab: Path, sha256: str) -> None:
        """One file, by way of a .part file checked against its SHA-256 (none left behind)."""
        from gyrostand.db.merge import MergeRefused
        from gyrostand.frames.logfile import sha256_of

        if lab.is_file() and sha256_of(lab) == sha256:
            return  # merged before
        part = lab.with_name(lab.name + ".part")
        lab.parent.mkdir(parents=True, exist_ok=True)
        try:
            shutil.copyfile(source, part)
            if sha256_of(part) != sha256:
                raise MergeRefused(
                    f"raw log {source} is not the file its campaign recorded (its SHA-256 "
                    "differs); nothing merged"
                )
            os.replace(part, lab)
        finally:
            part.unlink(missing_ok=True)
        self.copied.append(lab)

    def remove_copies(self) -> None:
        """Take back the files this merge copied (the database is rolled back as well)."""
        for path in self.copied:
            path.unlink(missing_ok=True)


DONE = {
    "merged": "merged as lab campaign {lab_id}",
    "replaced": "replaced its earlier, incomplete copy, lab campaign {lab_id}",
    "identical": "already merged (identical), lab campaign {lab_id}",
    "skipped": "skipped: {reason}",
}
DRY = {
    "merged": "would be merged as a new lab campaign",
    "replaced": "would replace its earlier, incomplete copy, lab campaign {lab_id}",
}


def stand_wal(stand: str) -> None:
    """Warn when a stand's SQLite file has commits in its write-ahead log beside it: merged from
    there, but a copy of the file alone lacks them (db.wal)."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    from gyrostand.db.session import database_url
    from gyrostand.db.wal import unmerged_wal

    try:
        url = make_url(database_url(stand))
    except (ArgumentError, ValueError):  # a URL it cannot read: open_stand says so
        return
    if url.get_backend_name() != "sqlite" or not url.database:
        return
    path = Path(url.database)
    if size := unmerged_wal(path):
        warn(
            f"{path}-wal beside it holds {size} bytes of its write-ahead log (a process has "
            f"it open, or one ended without closing it): merged from there, but a copy of "
            f"{path.name} without its -wal would lack the latest commits"
        )


def open_stand(stand: str) -> sessionmaker[Session]:
    """The stand's database, read as it is (never created or upgraded), or a one-line error."""
    from gyrostand.db.session import (
        DatabaseBehind,
        DatabaseUnusable,
        DatabaseVersionError,
        database_url,
        open_database,
        schema_heads,
    )

    shown = shown_url(stand)
    try:
        return open_database(database_url(stand), upgrade=False, create=False)
    except DatabaseBehind as error:
        if not error.current:
            fail(f"{shown} is an empty database, not a stand's gyrostand database")
        fail(
            f"{shown} has schema {', '.join(error.current)}, the lab "
            f"{', '.join(sorted(schema_heads()))}: upgrade it first with "
            f"`gyrostand db upgrade {shown}`, then merge"
        )
    except DatabaseVersionError as error:
        fail(str(error))
    except DatabaseUnusable as error:
        fail(str(error), EXIT_BAD_INPUT if error.bad_input else EXIT_FAILED)


def campaign_line(done: CampaignMerge, dry_run: bool) -> str:
    """One campaign's line of the merge's output."""
    stand = f" (stand {done.stand})" if done.stand is not None else ""
    form = (DRY if dry_run else {}).get(done.outcome, DONE[done.outcome])
    logs = ""
    if done.raw_logs:
        logs = f"; {done.raw_logs} raw log{'s' if done.raw_logs > 1 else ''} "
        logs += "to copy" if dry_run else "in the lab's raw folder"
    return printable(f"campaign {done.source_id}{stand}: " + form.format(**vars(done)) + logs)


def totals_line(result: MergeResult, dry_run: bool) -> str:
    counts = ", ".join(
        f"{result.count(outcome)} {name}"
        for outcome, name in (
            ("merged", "merged"),
            ("replaced", "replaced"),
            ("identical", "already merged"),
            ("skipped", "skipped"),
        )
    )
    return f"{'dry run, nothing changed: ' if dry_run else ''}{counts}"


def register(app: typer.Typer) -> None:
    """Add the db merge and db upgrade commands to the CLI."""

    db_app = typer.Typer(
        help="The lab database: merge stands' databases into it.", no_args_is_help=True
    )
    app.add_typer(db_app, name="db")

    @db_app.command("merge")
    def db_merge(
        stand: Annotated[str, typer.Argument(help="The stand's database (SQLite file or URL).")],
        into: Annotated[
            str,
            typer.Option("--into", help="The lab database: a SQLite file path or any URL."),
        ],
        dry_run: Annotated[
            bool, typer.Option("--dry-run", help="Say what would be merged; change nothing.")
        ] = False,
        raw_dir: Annotated[
            Path | None,
            typer.Option(
                "--raw-dir",
                help="Copy the campaigns' verified raw CAN logs into this folder of the lab "
                "(default: the lab's records name the files where the stand wrote them).",
            ),
        ] = None,
        as_json: JsonOption = False,
    ) -> None:
        """Copy a stand's campaigns into the lab database with their origin (the stand
        database's identity, their ids there, the SHA-256 of their content). Merging again adds
        nothing; a campaign that changed since is a conflict (nothing merged), unless the lab's
        copy is incomplete and untouched, which is then replaced. Campaigns being acquired or
        left running are skipped."""
        from gyrostand.db.merge import MergeRefused, merge_database
        from gyrostand.db.session import database_url
        from gyrostand.db.wal import checkpoint

        stand_wal(stand)
        source = open_stand(stand)
        lab = open_db(into)
        merged_from = shown_url(database_url(stand))
        raw_logs = None if raw_dir is None else RawLogFolder(raw_dir)
        try:
            result = merge_database(source, lab, merged_from, dry_run=dry_run, raw_logs=raw_logs)
        except MergeRefused as error:
            fail(str(error), EXIT_FAILED)
        except Exception:  # the commit failed after the copies: take them back
            if raw_logs is not None:
                raw_logs.remove_copies()
            raise
        checkpoint(lab.kw["bind"])  # the lab's file alone holds the merge (db.wal)
        if as_json:
            document = {
                "source_database": result.source_database,
                "dry_run": dry_run,
                "campaigns": [vars(c) for c in result.campaigns],
            }
            typer.echo(json.dumps(document, indent=2))
            return
        for done in result.campaigns:
            typer.echo(campaign_line(done, dry_run))
        typer.echo(totals_line(result, dry_run))

    @db_app.command("upgrade")
    def db_upgrade(
        database: Annotated[str, typer.Argument(help="A SQLite file path or any URL.")],
    ) -> None:
        """Bring a database to this gyrostand's schema (commands that write do it on opening;
        `db merge` leaves the stand's database as it is)."""
        from gyrostand.db.session import schema_heads

        open_db(database, must_exist=True)
        typer.echo(printable(f"{shown_url(database)}: schema {', '.join(sorted(schema_heads()))}"))
