"""CLI: import, export."""

import typer

from gyrostand.errors import not_implemented


def register(app: typer.Typer) -> None:
    """Add the import, export command(s) to the CLI."""

    @app.command("import")
    def import_() -> None:
        """Import historical manual measurements from a file."""
        not_implemented("import")

    @app.command()
    def export() -> None:
        """Export a campaign's observations (CSV, Parquet, Excel)."""
        not_implemented("export")
