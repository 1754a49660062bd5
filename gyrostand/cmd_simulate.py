"""CLI: simulate."""

import typer

from gyrostand.errors import not_implemented


def register(app: typer.Typer) -> None:
    """Add the simulate command(s) to the CLI."""

    @app.command()
    def simulate() -> None:
        """Run the simulated gyrocompass + roll stand on a CAN bus."""
        not_implemented("simulate")
