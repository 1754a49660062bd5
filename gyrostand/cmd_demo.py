"""CLI: demo -- the whole chain on the embedded defaults: the campaign of Potemkin (1982) on the
simulated gyrocompass + roll stand over an in-process python-can virtual bus, stored in SQLite
under ./runs/, analysed, and written up as the stand report."""

from importlib.resources import files
from pathlib import Path

import typer

from gyrostand.cmd_campaign import BusOptions, new_campaign, print_outcome
from gyrostand.cmd_report import DEFAULT_OUT, write_campaign_report

DEMO_PLAN = files("gyrostand") / "plans" / "paper.toml"  # also examples/paper.toml


def register(app: typer.Typer) -> None:
    """Add the demo command to the CLI."""

    @app.command()
    def demo(
        quiet: bool = typer.Option(False, "--quiet", help="No live progress display."),
    ) -> None:
        """Run the paper's campaign on the simulated stand, analyse it, write its report."""
        bus = BusOptions(interface=None, channel=None, speedup=None, seed=None, timing=None)
        typer.echo(
            "1/2 campaign: the example of Potemkin (1982) on the simulated stand (virtual CAN "
            "bus, virtual time)"
        )
        result, database = new_campaign(Path(str(DEMO_PLAN)), None, bus, quiet)
        print_outcome(result, database)
        typer.echo("2/2 analysis and report")
        written = write_campaign_report(database, result.campaign_id, DEFAULT_OUT)
        for kind, path in written.items():
            typer.echo(f"  {kind}: {path}")
        typer.echo(f"report: {written['html']}")
