"""A simulated fleet: one instrument model's units, each with its own true C and T drawn from
the type's distribution (normal), in groups (factories); one group's units shifted. Each unit
runs one campaign of a plan on the simulated stand, labelled with its group, and is analysed,
so that `fleet analyze` has a fleet whose answer is known."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import typer

from gyrostand.cmd_campaign import BusOptions, new_campaign
from gyrostand.cmd_data import open_db
from gyrostand.db.lease import take_lease
from gyrostand.plan.model import Plan, revised
from gyrostand.report.stored import analyze_stored


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


def unit_plan(plan: Plan, serial: str, c: float, t: float, seed: int) -> Plan:
    """The plan for one unit: its serial, its simulated compass's true C and T, its seed."""
    bus = plan.model_dump(exclude_unset=True).get("bus", {})
    simulator = bus.get("simulator", {})
    compass = {**simulator.get("compass", {}), "C_gcm2s2": c, "T_s": t}
    return revised(
        plan,
        instrument={"serial": serial},
        bus={**bus, "seed": seed, "simulator": {**simulator, "compass": compass}},
    )


def simulate_fleet(
    plan: Plan, db: str, design: FleetDesign, factor: str = "factory"
) -> list[SimulatedUnit]:
    """Run and analyse one campaign per unit into `db`, each labelled `factor` = its group
    (a simulated plan that is not `acquisition_only`). Raises typer.Exit (its one line on
    stderr) when a campaign cannot run."""
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
                with sessions.begin() as session:
                    analyze_stored(session, result.campaign_id)
            finally:
                sessions.kw["bind"].dispose()
            units.append(SimulatedUnit(result.campaign_id, serial, group, float(c), float(t)))
    return units
