"""CLI: plan check|schema -- validate a campaign plan file; the plan's JSON Schema for editors.

`gyrostand plan check PLAN` prints one summary line (with the fit's residual degrees of freedom,
and a warning line when they are few) and a line on the spacing of the observations (a warning
when successive ones are correlated, naming the spacing they need), or every problem one per
line on stderr ("gyrostand: error: PLAN: [table] key: ...", exit code 1). `gyrostand plan
schema [--out FILE]` prints the JSON Schema of a plan file, generated from the plan model
(docs/plan.md).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from gyrostand.db.url import shown_url
from gyrostand.errors import EXIT_FAILED, fail

if TYPE_CHECKING:
    from gyrostand.plan.model import Plan


def summary(plan: Plan) -> str:
    """The plan in one line: `plan.summary.describe` and the database."""
    from gyrostand.plan.summary import describe

    return f"{describe(plan)}, database {shown_url(plan.database)}"


def register(app: typer.Typer) -> None:
    """Add the plan check and plan schema commands to the CLI."""

    plan_app = typer.Typer(
        help="Check campaign plans; the plan's JSON Schema.", no_args_is_help=True
    )
    app.add_typer(plan_app, name="plan")

    @plan_app.command("check")
    def check(plan: Annotated[Path, typer.Argument(help="Campaign plan (TOML).")]) -> None:
        """Validate a plan as `campaign run` does before it touches the bus or the database:
        one summary line, or every problem one per line (exit code 1)."""
        from gyrostand.campaign_procedures import describe, resolved
        from gyrostand.plan.codec import prepare
        from gyrostand.plan.model import PlanError, load_plan
        from gyrostand.plan.summary import design_warning, old_spellings, spacing

        try:
            checked = load_plan(plan)
            prepare(checked)
        except PlanError as exc:
            for problem in exc.problems:
                typer.echo(f"gyrostand: error: {plan}: {problem}", err=True)
            raise typer.Exit(EXIT_FAILED) from None
        procedures = resolved(checked)
        typer.echo(f"{plan}: ok — {summary(checked)}")
        for procedure in procedures:
            typer.echo(f"{plan}: procedure — {describe(procedure)}")
        if warning := design_warning(checked):
            typer.echo(f"{plan}: warning — {warning}")
        if (observed := spacing(checked)) is None:
            typer.echo(
                f"{plan}: note — independence of successive observations not checked: "
                "state the reading's correlation time, [observation] correlation_time_s"
            )
        else:
            kind = "note" if observed.independent else "warning"
            typer.echo(f"{plan}: {kind} — {observed.describe()}")
        for note in old_spellings(checked):
            typer.echo(f"{plan}: note — {note}")

    @plan_app.command("schema")
    def schema(
        out: Annotated[
            Path | None, typer.Option("--out", help="Write it to this file (default: stdout).")
        ] = None,
    ) -> None:
        """Print the JSON Schema of a plan file (for editors that validate TOML, e.g. with a
        `#:schema FILE` first line)."""
        from gyrostand.plan.model import schema as plan_schema

        text = json.dumps(plan_schema(), indent=2) + "\n"
        if out is None:
            typer.echo(text, nl=False)
            return
        try:
            out.write_text(text, encoding="utf-8")
        except OSError as exc:
            fail(f"cannot write {out}: {exc.strerror or exc}")
        typer.echo(f"wrote {out}")
