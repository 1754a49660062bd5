"""CLI: analyze -- the seed-000 analysis of a campaign's trials, as text or one JSON document.

`gyrostand analyze --csv FILE [--plan PLAN.toml] [--json]`. Without --plan the seed-000 example
constants, start values, admissible region and ship forecast are used (a note on stderr says so).
`gyrostand analyze CAMPAIGN_ID [--db URL_OR_PATH] [--json]` analyses a campaign in the database
with its stored plan's settings and records the run (`report.stored.analyze_stored`).
`gyrostand analyze CAMPAIGN_ID --signal` and `gyrostand analyze --signal --log FILE.blf|.asc
[--plan PLAN.toml] [--from S] [--to S]` print the signal analysis of the reading (report section
10: noise, hidden harmonics, sampling interval, settle points, acceptance by excursions); they
read the database and the raw log only.
The pieces are separate functions so other sources (a campaign in the database) can reuse them:
`plan_settings` -> `AnalysisSettings`, `run_analysis`, `emit`.
"""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from gyrostand.analysis.errors import AnalysisError
from gyrostand.cmd_data import DEFAULT_DB, MAX_CAMPAIGN_ID, DbOption, JsonOption, open_db
from gyrostand.db.url import shown_url
from gyrostand.errors import fail, printable, printable_lines
from gyrostand.stages import Stages

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gyrostand.analysis.campaign import CampaignAnalysis
    from gyrostand.analysis.trials import TrialInput
    from gyrostand.report.settings import AnalysisSettings
    from gyrostand.report.signal import SignalSection
    from gyrostand.report.stored import AppliedMotion

PAPER_NOTE = (
    "note: no --plan given: using the example constants, start values and ship forecast of "
    "Potemkin (1982)"
)
SIGNAL_SCHEMA = "gyrostand.signal/2"  # the report JSON's "signal" object, with this key added;
# version 2: acceptance.excursions gained method, is_bound and the Kolmogorov/Vanmarcke fields


def plan_settings(path: Path) -> tuple[AnalysisSettings, tuple[str, ...]]:
    """The analysis settings of a plan file, whole or partial (`report.settings`), and a note
    for each table taken from the example of Potemkin (1982) (for stderr once the analysis
    succeeded: a failure is one line)."""
    from gyrostand.plan.model import PlanError, load_any_plan
    from gyrostand.report.settings import fallback_notes, settings_from_plan

    try:
        plan = load_any_plan(path)
    except PlanError as exc:
        fail(f"plan {path}: " + "; ".join(exc.problems))
    return settings_from_plan(plan), fallback_notes(plan, source=f"note: plan {path}")


def run_analysis(trials: list[TrialInput], settings: AnalysisSettings) -> CampaignAnalysis:
    """The analysis, with analysis errors turned into one-line CLI failures."""
    from gyrostand.analysis.campaign import analyze_campaign

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


def emit(
    analysis: CampaignAnalysis,
    as_json: bool,
    heading_source: str | None = None,
    motion: Sequence[AppliedMotion] = (),
) -> None:
    """Print the analysis as text sections, or as one JSON document (keys: analysis.campaign);
    a stored campaign's heading source (protocol, resolution, time base) and its trials'
    commanded and applied motion (key "motion") first."""
    from gyrostand.report.text import render_text, terminal_notation

    if as_json:
        document = analysis.to_dict()
        if motion:
            document = {"motion": [m.to_dict() for m in motion], **document}
        if heading_source is not None:
            document = {"heading_source": heading_source, **document}
        typer.echo(json.dumps(document, indent=2, allow_nan=False))
    else:  # it may quote stored strings: control characters escaped
        text = render_text(analysis)
        if motion:
            lines = "\n".join(terminal_notation(m.describe()) for m in motion)
            text = f"MOTION (commanded; applied: measured A and τ, their SE)\n{lines}\n\n{text}"
        if heading_source is not None:
            text = f"HEADING SOURCE\n{heading_source}\n\n{text}"
        typer.echo(printable_lines(text), nl=False)


def register(app: typer.Typer) -> None:
    """Add the analyze command to the CLI."""

    @app.command()
    def analyze(
        campaign: Annotated[
            int | None,
            typer.Argument(help="A stored campaign's id (with --db).", min=1, max=MAX_CAMPAIGN_ID),
        ] = None,
        db: DbOption = DEFAULT_DB,
        csv: Annotated[
            Path | None,
            typer.Option("--csv", help="Trials table (columns as examples/paper.csv)."),
        ] = None,
        plan: Annotated[
            Path | None,
            typer.Option(
                "--plan",
                help="Campaign plan TOML: constants, start, forecast (with --csv); protocol "
                "and \\[acceptance] (with --signal --log).",
            ),
        ] = None,
        as_json: JsonOption = False,
        signal: Annotated[
            bool,
            typer.Option(
                "--signal",
                help="Signal analysis of the reading (noise, harmonics, sampling, settle, "
                "excursions) of a CAMPAIGN or of --log FILE.",
            ),
        ] = False,
        log: Annotated[
            Path | None,
            typer.Option("--log", help="With --signal: a raw CAN log (.blf or .asc)."),
        ] = None,
        start_s: Annotated[
            float | None,
            typer.Option("--from", help="With --log: start of the record, stand seconds."),
        ] = None,
        end_s: Annotated[
            float | None,
            typer.Option("--to", help="With --log: end of the record, stand seconds."),
        ] = None,
    ) -> None:
        """Analyse a stored campaign or a CSV of trials (Cochran, fit, adequacy, control,
        forecast). A stored campaign's analysis is recorded in the database. With --signal:
        the signal analysis of a campaign's raw reading or of a raw log (nothing recorded)."""
        if signal:
            emit_signal(signal_of(campaign, db, csv, plan, log, start_s, end_s), as_json)
            return
        if log is not None or start_s is not None or end_s is not None:
            fail("--log, --from and --to go with --signal")
        if campaign is not None:
            if csv is not None or plan is not None:
                fail("give a CAMPAIGN id or --csv FILE [--plan PLAN], not both")
            from gyrostand.db.models import Campaign

            with open_db(db, must_exist=True)() as session:  # bad input: one line, no stage
                if session.get(Campaign, campaign) is None:
                    fail(f"no campaign {campaign} in the database")
            with Stages("analyze") as stage:
                stage(f"campaign {campaign} in {shown_url(db)}: analysing it (the run is recorded)")
                analysis, heading, motion = analyze_stored_campaign(db, campaign)
                fitted = len(analysis.fit_indices)
                stage.done(f"campaign {campaign}: {fitted} trials fitted, the analysis recorded")
            emit(analysis, as_json, heading, motion)
            return
        if csv is None:
            fail("no source given: use --csv FILE (see examples/paper.csv) or a CAMPAIGN id")
        from gyrostand.analysis.csv_input import read_trials_csv
        from gyrostand.report.settings import SEED_000_SETTINGS

        try:  # the table first: a note about the settings would not help a missing file
            trials = read_trials_csv(csv)
        except AnalysisError as exc:
            fail(str(exc))
        if plan is None:
            settings, notes = SEED_000_SETTINGS, (PAPER_NOTE,)
        else:
            settings, notes = plan_settings(plan)
        analysis = run_analysis(trials, settings)
        for note in notes:
            typer.echo(note, err=True)
        emit(analysis, as_json)


