"""The `gyrostand` command line: a thin composition root over stand, db, acquisition, analysis."""

from pathlib import Path
from typing import Annotated

import typer

from gyrostand import __version__
from gyrostand.errors import not_implemented

app = typer.Typer(
    name="gyrostand",
    help="Rolling-stand tests of marine gyrocompasses: simulate, acquire, analyse, report.",
    no_args_is_help=True,
    add_completion=False,
)
campaign_app = typer.Typer(
    help="Run, resume and inspect rolling-stand campaigns.", no_args_is_help=True
)
app.add_typer(campaign_app, name="campaign")


def _version(value: bool) -> None:
    if value:
        typer.echo(f"gyrostand {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """Rolling-stand tests of marine gyrocompasses."""


@app.command()
def simulate() -> None:
    """Run the simulated gyrocompass + roll stand on a CAN bus."""
    not_implemented("simulate")


@campaign_app.command("run")
def campaign_run(plan: Path) -> None:
    """Run a campaign plan (TOML) on the stand."""
    not_implemented("campaign run")


@campaign_app.command("resume")
def campaign_resume(campaign_id: int) -> None:
    """Continue a campaign from its first incomplete series."""
    not_implemented("campaign resume")


@campaign_app.command("status")
def campaign_status(campaign_id: int) -> None:
    """Show where a campaign stands."""
    not_implemented("campaign status")


@app.command()
def analyze() -> None:
    """Analyse a campaign or a CSV of trials (Cochran, fit, adequacy, control, forecast)."""
    not_implemented("analyze")


@app.command()
def report() -> None:
    """Write the stand report (HTML, PDF, JSON, CSV) of a campaign."""
    not_implemented("report")


@app.command("import")
def import_() -> None:
    """Import historical manual measurements from a file."""
    not_implemented("import")


@app.command()
def export() -> None:
    """Export a campaign's observations (CSV, Parquet, Excel)."""
    not_implemented("export")


@app.command()
def replay() -> None:
    """Re-derive observations offline from a raw CAN log into a new campaign."""
    not_implemented("replay")


@app.command()
def demo() -> None:
    """Run the whole chain on the embedded defaults."""
    not_implemented("demo")
