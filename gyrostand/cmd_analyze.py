"""CLI: analyze."""

import typer

from gyrostand.errors import not_implemented


def register(app: typer.Typer) -> None:
    """Add the analyze command(s) to the CLI."""

    @app.command()
    def analyze() -> None:
        """Analyse a campaign or a CSV of trials (Cochran, fit, adequacy, control, forecast)."""
        not_implemented("analyze")
