"""CLI: plan check|schema -- validate a campaign plan file; the plan's JSON Schema for editors.

`gyrostand plan check PLAN` prints one summary line (with the fit's residual degrees of freedom,
and a warning line when they are few), or every problem one per line with its path in the plan
(exit code 1). `gyrostand plan schema [--out FILE]` prints the JSON Schema of a
plan file, generated from the plan model (docs/plan.md).
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
    """The plan in one line: design with the fit's residual degrees of freedom, N, settle, bus,
    database."""
    fit = sum(t.role == "fit" for t in plan.trials)
    design = f"{len(plan.trials)} trials ({fit} fit, {len(plan.trials) - fit} control)"
    if not plan.campaign.acquisition_only:
        design += f", {plan.residual_dof} residual degrees of freedom"
    bus = plan.bus
    if bus.simulated:
        where = f"simulated stand in {bus.timing} time"
    else:
        where = f"python-can {bus.interface or '(configured)'} {bus.channel or ''}".rstrip()
    if plan.compass.protocol != "gyrostand":
        where += f", compass on {plan.compass.protocol}"
        if plan.compass.protocol == "iec61162" and not bus.simulated:
            where += f" at {plan.compass.port}, {plan.compass.baud} baud"
    acceptance = ", acceptance by excursions" if plan.acceptance is not None else ""
    return (
        f"{design}, N = {plan.n_obs}, settle by {plan.settle.method}{acceptance}, {where}, "
        f"database {shown_url(plan.database)}"
    )


def design_warning(plan: Plan) -> str | None:
    """Why the design is fragile when it leaves few residual degrees of freedom (None if not)."""
    from gyrostand.plan.model import FEW_RESIDUAL_DOF, FIT_PARAMETERS

    dof = plan.residual_dof
    if plan.campaign.acquisition_only or dof > FEW_RESIDUAL_DOF:
        return None
    return (
        f"the fit of C and T leaves {dof} residual degree{'s' if dof != 1 else ''} of freedom "
        f"(fit trials minus the {FIT_PARAMETERS} parameters): its t({dof}) intervals are wide, "
        "and a residual variance near 0 by chance goes unnoticed in them; add fit trials"
    )


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
        from gyrostand.plan.codec import prepare
        from gyrostand.plan.model import PlanError, load_plan

        try:
            checked = load_plan(plan)
            prepare(checked)
        except PlanError as exc:
            for problem in exc.problems:
                typer.echo(f"{plan}: {problem}")
            raise typer.Exit(EXIT_FAILED) from None
        typer.echo(f"{plan}: ok — {summary(checked)}")
        if warning := design_warning(checked):
            typer.echo(f"{plan}: warning — {warning}")

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
