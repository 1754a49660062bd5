"""CLI: db -- the lab database: merge a stand's database into it (`db merge`), and bring a
database to this gyrostand's schema (`db upgrade`)."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Annotated

import typer

from gyrostand.cmd_data import open_db
from gyrostand.errors import EXIT_BAD_INPUT, EXIT_FAILED, fail, printable

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

    from gyrostand.db.merge import CampaignMerge, MergeResult

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

    try:
        return open_database(database_url(stand), upgrade=False, create=False)
    except DatabaseBehind as error:
        if not error.current:
            fail(f"{stand} is an empty database, not a stand's gyrostand database")
        fail(
            f"{stand} has schema {', '.join(error.current)}, the lab "
            f"{', '.join(sorted(schema_heads()))}: upgrade it first with "
            f"`gyrostand db upgrade {stand}`, then merge"
        )
    except DatabaseVersionError as error:
        fail(str(error))
    except DatabaseUnusable as error:
        fail(str(error), EXIT_BAD_INPUT if error.bad_input else EXIT_FAILED)


def campaign_line(done: CampaignMerge, dry_run: bool) -> str:
    """One campaign's line of the merge's output."""
    stand = f" (stand {done.stand})" if done.stand is not None else ""
    form = (DRY if dry_run else {}).get(done.outcome, DONE[done.outcome])
    return printable(f"campaign {done.source_id}{stand}: " + form.format(**vars(done)))


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
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON document.")] = False,
    ) -> None:
        """Copy a stand's campaigns into the lab database with their origin (the stand
        database's identity, their ids there, the SHA-256 of their content). Merging again adds
        nothing; a campaign that changed since is a conflict (nothing merged), unless the lab's
        copy is incomplete and untouched, which is then replaced. Campaigns being acquired or
        left running are skipped."""
        from sqlalchemy.engine import make_url

        from gyrostand.db.merge import MergeRefused, merge_database
        from gyrostand.db.session import database_url

        source = open_stand(stand)
        lab = open_db(into)
        merged_from = make_url(database_url(stand)).render_as_string(hide_password=True)
        try:
            result = merge_database(source, lab, merged_from, dry_run=dry_run)
        except MergeRefused as error:
            fail(str(error), EXIT_FAILED)
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
        typer.echo(printable(f"{database}: schema {', '.join(sorted(schema_heads()))}"))
