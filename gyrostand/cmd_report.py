"""CLI: report."""

import typer

from gyrostand.errors import not_implemented


def register(app: typer.Typer) -> None:
    """Add the report command(s) to the CLI."""

    @app.command()
    def report() -> None:
        """Write the stand report (HTML, PDF, JSON, CSV) of a campaign."""
        not_implemented("report")
