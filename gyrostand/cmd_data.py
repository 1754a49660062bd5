"""CLI: import historical measurements, export a campaign (CSV, Parquet, Excel)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from gyrostand.db.url import DB_ENV
from gyrostand.errors import EXIT_BAD_INPUT, EXIT_FAILED, fail
from gyrostand.stages import Stages

if TYPE_CHECKING:
    from sqlalchemy.orm import Session, sessionmaker

DEFAULT_DB = "runs/gyrostand.sqlite"

DbOption = Annotated[
    str,
    typer.Option("--db", envvar=DB_ENV, help="Database: a SQLite file path or any SQLAlchemy URL."),
]
JsonOption = Annotated[bool, typer.Option("--json", help="Print one JSON document.")]
MAX_CAMPAIGN_ID = 2**31 - 1
"""Largest campaign id: ids are Integer columns of the database (32-bit signed in PostgreSQL
and MySQL; a larger number is no campaign anywhere)."""
CampaignId = Annotated[int, typer.Argument(help="Campaign id.", min=1, max=MAX_CAMPAIGN_ID)]


TagOption = Annotated[
    list[str] | None,
    typer.Option(
        "--tag",
        help="A label of the campaign, key=value (repeatable): e.g. factory=A, lot=2026-07, "
        "stand=S2; fleet statistics group campaigns by a key.",
    ),
]


def parse_tags(tags: list[str] | None) -> dict[str, str]:
    """The --tag options as labels, or a one-line error naming the bad one (or a key given
    twice)."""
    from gyrostand.db.queries import parse_label

    labels: dict[str, str] = {}
    for tag in tags or []:
        try:
            key, value = parse_label(tag)
        except ValueError as error:
            fail(f"--tag: {error}")
        if key in labels:
            fail(f"--tag: label {key} given twice")
        labels[key] = value
    return labels


class ExportFormat(StrEnum):
    csv = "csv"
    parquet = "parquet"
    xlsx = "xlsx"


def open_db(db: str, *, must_exist: bool = False) -> sessionmaker[Session]:
    """The database's session factory, or a one-line error: a missing file (`must_exist`: the
    command only reads), a wrong schema, a file or URL that is no database (exit code 2), a
    database the environment does not let us use (exit code 1)."""
    from gyrostand.db.session import (
        DatabaseUnusable,
        DatabaseVersionError,
        database_url,
        open_database,
    )

    try:
        return open_database(database_url(db), create=not must_exist)
    except DatabaseVersionError as error:
        fail(str(error))
    except DatabaseUnusable as error:
        fail(str(error), EXIT_BAD_INPUT if error.bad_input else EXIT_FAILED)


def plan_metadata(path: Path) -> dict[str, Any]:
    """Instrument, site and operator of a plan file, whole or partial (`plan.model`), and its
    text (stored with the import)."""
    from gyrostand.plan.model import PlanError, parse_any_plan, read_text

    try:
        text = read_text(path)
        plan = parse_any_plan(text)
    except PlanError as error:
        fail(f"{path}: invalid plan: " + "; ".join(error.problems))
    metadata: dict[str, Any] = {
        "plan_toml": text,
        **plan.instrument.model_dump(),
        **plan.site.model_dump(),
    }
    if plan.campaign is not None:
        metadata["operator"] = plan.campaign.operator
    return metadata


def register(app: typer.Typer) -> None:
    """Add the import and export commands to the CLI."""

    @app.command("import")
    def import_(
        file: Annotated[Path, typer.Argument(help="CSV, Excel (.xlsx) or Parquet file.")],
        plan: Annotated[
            Path | None,
            typer.Option(
                help="Campaign plan (TOML), whole or partial: its \\[instrument] and \\[site] "
                "describe the data, its \\[analysis] and \\[forecast] the analysis."
            ),
        ] = None,
        operator: Annotated[str | None, typer.Option(help="Who made the measurements.")] = None,
        tag: TagOption = None,
        db: DbOption = DEFAULT_DB,
    ) -> None:
        """Import historical manual measurements: per observation, per series (mean, variance,
        N) or per trial as the paper's table prints it. Nothing is written unless the whole
        file is valid."""
        from sqlalchemy.exc import OperationalError

        from gyrostand import SOFTWARE_VERSION
        from gyrostand.db.io import (
            SEED_000_METADATA,
            ImportFileError,
            MetadataError,
            check_metadata,
            read_import_file,
            store_import,
        )

        metadata = dict(SEED_000_METADATA) if plan is None else plan_metadata(plan)
        if operator is not None:
            metadata["operator"] = operator
        metadata["software_version"] = SOFTWARE_VERSION
        labels = parse_tags(tag)
        try:
            check_metadata(metadata)
            data = read_import_file(file)
        except (MetadataError, ImportFileError) as error:
            fail(str(error))
        from gyrostand.db.session import writer

        sessions = open_db(db)
        try:  # waits its turn behind another writer (a campaign running into the same file)
            with writer(sessions).begin() as session:
                campaign_id = store_import(session, data, metadata, labels).id
        except OperationalError as error:  # e.g. locked by another writer; rolled back
            fail(f"nothing imported, the database refused the write: {error.orig}")
        if plan is None:
            typer.echo(
                "no --plan: used the example instrument and site of Potemkin (1982) (lP = 6.57e6 "
                "g*cm^2/s^2, H1 = 1.55e8 g*cm^2/s, latitude 46.5 deg, U = 7.3e-5 rad/s, "
                "g = 981 cm/s^2)",
                err=True,
            )
        typer.echo(
            f"imported {file} ({data.form} form, {len(data.trials)} trials, N = {data.n_obs}) "
            f"as campaign {campaign_id}"
        )

    @app.command()
    def export(
        campaign: CampaignId,
        format: Annotated[ExportFormat, typer.Option("--format", "-f")] = ExportFormat.csv,
        out: Annotated[
            Path | None,
            typer.Option(
                help="Output file (default runs/export/campaign-ID.FORMAT). For csv and parquet "
                "the series and trial summaries go next to it as NAME.series.EXT, NAME.trials.EXT."
            ),
        ] = None,
        db: DbOption = DEFAULT_DB,
    ) -> None:
        """Export a campaign's observations and series/trial summaries (CSV, Parquet, Excel)."""
        from gyrostand.db.queries import CampaignNotFound
        from gyrostand.report.export import export_campaign, export_paths

        fmt = format.value
        out = out or Path("runs/export") / f"campaign-{campaign}.{fmt}"
        sessions = open_db(db, must_exist=True)
        with Stages("export") as stage:  # (bad input is found as it runs: one line, no stage)
            try:
                with sessions() as session:
                    frames = export_campaign(session, campaign, fmt, out)
            except CampaignNotFound as error:
                fail(str(error))
            except OSError as error:
                fail(f"cannot write {out}: {error.strerror or error}")
            tables = frames.tables()
            rows = sum(len(t) for t in tables.values())
            stage.done(f"campaign {campaign}: {rows} rows in {len(tables)} tables written")
        for table, path in export_paths(out, fmt).items():
            where = f"{path} [{table}]" if fmt == "xlsx" else str(path)
            typer.echo(f"wrote {where}: {len(tables[table])} {table}")
