"""CLI: fleet statistics over the analysed campaigns of one instrument model (`fleet analyze`)
and a simulated fleet to try them on (`fleet simulate`)."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from gyrostand.cmd_data import DEFAULT_DB, DbOption, open_db
from gyrostand.errors import fail, printable_lines


def register(app: typer.Typer) -> None:
    """Add the fleet analyze command to the CLI."""

    fleet_app = typer.Typer(
        help="Fleet statistics across the units of one instrument model.", no_args_is_help=True
    )
    app.add_typer(fleet_app, name="fleet")

    @fleet_app.command("analyze")
    def fleet_analyze(
        model: Annotated[str, typer.Option(help="Instrument model.")],
        by: Annotated[
            str,
            typer.Option(help="The label key the units are grouped by: factory, lot, stand..."),
        ],
        q: Annotated[
            float, typer.Option(help="Significance level of the tests.", min=0.001, max=0.2)
        ] = 0.05,
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON document.")] = False,
        db: DbOption = DEFAULT_DB,
    ) -> None:
        """Compare the groups of a model's units (Fisher's analysis of variance and Smirnov's
        test of C and T, Sveshnikov section 8.2) and name the units outside the type's
        prediction interval. Each unit counts once: its latest completed, analysed campaign
        with the label."""
        from gyrostand.analysis.fleet import FleetError, analyze_fleet
        from gyrostand.db.queries import LABEL_KEY
        from gyrostand.report.fleet import fleet_inputs, fleet_text

        if not LABEL_KEY.fullmatch(by):
            fail(f"--by {by!r} is no label key (lower-case letters, digits and _)")
        with open_db(db, must_exist=True)() as session:
            inputs = fleet_inputs(session, model, by)
        if not inputs.units and not inputs.left_out:
            fail(f"no completed campaign of model {model!r} in the database")
        try:
            analysis = analyze_fleet(inputs.units, factor=by, q=q)
        except FleetError as error:
            fail(f"model {model}: {error}")
        if as_json:
            left_out = [vars(c) for c in inputs.left_out]
            document = {"model": model, **analysis.to_dict(), "left_out": left_out}
            typer.echo(json.dumps(document, indent=2, allow_nan=False))
            return
        typer.echo(printable_lines(fleet_text(inputs, analysis)))
