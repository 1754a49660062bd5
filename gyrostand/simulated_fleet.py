"""A simulated fleet: one instrument model's units, each with its own true C and T drawn from
the type's distribution (normal), in groups (factories); one group's units shifted. Each unit
runs one campaign of a plan on the simulated stand, labelled with its group, and is analysed,
so that `fleet analyze` has a fleet whose answer is known."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import typer

from gyrostand.analysis.fleet import FleetAnalysis, FleetUnit
from gyrostand.cmd_campaign import BusOptions, new_campaign
from gyrostand.cmd_data import open_db
from gyrostand.db.lease import take_lease
from gyrostand.plan.model import Plan, parse_plan
from gyrostand.plan.overrides import with_keys
from gyrostand.report.stored import analyze_stored

QUICK = {
    "bus.simulator": {"heading_rate_hz": 2.0, "status_rate_hz": 0.5},
    "bus.simulator.compass": {"undamped_period_s": 240.0, "damping_ratio": 0.8},
    "settle": {"undamped_period_s": 240.0, "damping_ratio": 0.8},
    "observation": {"still_window_s": 30.0, "rocking_window_periods": 4},
    "tracking": {"confirm_s": 30.0},
}
"""A plan's trials and N on a simulated compass that settles in minutes instead of hours: undamped
precession period 240 s (the paper's compass: 84 min), damping ratio 0.8, heading frames at 2 Hz,
windows of 30 s still and 4 rocking periods (the paper's plan: 60 s and 8), the stand given 30 s
to reach its motion. The paper's plan then runs in about 3 s a campaign instead of 30."""


@dataclass(frozen=True)
class FleetDesign:
    """The type's distribution (C relative, T absolute SD), the groups and the shift of one."""

    groups: tuple[str, ...] = ("A", "B", "C")
    units_per_group: int = 3
    c_mean_gcm2s2: float = 6.0e7
    c_sd_fraction: float = 0.03
    t_mean_s: float = 1.1
    t_sd_s: float = 0.03
    shifted: str | None = "C"
    c_shift_fraction: float = 0.0
    t_shift_s: float = 0.3
    seed: int = 1


@dataclass(frozen=True)
class SimulatedUnit:
    campaign_id: int
    serial: str
    group: str
    true_c_gcm2s2: float
    true_t_s: float


def with_tables(plan: Plan, tables: Mapping[str, Mapping[str, Any]]) -> Plan:
    """The plan with keys of some tables set in its text (`with_keys`), so that each campaign
    stores the plan it ran. ValueError for a layout `with_keys` cannot edit, `PlanError`."""
    return parse_plan(with_keys(plan.text, tables))


def unit_plan(plan: Plan, serial: str, c: float, t: float, seed: int) -> Plan:
    """The plan for one unit: its serial, its simulated compass's true C and T, its seed."""
    return with_tables(
        plan,
        {
            "instrument": {"serial": serial},
            "bus": {"seed": seed},
            "bus.simulator.compass": {"c_gcm2s2": c, "t_s": t},
        },
    )


def simulate_fleet(
    plan: Plan,
    db: str,
    design: FleetDesign,
    factor: str = "factory",
    done: Callable[[SimulatedUnit], None] | None = None,
) -> list[SimulatedUnit]:
    """Run and analyse one campaign per unit into `db`, each labelled `factor` = its group
    (a simulated plan that is not `acquisition_only`), calling `done` after each. Raises
    typer.Exit (its one line on stderr) when a campaign cannot run."""
    rng = np.random.default_rng(design.seed)
    units = []
    for group in design.groups:
        shifted = group == design.shifted
        for i in range(1, design.units_per_group + 1):
            c = design.c_mean_gcm2s2 * (
                1
                + design.c_sd_fraction * rng.standard_normal()
                + (design.c_shift_fraction if shifted else 0.0)
            )
            t = design.t_mean_s + design.t_sd_s * rng.standard_normal()
            t += design.t_shift_s if shifted else 0.0
            serial = f"{group}-{i:03d}"
            seed = int(rng.integers(2**31))
            result, database = new_campaign(
                unit_plan(plan, serial, float(c), float(t), seed),
                db,
                BusOptions(None, None, None, None, None),
                quiet=True,
                labels={factor: group},
            )
            if result.outcome != "completed":
                typer.echo(f"campaign {result.campaign_id} of {serial}: {result.outcome}", err=True)
                raise typer.Exit(1)
            sessions = open_db(database, must_exist=True)
            try:
                take_lease(sessions, result.campaign_id).release()  # as the command's exit does
                analyze_stored(sessions, result.campaign_id)
            finally:
                sessions.kw["bind"].dispose()
            units.append(SimulatedUnit(result.campaign_id, serial, group, float(c), float(t)))
            if done is not None:
                done(units[-1])
    return units


@dataclass(frozen=True)
class SplitCheck:
    """The fleet analysis's measurement/type split against a simulated fleet's known truth, for
    one parameter: the units' actual measurement errors (estimate - true value) against the SEs
    their fits gave, and the type's SD the split estimated against the one the fleet was drawn
    with (C relative to its mean, T in seconds)."""

    symbol: str
    rms_error: float
    rms_se: float
    type_sd: float
    type_sd_interval: tuple[float, float]
    drawn_sd: float

    def line(self) -> str:
        """One line: what the split assumed (SE) against what the errors were, and its result."""
        unit, scale = ("%", 100.0) if self.symbol == "C" else (" s", 1.0)
        low, high = (scale * x for x in self.type_sd_interval)
        return (
            f"  {self.symbol}: actual errors RMS {scale * self.rms_error:.3g}{unit} against the "
            f"fits' SEs RMS {scale * self.rms_se:.3g}{unit} (ratio "
            f"{self.rms_error / self.rms_se:.2f}); the type's SD from the split "
            f"{scale * self.type_sd:.3g}{unit} ({low:.3g} to {high:.3g}), drawn with "
            f"{scale * self.drawn_sd:.3g}{unit}"
        )


def split_check(
    made: list[SimulatedUnit],
    units: Sequence[FleetUnit],
    analysis: FleetAnalysis,
    design: FleetDesign,
) -> tuple[SplitCheck, ...]:
    """C (relative) and T of the fleet `analysis` of `units` against the truth of `made`."""
    truth = {u.campaign_id: u for u in made}
    measured = [u for u in units if u.campaign_id in truth]
    checks = []
    for p in analysis.parameters:
        relative = p.symbol == "C"
        errors, ses = [], []
        for u in measured:
            value, se = u.value(p.parameter)
            true = truth[u.campaign_id].true_c_gcm2s2 if relative else truth[u.campaign_id].true_t_s
            scale = true if relative else 1.0
            errors.append((value - true) / scale)
            ses.append(se / scale)
        mean = p.anova.grand_mean if relative else 1.0
        checks.append(
            SplitCheck(
                symbol=p.symbol,
                rms_error=float(np.sqrt(np.mean(np.square(errors)))),
                rms_se=float(np.sqrt(np.mean(np.square(ses)))),
                type_sd=p.anova.s2_type**0.5 / mean,
                type_sd_interval=(
                    p.anova.s2_type_interval[0] ** 0.5 / mean,
                    p.anova.s2_type_interval[1] ** 0.5 / mean,
                ),
                drawn_sd=design.c_sd_fraction if relative else design.t_sd_s,
            )
        )
    return tuple(checks)
