"""CLI: report -- the certification document of a stored campaign.

`gyrostand report CAMPAIGN [--db URL_OR_PATH] [--out DIR] [--format html,pdf,json,csv]
[--profile NAME_OR_FILE] [--number N] [--draft | --final]` analyses the campaign (recording
the analysis run), assembles the report from the database and the raw CAN log, and writes
campaign-ID.html, .pdf (PDF/A-3a, carrying the JSON, the trial CSV and the plan), .json and
campaign-ID-trials.csv. `write_campaign_report`
does the same for other commands (the demo).

A report that lacks an item of ISO/IEC 17025 7.8.2 (`report.build.missing_items`: report number,
laboratory, customer, manufacturer, dates of the trials, the station's two sign-offs) is a
DRAFT whatever the options; `--final` refuses to write it, naming what is missing, and records
nothing.
"""

from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated

import typer

from gyrostand.cmd_data import DEFAULT_DB, CampaignId, DbOption, open_db
from gyrostand.db.url import shown_url
from gyrostand.errors import fail, printable
from gyrostand.report import FORMATS, SHIPPED, SHIPPED_PROFILES, collector_paused
from gyrostand.stages import Stages

DEFAULT_OUT = Path("runs/reports")


def write_campaign_report(
    db: str,
    campaign_id: int,
    out: Path = DEFAULT_OUT,
    formats: tuple[str, ...] = FORMATS,
    profile: str | None = None,
    number: str | None = None,
    draft: bool = False,
    final: bool = False,
) -> dict[str, Path]:
    """Analyse and report one campaign; the files written by format (one-line CLI errors,
    every input checked before the analysis run is recorded). ``profile`` None: the one the
    campaign's plan names ([standard] profile), else the shipped default. ``final``: refuse
    (one line, the database unchanged) a report that would be a DRAFT. A line on stderr per
    stage: the analysis and the PDF take seconds."""
    from gyrostand.analysis.errors import AnalysisError
    from gyrostand.db.models import Campaign

    sessions = open_db(db, must_exist=True)
    with sessions() as session:
        campaign = session.get(Campaign, campaign_id)
        if campaign is None:
            fail(f"no campaign {campaign_id} in the database")
        plan_toml = campaign.plan_toml
    if profile is None:
        profile = plan_profile(plan_toml)
        if profile != SHIPPED:
            stage(f"profile {profile}: the one the campaign's plan names ([standard] profile)")
    from gyrostand.report.compliance import load_profile

    try:
        limits = load_profile(profile)
    except AnalysisError as error:
        fail(str(error))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        fail(f"cannot write the report in {out}: {error.strerror or error}")

    stage(f"campaign {campaign_id} in {shown_url(db)}: analysing it (the analysis run is recorded)")
    from sqlalchemy.exc import OperationalError

    from gyrostand.db.queries import CampaignNotFound
    from gyrostand.frames.errors import LogFileError
    from gyrostand.report.stored import NotFinal, campaign_report
    from gyrostand.report.writer import write_report

    try:
        generated = datetime.now(UTC).isoformat(sep=" ", timespec="seconds")
        report = campaign_report(
            sessions,
            campaign_id,
            database=shown_url(db),
            profile=limits,
            generated_at=generated,
            report_number=number,
            final=final,
        )
        report = replace(report, draft=report.draft or draft)
        if report.missing:
            stage(f"a DRAFT: it lacks {', '.join(report.missing)}")
        if report.analysis is None:
            typer.echo(
                f"note: campaign {campaign_id} could not be analysed "
                f"({printable(report.analysis_error)}); the report documents its plan and "
                "acquisition only",
                err=True,
            )
        stage(f"writing {', '.join(dict.fromkeys(formats))} to {out}")
        return write_report(report, out, formats, stage)
    except NotFinal as error:  # raised before the analysis run is recorded
        fail(
            f"report --final: campaign {campaign_id} lacks {error} (ISO/IEC 17025 7.8.2); "
            "it can only be a DRAFT"
        )
    except (AnalysisError, CampaignNotFound) as error:
        fail(str(error))
    except LogFileError as error:
        fail(f"campaign {campaign_id}: cannot read its raw log {error}")
    except OperationalError as error:
        fail(f"the database refused the analysis run: {error.orig}")


def plan_profile(plan_toml: str) -> str:
    """The compliance profile a stored plan names ([standard] profile; the procedures were run
    by it), else the shipped default."""
    from gyrostand.plan.model import Plan, PlanError, parse_any_plan

    try:
        plan = parse_any_plan(plan_toml)
    except PlanError:  # the report says what is wrong with it
        return SHIPPED
    if isinstance(plan, Plan) and "standard" in plan.model_fields_set:
        return plan.standard.profile
    return SHIPPED


def stage(what: str) -> None:
    """One line on stderr: what the report is doing now."""
    typer.echo(f"report: {printable(what)}", err=True)


def register(app: typer.Typer) -> None:
    """Add the report command to the CLI."""

    @app.command()
    def report(
        campaign: CampaignId,
        db: DbOption = DEFAULT_DB,
        out: Annotated[Path, typer.Option(help="Folder for the report files.")] = DEFAULT_OUT,
        format: Annotated[
            str, typer.Option("--format", "-f", help="Comma-separated: html,pdf,json,csv.")
        ] = ",".join(FORMATS),
        profile: Annotated[
            str | None,
            typer.Option(
                help=(
                    f"Compliance limits: a shipped profile ({', '.join(SHIPPED_PROFILES)}) "
                    "or a profile TOML file (default: the plan's \\[standard] profile, else "
                    f"{SHIPPED})."
                ),
                show_default=False,
            ),
        ] = None,
        number: Annotated[
            str | None,
            typer.Option("--number", help="Report number (default: the plan's \\[report] number)."),
        ] = None,
        draft: Annotated[
            bool,
            typer.Option(
                "--draft",
                help="Not for issue: DRAFT on every page and in the JSON (always so when an "
                "item of ISO/IEC 17025 7.8.2 or a sign-off is missing).",
            ),
        ] = False,
        final: Annotated[
            bool,
            typer.Option(
                "--final",
                help="Issue it: refuse when the report would be a DRAFT, naming what is missing.",
            ),
        ] = False,
    ) -> None:
        """Write the stand report (HTML, PDF, JSON, trial-table CSV) of a campaign."""
        formats = tuple(f.strip().lower() for f in format.split(",") if f.strip())
        unknown = [f for f in formats if f not in FORMATS]
        if unknown or not formats:
            fail(f"--format: {', '.join(unknown) or 'nothing'} not among {', '.join(FORMATS)}")
        if number is not None and not number.strip():
            fail("--number: the report number is empty")
        if draft and final:
            fail("--draft and --final: give one of them")
        progress = Stages("report")  # its stages: `stage`, plain lines
        with collector_paused():
            written = write_campaign_report(
                db, campaign, out, formats, profile, number, draft, final
            )
        for kind, path in written.items():
            typer.echo(f"wrote {kind}: {path}")
        progress.done(f"campaign {campaign}: {len(written)} files written in {out}")
