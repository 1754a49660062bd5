"""CLI: campaign run/resume/status, replay."""

from pathlib import Path

import typer

from gyrostand.errors import not_implemented


def register(app: typer.Typer) -> None:
    """Add the campaign run/resume/status, replay command(s) to the CLI."""

    campaign_app = typer.Typer(help="Run, resume and inspect campaigns.", no_args_is_help=True)
    app.add_typer(campaign_app, name="campaign")

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
    def replay() -> None:
        """Re-derive observations offline from a raw CAN log into a new campaign."""
        not_implemented("replay")