def analyze_stored_campaign(
    db: str, campaign_id: int
) -> tuple[CampaignAnalysis, str, tuple[AppliedMotion, ...]]:
    """Analyse a campaign stored in the database (settings from its plan, constants from the
    campaign) and record the analysis run; with its heading source and its trials' applied
    motion; one-line CLI errors."""
    from sqlalchemy.exc import OperationalError

    from gyrostand.db.models import Campaign
    from gyrostand.db.queries import CampaignNotFound
    from gyrostand.report.stored import analyze_stored, campaign_motion, heading_source

    sessions = open_db(db, must_exist=True)
    try:
        stored = analyze_stored(sessions, campaign_id)  # a read, the computation, a short write
        with sessions() as session:
            heading = heading_source(session.get_one(Campaign, campaign_id))
            motion = campaign_motion(session.get_one(Campaign, campaign_id))
    except (AnalysisError, CampaignNotFound) as exc:
        fail(str(exc))
    except OperationalError as exc:
        fail(f"the database refused the analysis run: {exc.orig}")
    for t in stored.inputs.left_out:
        if t.superseded_by is None:  # (a superseded attempt is replaced, not missing)
            message = f"warning: trial {t.index} left out of the analysis ({t.reason})"
            typer.echo(printable(message), err=True)
    for note in stored.inputs.notes:
        typer.echo(printable(f"note: {note}"), err=True)
    return stored.analysis, heading, motion


def signal_of(
    campaign: int | None,
    db: str,
    csv: Path | None,
    plan: Path | None,
    log: Path | None,
    start_s: float | None,
    end_s: float | None,
) -> SignalSection:
    """The signal analysis the --signal options ask for; one-line CLI errors."""
    from gyrostand.frames.logfile import LogFileError
    from gyrostand.plan.model import PlanError, load_plan
    from gyrostand.report.signal_record import log_signal

    if csv is not None:
        fail("--signal reads a raw CAN log (a CAMPAIGN's or --log FILE), not --csv")
    if campaign is not None:
        if log is not None or plan is not None or start_s is not None or end_s is not None:
            fail("give a CAMPAIGN id or --log FILE [--plan PLAN] [--from S] [--to S], not both")
        return campaign_signal_of(db, campaign)
    if log is None:
        fail("--signal needs a CAMPAIGN id or --log FILE (.blf or .asc)")
    if not log.is_file():
        fail(f"raw log {log}: not found")
    try:
        section = log_signal(log, None if plan is None else load_plan(plan), start_s, end_s)
    except PlanError as exc:
        fail(f"plan {plan}: {exc}")
    except AnalysisError as exc:
        fail(str(exc))
    except LogFileError as exc:
        fail(f"cannot read the raw log {exc}")
    except (OSError, ValueError, EOFError, struct.error, zlib.error) as exc:
        fail(f"raw log {log}: cannot read it ({exc})")
    if section.noise is None:
        fail(f"raw log {log}: {section.noise_error}")
    return section


def campaign_signal_of(db: str, campaign_id: int) -> SignalSection:
    """The signal analysis of a stored campaign (read only); fails when it has no record."""
    from gyrostand.db.queries import CampaignNotFound
    from gyrostand.frames.logfile import LogFileError
    from gyrostand.report.stored import campaign_signal

    sessions = open_db(db, must_exist=True)
    try:
        with sessions() as session:
            section = campaign_signal(session, campaign_id)
    except (AnalysisError, CampaignNotFound) as exc:
        fail(str(exc))
    except LogFileError as exc:
        fail(f"campaign {campaign_id}: cannot read its raw log {exc}")
    if section.noise is None:
        fail(f"campaign {campaign_id}: {section.noise_error or section.record_note}")
    return section


def emit_signal(section: SignalSection, as_json: bool) -> None:
    """Print the signal analysis as text, or as one JSON document (report section 10's keys)."""
    from gyrostand.report.signal_text import render_signal_text

    if as_json:
        document = {"schema": SIGNAL_SCHEMA, **section.to_dict()}
        typer.echo(json.dumps(document, indent=2, allow_nan=False))
    else:
        typer.echo(printable_lines(render_signal_text(section)), nl=False)
