"""CLI: demo -- the whole chain on the embedded defaults: the paper's campaign (seed 000) on the
simulated gyrocompass + roll stand over an in-process python-can virtual bus, stored in SQLite
under ./runs/, analysed, and written up as the stand report."""

from importlib.resources import files

import typer

from gyrostand.cmd_campaign import checked_plan, print_outcome, run_campaign
from gyrostand.cmd_data import open_db
from gyrostand.cmd_report import DEFAULT_OUT, write_campaign_report
from gyrostand.errors import fail

DEMO_PLAN = files("gyrostand") / "plans" / "paper.toml"  # also examples/paper.toml


def register(app: typer.Typer) -> None:
    """Add the demo command to the CLI."""

    @app.command()
    def demo(
        quiet: bool = typer.Option(False, "--quiet", help="No live progress display."),
    ) -> None:
        """Run the paper's campaign on the simulated stand, analyse it, write its report."""
        from gyrostand.acquisition.store import CampaignStore
        from gyrostand.plan.model import PlanError, parse_plan

        try:
            plan = parse_plan(DEMO_PLAN.read_text())
        except PlanError as exc:  # the shipped plan is tested; this guards a broken install
            fail("embedded demo plan invalid: " + "; ".join(exc.problems))
        plan = checked_plan(plan, interface=None, channel=None, db=None, speedup=None, seed=None)
        typer.echo(
            f"1/2 campaign: {len(plan.trials)} trials of the example of Potemkin (1982) on the "
            f"simulated stand (virtual CAN bus, {plan.bus.timing} time) into {plan.database}"
        )
        store = CampaignStore.create(open_db(plan.database, must_exist=False), plan)
        print_outcome(run_campaign(plan, store, quiet), plan.database)
        typer.echo("2/2 analysis and report")
        written = write_campaign_report(plan.database, store.campaign_id, DEFAULT_OUT)
        for kind, path in written.items():
            typer.echo(f"  {kind}: {path}")
        typer.echo(f"report: {written['html']}")
