"""CLI: analyze -- the seed-000 analysis of a campaign's trials, as text or one JSON document.

`gyrostand analyze --csv FILE [--plan PLAN.toml] [--json]`. Without --plan the seed-000 example
constants, start values, admissible region and ship forecast are used (a note on stderr says so).
`gyrostand analyze CAMPAIGN_ID [--db URL_OR_PATH] [--json]` analyses a campaign in the database
with its stored plan's settings and records the run (`acquisition.stored.analyze_stored`).
The pieces are separate functions so other sources (a campaign in the database) can reuse them:
`settings_from_plan` -> `AnalysisSettings`, `run_analysis`, `emit`.
"""

import json
from pathlib import Path
from typing import Annotated

import typer
from sqlalchemy.exc import OperationalError

from acquisition.stored import analyze_stored
from analysis.campaign import CampaignAnalysis, analyze_campaign
from analysis.csv_input import read_trials_csv
from analysis.errors import AnalysisError
from analysis.settings import SEED_000_SETTINGS, AnalysisSettings
from analysis.settings import settings_from_plan as plan_settings
from analysis.text_report import render_text
from analysis.trials import TrialInput
from db.queries import CampaignNotFound
from gyrostand.cmd_data import DEFAULT_DB, DbOption, open_db
from gyrostand.errors import fail

PAPER_NOTE = (
    "note: no --plan given: using the seed-000 example constants, start values and ship "
    "forecast (Potemkin 1982)"
)
PAPER_SETTINGS = SEED_000_SETTINGS


def settings_from_plan(path: Path) -> AnalysisSettings:
    """Read [instrument], [site], [analysis] and the optional [forecast] of a campaign plan."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        fail(f"plan {path}: cannot read it ({exc})")
    try:
        return plan_settings(text)
    except AnalysisError as exc:
        fail(f"plan {path}: {exc}")


def run_analysis(trials: list[TrialInput], settings: AnalysisSettings) -> CampaignAnalysis:
    """The analysis, with analysis errors turned into one-line CLI failures."""
    try:
        return analyze_campaign(
            trials,
            settings.constants,
            q=settings.q,
            start=settings.start,
            admissible=settings.admissible,
            forecast=settings.forecast,
        )
    except AnalysisError as exc:
        fail(str(exc))


def emit(analysis: CampaignAnalysis, as_json: bool) -> None:
    """Print the analysis as text sections, or as one JSON document (keys: analysis.campaign)."""
    if as_json:
        typer.echo(json.dumps(analysis.to_dict(), indent=2, allow_nan=False))
    else:
        typer.echo(render_text(analysis), nl=False)


def register(app: typer.Typer) -> None:
    """Add the analyze command to the CLI."""

    @app.command()
    def analyze(
        campaign: Annotated[
            int | None, typer.Argument(help="A stored campaign's id (with --db).")
        ] = None,
        db: DbOption = DEFAULT_DB,
        csv: Annotated[
            Path | None,
            typer.Option("--csv", help="Trials table (columns as examples/paper.csv)."),
        ] = None,
        plan: Annotated[
            Path | None,
            typer.Option("--plan", help="Campaign plan TOML: constants, start, forecast."),
        ] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON document.")] = False,
    ) -> None:
        """Analyse a stored campaign or a CSV of trials (Cochran, fit, adequacy, control,
        forecast). A stored campaign's analysis is recorded in the database."""
        if campaign is not None:
            if csv is not None or plan is not None:
                fail("give a CAMPAIGN id or --csv FILE [--plan PLAN], not both")
            emit(analyze_stored_campaign(db, campaign), as_json)
            return
        if csv is None:
            fail("no source given: use --csv FILE (see examples/paper.csv) or a CAMPAIGN id")
        if plan is None:
            typer.echo(PAPER_NOTE, err=True)
            settings = PAPER_SETTINGS
        else:
            settings = settings_from_plan(plan)
        try:
            trials = read_trials_csv(csv)
        except AnalysisError as exc:
            fail(str(exc))
        emit(run_analysis(trials, settings), as_json)


def analyze_stored_campaign(db: str, campaign_id: int) -> CampaignAnalysis:
    """Analyse a campaign stored in the database (settings from its plan, constants from the
    campaign) and record the analysis run; one-line CLI errors."""
    sessions = open_db(db, must_exist=True)
    try:
        with sessions.begin() as session:
            return analyze_stored(session, campaign_id).analysis
    except (AnalysisError, CampaignNotFound) as exc:
        fail(str(exc))
    except OperationalError as exc:
        fail(f"the database refused the analysis run: {exc.orig}")
