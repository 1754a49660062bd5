"""CLI: demo -- the whole chain on the embedded defaults: the campaign of Potemkin (1982) on the
simulated gyrocompass + roll stand over an in-process python-can virtual bus, stored in SQLite
under ./runs/, analysed, and written up as the stand report."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gyrostand.cmd_campaign import BusOptions, new_campaign, print_outcome
from gyrostand.cmd_data import open_db
from gyrostand.cmd_report import DEFAULT_OUT, write_campaign_report

if TYPE_CHECKING:
    from gyrostand.db.queries import CampaignResult, Estimate

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
        from gyrostand.db.queries import campaign_result
        from gyrostand.station.state import conformity_verdict

        with open_db(database, must_exist=True)() as session:
            analysed = campaign_result(session, result.campaign_id)
        decision = conformity_verdict(written["json"]) if "json" in written else None
        for line in result_lines(analysed, decision):
            typer.echo(line)
        typer.echo(f"report: {written['html']}")


def result_lines(result: CampaignResult | None, decision: str | None) -> list[str]:
    """What a newcomer came for: C and T with their confidence intervals, Cochran's and Fisher's
    decisions, the report's decision."""
    if result is None:
        return ["result: the campaign could not be analysed (see the report)"]

    def estimate(name: str, e: Estimate | None, scale: float, exponent: str, unit: str) -> str:
        if e is None:
            return f"  {name}: not estimated"
        value, low, high = (f"{v / scale:.4f}{exponent}" for v in (e.value, e.low, e.high))
        return f"  {name} = {value} {unit}, {level} confidence interval {low} to {high}"

    def yes_no(value: bool | None) -> str:
        return "not tested" if value is None else ("yes" if value else "no")

    level = f"{100 * result.confidence:.0f} %"
    return [
        "result:",
        estimate("C", result.c_gcm2s2, 1e7, "e7", "g·cm²·s⁻²"),
        estimate("T", result.t_s, 1.0, "", "s"),
        f"  trial variances homogeneous (Cochran): {yes_no(result.homogeneous)}",
        f"  model adequate on the trial means (Fisher): {yes_no(result.adequate)}",
        f"  report's decision: {decision or 'not stated'}",
    ]
