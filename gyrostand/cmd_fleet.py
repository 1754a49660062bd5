"""CLI: fleet statistics over the analysed campaigns of one instrument model (`fleet analyze`),
their report (`fleet report`: HTML, PDF or JSON) and a simulated fleet to try them on
(`fleet simulate`)."""

from __future__ import annotations

import json
import re
import shlex
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from gyrostand.cmd_data import DEFAULT_DB, DbOption, JsonOption, open_db
from gyrostand.db.url import DB_ENV, shown_url
from gyrostand.errors import fail, printable_lines
from gyrostand.stages import Stages

if TYPE_CHECKING:
    from gyrostand.analysis.fleet import FleetAnalysis
    from gyrostand.report.fleet import FleetInputs

ByOption = Annotated[
    str, typer.Option(help="The label key the units are grouped by: factory, lot, stand...")
]
QOption = Annotated[
    float, typer.Option(help="Significance level of the tests.", min=0.001, max=0.2)
]
GROUP_NAMES = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"


def analysed_fleet(model: str, by: str, q: float, db: str) -> tuple[FleetInputs, FleetAnalysis]:
    """The units of `model` in `db` grouped by label `by`, and their analysis (one-line
    errors)."""
    from gyrostand.analysis.fleet import FleetError, analyze_fleet
    from gyrostand.db.queries import LABEL_KEY
    from gyrostand.report.fleet import fleet_inputs

    if not LABEL_KEY.fullmatch(by):
        fail(f"--by {by!r} is no label key (lower-case letters, digits and _)")
    with open_db(db, must_exist=True)() as session:
        inputs = fleet_inputs(session, model, by)
    if not inputs.units and not inputs.left_out:
        fail(f"no completed campaign of model {model!r} in the database")
    try:
        return inputs, analyze_fleet(inputs.units, factor=by, q=q)
    except FleetError as error:
        why: dict[str, list[int]] = {}  # the campaigns left out, by reason
        for c in inputs.left_out:
            why.setdefault(c.reason, []).append(c.campaign_id)
        left = "; ".join(
            f"campaign{'s' if len(ids) > 1 else ''} {', '.join(map(str, sorted(ids)))}: {reason}"
            for reason, ids in why.items()
        )
        fail(f"model {model}: {error}" + (f" (left out: {left})" if left else ""))


