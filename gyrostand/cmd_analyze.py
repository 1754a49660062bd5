"""CLI: analyze -- the seed-000 analysis of a campaign's trials, as text or one JSON document.

`gyrostand analyze --csv FILE [--plan PLAN.toml] [--json]`. Without --plan the seed-000 example
constants, start values, admissible region and ship forecast are used (a note on stderr says so).
The pieces are separate functions so other sources (a campaign in the database) can reuse them:
`settings_from_plan` -> `AnalysisSettings`, `run_analysis`, `emit`.
"""

import json
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer

from analysis import paper_example
from analysis.campaign import AdmissibleRegion, CampaignAnalysis, analyze_campaign
from analysis.csv_input import read_trials_csv
from analysis.errors import AnalysisError
from analysis.forecast import ShipConditions
from analysis.gyro_model import KnownConstants
from analysis.text_report import render_text
from analysis.trials import TrialInput
from gyrostand.errors import fail

PAPER_NOTE = (
    "note: no --plan given: using the seed-000 example constants, start values and ship "
    "forecast (Potemkin 1982)"
)


@dataclass(frozen=True)
class AnalysisSettings:
    """What a plan contributes to the analysis."""

    constants: KnownConstants
    q: float
    start: tuple[float, float]
    admissible: AdmissibleRegion | None
    forecast: ShipConditions | None


PAPER_SETTINGS = AnalysisSettings(
    constants=paper_example.CONSTANTS,
    q=0.05,
    start=paper_example.START,
    admissible=paper_example.ADMISSIBLE,
    forecast=paper_example.FORECAST,
)


def _table(plan: dict[str, Any], name: str, path: Path) -> dict[str, Any]:
    table = plan.get(name)
    if not isinstance(table, dict):
        fail(f"plan {path}: table [{name}] is missing")
    return table


def _number(table: dict[str, Any], table_name: str, key: str, path: Path) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        fail(f"plan {path}: [{table_name}] {key} must be a number, got {value!r}")
    return float(value)


def _range(table: dict[str, Any], key: str, path: Path) -> tuple[float, float] | None:
    value = table.get(key)
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == 2 and value[0] < value[1]):
        fail(f"plan {path}: [analysis] {key} must be [low, high], got {value!r}")
    return float(value[0]), float(value[1])


def settings_from_plan(path: Path) -> AnalysisSettings:
    """Read [instrument], [site], [analysis] and the optional [forecast] of a campaign plan."""
    try:
        plan = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        fail(f"plan {path}: cannot read it ({exc})")
    instrument, site = _table(plan, "instrument", path), _table(plan, "site", path)
    settings = _table(plan, "analysis", path)
    try:
        constants = KnownConstants(
            lP_gcm2s2=_number(instrument, "instrument", "lp_gcm2s2", path),
            H1_gcm2s=_number(instrument, "instrument", "h1_gcm2s", path),
            earth_rate_rad_s=_number(site, "site", "earth_rate_rad_s", path),
            gravity_cm_s2=_number(site, "site", "gravity_cm_s2", path),
            latitude_deg=_number(site, "site", "latitude_deg", path),
        )
        c_range = _range(settings, "admissible_c", path)
        t_range = _range(settings, "admissible_t_s", path)
        admissible = (
            None
            if c_range is None and t_range is None
            else AdmissibleRegion(c_range or (0.0, float("inf")), t_range or (0.0, float("inf")))
        )
        ship = plan.get("forecast")
        forecast = None
        if ship is not None:
            forecast = ShipConditions(
                roll_deg=_number(ship, "forecast", "roll_deg", path),
                arm_cm=_number(ship, "forecast", "arm_cm", path),
                period_s=_number(ship, "forecast", "period_s", path),
                course_deg=_number(ship, "forecast", "course_deg", path),
                latitude_deg=_number(ship, "forecast", "latitude_deg", path),
                motion=str(ship.get("motion", "roll")),
                amplitude_cm=(
                    _number(ship, "forecast", "amplitude_cm", path)
                    if "amplitude_cm" in ship
                    else None
                ),
            )
    except AnalysisError as exc:
        fail(f"plan {path}: {exc}")
    return AnalysisSettings(
        constants=constants,
        q=_number(settings, "analysis", "q", path) if "q" in settings else 0.05,
        start=(
            _number(settings, "analysis", "start_c", path),
            _number(settings, "analysis", "start_t_s", path),
        ),
        admissible=admissible,
        forecast=forecast,
    )


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
        """Analyse a CSV of trials (Cochran, fit, adequacy, control, forecast)."""
        if csv is None:
            fail("no source given: use --csv FILE (see examples/paper.csv)")
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
