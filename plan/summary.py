"""A checked plan in words: its design, N, settle method and bus on one line (`gyrostand plan
check`, the station's start form), why a design is fragile, whether its observations are
spaced to be independent, and keys in an old spelling."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass

from gyrostand.plan.model import FEW_RESIDUAL_DOF, FIT_PARAMETERS, K_PROMPT, Plan
from gyrostand.stand.simconfig import renamed_knobs


def describe(plan: Plan) -> str:
    """The design with the fit's residual degrees of freedom, N, settle, acceptance, bus."""
    fit = sum(t.role == "fit" for t in plan.trials)
    design = f"{len(plan.trials)} trials ({fit} fit, {len(plan.trials) - fit} control)"
    if not plan.campaign.acquisition_only:
        design += f", {plan.residual_dof} residual degrees of freedom"
    bus = plan.bus
    if bus.simulated:
        pace = "virtual time" if bus.timing == "virtual" else "real time (paced by the wall clock)"
        where = f"simulated stand in {pace}"
    else:
        where = f"python-can {bus.interface or '(configured)'} {bus.channel or ''}".rstrip()
    if plan.stand.protocol == "cia402":
        k_prompts = sum(p.id.startswith(K_PROMPT) for p in plan.prompt)
        where += f", CiA 402 drive node {plan.stand.node_id} (K set by hand: {k_prompts} prompts)"
    if plan.compass.protocol != "gyrostand":
        where += f", compass on {plan.compass.protocol}"
    if plan.compass.own_bus:
        where += f" on its own bus ({plan.compass.interface} {plan.compass.channel})"
    if plan.inclinometer_mount is not None:
        protocol, address, axis, _ = plan.inclinometer_mount
        where += f", roll measured by a {protocol} inclinometer ({address}, axis {axis})"
    acceptance = ", acceptance by excursions" if plan.acceptance is not None else ""
    return f"{design}, N = {plan.n_obs}, settle by {plan.settle.method}{acceptance}, {where}"


def design_warning(plan: Plan) -> str | None:
    """Why the design is fragile when it leaves few residual degrees of freedom (None if not)."""
    dof = plan.residual_dof
    if plan.campaign.acquisition_only or dof > FEW_RESIDUAL_DOF:
        return None
    return (
        f"the fit of C and T leaves {dof} residual degree{'s' if dof != 1 else ''} of freedom "
        f"(fit trials minus the {FIT_PARAMETERS} parameters): its t({dof}) intervals are wide, "
        "and a residual variance near 0 by chance goes unnoticed in them; add fit trials"
    )


@dataclass(frozen=True)
class Spacing:
    """The plan's spacing against the one that makes successive observations independent, for
    the reading's correlation time: the correlation of successive observations at the plan's
    spacing in its shortest window (``window_s``; the still window when no rocking one is
    shorter), and the spacing from which every window's is at most ``max_correlation``."""

    correlation_time_s: float
    window_s: float
    spacing_s: float
    correlation: float
    needed_s: float
    max_correlation: float

    @property
    def independent(self) -> bool:
        return self.spacing_s >= self.needed_s

    def describe(self) -> str:
        where = (
            f"successive observations of the {self.window_s:g} s windows correlate "
            f"rho = {self.correlation:+.3f} at [observation] spacing_s = {self.spacing_s:g} for "
            f"the reading's correlation time {self.correlation_time_s:g} s (Sveshnikov "
            f"eqs 8.92-8.94)"
        )
        if self.independent:
            return f"{where}: independent (|rho| <= {self.max_correlation:g})"
        return (
            f"{where}, beyond |rho| = {self.max_correlation:g}: Cochran's and Fisher's tests "
            f"assume independent observations; set [observation] spacing_s = "
            f"{math.ceil(self.needed_s)} (stand seconds between windows)"
        )


def spacing(plan: Plan) -> Spacing | None:
    """The plan's observation spacing checked against [observation] correlation_time_s (None
    when the plan does not state it)."""
    from gyrostand.analysis.effective import (
        MAX_CORRELATION,
        independent_spacing_s,
        touching_correlation,
    )

    obs = plan.observation
    tau = obs.correlation_time_s
    if tau is None:
        return None
    windows = {obs.still_window_s, *(obs.rocking_window_periods * t.period_s for t in plan.trials)}
    window = min(windows)  # the shortest window correlates most (rho(W) falls with W)
    rho = touching_correlation(window, tau) * math.exp(-obs.spacing_s / tau)  # rho(W + s)
    needed = independent_spacing_s(window, tau)
    return Spacing(tau, window, obs.spacing_s, rho, needed, MAX_CORRELATION)


def old_spellings(plan: Plan) -> list[str]:
    """A note per `[bus.simulator]` knob the plan's text spells the old way (still read)."""
    simulator = tomllib.loads(plan.text).get("bus", {}).get("simulator", {})
    return [
        f"[bus.simulator.{table}] {old} is spelled {new} now (the old spelling is still read)"
        for table, old, new in renamed_knobs(simulator)
    ]