def register(app: typer.Typer) -> None:
    """Add the fleet commands (analyze, report, simulate) to the CLI."""

    fleet_app = typer.Typer(
        help="Fleet statistics across the units of one instrument model.", no_args_is_help=True
    )
    app.add_typer(fleet_app, name="fleet")

    @fleet_app.command("analyze")
    def fleet_analyze(
        model: Annotated[str, typer.Option(help="Instrument model.")],
        by: ByOption,
        q: QOption = 0.05,
        as_json: JsonOption = False,
        db: DbOption = DEFAULT_DB,
    ) -> None:
        """Compare the groups of a model's units (Fisher's analysis of variance and Smirnov's
        test of C and T, Sveshnikov section 8.2) and name the units outside the type's
        prediction interval. Each unit counts once: its latest completed, analysed campaign
        with the label."""
        from gyrostand.report.fleet import fleet_document, fleet_text

        inputs, analysis = analysed_fleet(model, by, q, db)
        if as_json:
            document = fleet_document(inputs, analysis)
            typer.echo(json.dumps(document, indent=2, allow_nan=False))
            return
        typer.echo(printable_lines(fleet_text(inputs, analysis)))

    @fleet_app.command("report")
    def fleet_report(
        model: Annotated[str, typer.Option(help="Instrument model.")],
        by: ByOption,
        out: Annotated[
            Path | None,
            typer.Option(
                "--out",
                "-o",
                help=(
                    "The report file; its suffix names the format: .html, .pdf or .json "
                    "(default: runs/reports/fleet-MODEL-by-LABEL.html)."
                ),
            ),
        ] = None,
        q: QOption = 0.05,
        draft: Annotated[
            bool, typer.Option("--draft", help="Mark every page DRAFT (not for issue).")
        ] = False,
        number: Annotated[
            str | None,
            typer.Option("--number", help="The report's number (without it: a DRAFT)."),
        ] = None,
        laboratory: Annotated[
            str | None,
            typer.Option("--laboratory", help="The issuing laboratory (without it: a DRAFT)."),
        ] = None,
        db: DbOption = DEFAULT_DB,
    ) -> None:
        """Write the fleet report (HTML, PDF or JSON) of a model's units grouped by a label.

        Which groups differ (analysis of variance, Smirnov's tests, Sveshnikov section 8.2),
        the units outside the type's prediction interval, control charts of C and T."""
        from gyrostand import SOFTWARE_VERSION
        from gyrostand.cmd_report import DEFAULT_OUT, stage
        from gyrostand.report import collector_paused
        from gyrostand.report.errors import ReportError
        from gyrostand.report.fleet import (
            FleetReport,
            fleet_format,
            simulated_campaigns,
            write_fleet_report,
        )

        path = out or DEFAULT_OUT / f"fleet-{re.sub(r'[^A-Za-z0-9]+', '-', model)}-by-{by}.html"
        try:
            fleet_format(path)
        except ReportError as error:
            fail(f"--out {error}")
        with collector_paused():  # the report's garbage: see `collector_paused`
            inputs, analysis = analysed_fleet(model, by, q, db)
            with open_db(db, must_exist=True)() as session:
                simulated = simulated_campaigns(session, inputs.units)
            report = FleetReport(
                inputs=inputs,
                analysis=analysis,
                generated_at=datetime.now(UTC).isoformat(sep=" ", timespec="seconds"),
                database=shown_url(db),
                software=SOFTWARE_VERSION,
                simulated=simulated,
                marked_draft=draft,
                number=number,
                laboratory=laboratory,
            )
            if report.missing:
                stage(f"a DRAFT: it lacks {', '.join(report.missing)} (--number, --laboratory)")
            stage(f"fleet of {model} by {by}: {analysis.n_units} units; writing {path}")
            try:
                typer.echo(
                    f"wrote {path.suffix.lstrip('.').lower()}: {write_fleet_report(report, path)}"
                )
            except ReportError as error:
                fail(str(error))

    @fleet_app.command("simulate")
    def fleet_simulate(
        db: Annotated[
            str,
            typer.Option(
                "--db", envvar=DB_ENV, help="Database to add the fleet to: a SQLite file or URL."
            ),
        ],
        units_per_group: Annotated[int, typer.Option(help="Units per group.", min=2)] = 4,
        groups: Annotated[
            int, typer.Option(help="Groups (factories A, B, ...).", min=2, max=26)
        ] = 3,
        shift_group: Annotated[str, typer.Option(help="The group whose C is shifted.")] = "B",
        shift: Annotated[
            float,
            typer.Option(
                help="Relative shift of the shifted group's C (0.2: 20 % larger).",
                min=-0.5,
                max=0.5,
            ),
        ] = 0.2,
        seed: Annotated[
            int, typer.Option(help="Random seed of the units and their campaigns.")
        ] = 1,
        model: Annotated[
            str | None, typer.Option(help="Instrument model (default: the plan's).")
        ] = None,
        plan: Annotated[
            Path | None,
            typer.Option(
                help=(
                    "A simulated campaign plan (TOML) every unit runs. Default: the paper's six "
                    "trials with N = 5 on a simulated compass that settles in minutes instead "
                    "of hours (undamped period 240 s, heading at 2 Hz, windows of 30 s and 4 "
                    "rocking periods): about 3 s a unit; the paper's plan itself "
                    "(examples/paper.toml) takes about 30 s a unit."
                )
            ),
        ] = None,
    ) -> None:
        """Build a simulated fleet, one factory's C shifted, to try the fleet statistics on.

        Units of one model in factories A, B, ..., each unit's true C and T drawn from the
        type's distribution (C: 6.0e7 g·cm²·s⁻², SD 3 %; T: 1.1 s, SD 0.03 s), the shifted
        factory's C moved by --shift; one campaign per unit on the simulated stand, labelled
        factory=..., and analysed."""
        from gyrostand.cmd_campaign import _load
        from gyrostand.cmd_demo import DEMO_PLAN
        from gyrostand.plan.model import PlanError
        from gyrostand.simulated_fleet import (
            QUICK,
            FleetDesign,
            SimulatedUnit,
            simulate_fleet,
            split_check,
            with_tables,
        )

        names = tuple(GROUP_NAMES[:groups])
        if shift_group not in names:
            fail(f"--shift-group {shift_group!r} is not among the groups {', '.join(names)}")
        source = plan or Path(str(DEMO_PLAN))
        base = _load(source)
        if not base.bus.simulated or base.campaign.acquisition_only:
            fail(f"{source}: the plan must run on the simulated stand and be analysed")
        changes = {} if plan else dict(QUICK)
        if model is not None:
            changes["instrument"] = {"model": model}
        try:
            base = with_tables(base, changes)
        except ValueError as error:
            fail(f"{source}: cannot set the fleet's keys in the plan's text: {error}")
        except PlanError as error:
            fail(f"{source} with the fleet's keys: invalid plan: " + "; ".join(error.problems))
        design = FleetDesign(
            groups=names,
            units_per_group=units_per_group,
            shifted=shift_group,
            c_shift_fraction=shift,
            t_shift_s=0.0,
            seed=seed,
        )
        shown = shown_url(db)
        typer.echo(
            f"fleet of {base.instrument.model}: {groups} factories x {units_per_group} units, "
            f"factory {shift_group}'s C shifted by {shift:+.0%}; one campaign a unit into {shown}"
        )
        started = time.monotonic()
        units = groups * units_per_group

        with Stages("fleet simulate") as stage:

            def done(unit: SimulatedUnit) -> None:
                typer.echo(
                    f"  campaign {unit.campaign_id}: {unit.serial} (factory {unit.group}), true "
                    f"C = {unit.true_c_gcm2s2 / 1e7:.3f}e7 g·cm²·s⁻², T = {unit.true_t_s:.3f} s"
                )
                finished = len(made) + 1
                made.append(unit)
                if finished < units:
                    stage(f"unit {finished}/{units} done; running unit {finished + 1}")

            made: list[SimulatedUnit] = []
            stage(f"running and analysing unit 1/{units} on the simulated stand")
            simulate_fleet(base, db, design, "factory", done)
            stage.done(f"{units} campaigns run and analysed")
        from gyrostand.analysis.fleet import FleetError, analyze_fleet
        from gyrostand.report.fleet import fleet_inputs

        with open_db(db, must_exist=True)() as session:
            inputs = fleet_inputs(session, base.instrument.model, "factory")
        try:
            analysis = analyze_fleet(inputs.units, factor="factory")
        except FleetError as error:
            typer.echo(f"the split cannot be checked: {error}")
        else:
            typer.echo(
                "the measurement/type split (fleet analysis) against the known truth; "
                "the type's SD with its 95 % interval:"
            )
            for check in split_check(made, inputs.units, analysis, design):
                typer.echo(check.line())
        where = f"--model {shlex.quote(base.instrument.model)} --by factory"
        where += f" --db {shlex.quote(shown)}"
        typer.echo(
            f"{groups * units_per_group} units in {time.monotonic() - started:.0f} s. Next:\n"
            f"  gyrostand fleet analyze {where}\n"
            f"  gyrostand fleet report {where} -o fleet.pdf"
        )
