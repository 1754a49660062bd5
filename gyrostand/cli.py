"""The `gyrostand` command line: a thin composition root over stand, db, acquisition, analysis.

Each command lives in its own `cmd_*` module and registers itself here. The command modules
import the analysis, database and acquisition layers inside the commands, so `--help` does not
wait for scipy, matplotlib, pandas and SQLAlchemy (~2 s)."""

from typing import Annotated

import typer

from gyrostand import (
    SOFTWARE_VERSION,
    cmd_analyze,
    cmd_campaign,
    cmd_data,
    cmd_demo,
    cmd_plan,
    cmd_report,
    cmd_simulate,
)

app = typer.Typer(
    name="gyrostand",
    help="Rolling-stand tests of marine gyrocompasses: simulate, acquire, analyse, report.",
    no_args_is_help=True,
    add_completion=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(SOFTWARE_VERSION)
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """Rolling-stand tests of marine gyrocompasses."""


for module in (cmd_plan, cmd_simulate, cmd_campaign, cmd_analyze, cmd_report, cmd_data, cmd_demo):
    module.register(app)
