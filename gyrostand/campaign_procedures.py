"""The standard's procedures of a campaign plan ([[procedure]]): resolved against the plan's
compliance profile ([standard] profile), run on the simulated compass before the trials, and
stored with the campaign; a resumed campaign keeps the stored results."""

from __future__ import annotations

from typing import TYPE_CHECKING

from gyrostand.errors import fail

if TYPE_CHECKING:
    from collections.abc import Mapping
    from threading import Event
    from typing import IO

    from gyrostand.acquisition.store import CampaignStore
    from gyrostand.plan.model import Plan, PromptPlan
    from gyrostand.plan.procedures import ResolvedProcedure


def resolved(plan: Plan) -> tuple[ResolvedProcedure, ...]:
    """The plan's procedures filled from its profile (one-line error: no such profile)."""
    from gyrostand.report.compliance import load_profile
    from gyrostand.report.errors import ReportError
    from gyrostand.report.procedures import resolve

    try:
        return resolve(plan, load_profile(plan.standard.profile))
    except ReportError as exc:
        fail(f"[standard] profile: {exc}")


def describe(procedure: ResolvedProcedure) -> str:
    """One procedure in one line: its parameters and departures."""
    p = procedure.plan
    if p.kind == "settling":
        text = (
            f"settling: from switch-on, band {p.band_deg:g} deg, recorded {p.max_wait_s:g} s, "
            f"fitted from {p.fit_from_s:g} s"
        )
    elif p.kind == "rolling":
        text = (
            f"rolling: {len(p.points or ())} envelope points, {p.readings} readings "
            f"{p.interval_s:g} s apart after {p.wait_s:g} s, beyond the stand: {p.beyond_stand}"
        )
    else:
        runs = (
            f"{p.runups} run-ups, off {p.off_s:g} s between, " if p.kind == "repeatability" else ""
        )
        text = f"{p.kind}: {runs}{p.readings} readings {p.interval_s:g} s apart after settling"
    if p.power == "manual":
        how = "on" if p.kind == "settling" else "off and on"
        text += f", switched {how} by hand (the operator is prompted)"
    departs = "; ".join(procedure.departures)
    return text + (f" (departs from the standard: {departs})" if departs else "")


def power_prompts(plan: Plan) -> dict[int, tuple[PromptPlan, ...]]:
    """By run-up, the operator's prompts to switch a compass powered by hand (`power =
    "manual"`): on for run-up 1 (settling); off, then on, for each further one (repeatability)."""
    from gyrostand.plan.model import PromptPlan

    out: dict[int, tuple[PromptPlan, ...]] = {}
    for p in plan.procedure:
        if p.power != "manual":
            continue
        if p.kind == "settling":
            text = "switch the compass on: run-up 1 (settling from switch-on) starts"
            out[1] = (PromptPlan(id="switch_on_1", text=text, before="campaign"),)
        for k in range(2, p.runups + 1) if p.kind == "repeatability" else ():
            off = f"switch the compass off: run-up {k - 1} of {p.runups} is done"
            on = f"switch the compass on after {p.off_s:g} s off: run-up {k} of {p.runups}"
            out[k] = (
                PromptPlan(id=f"switch_off_{k}", text=off, before="campaign"),
                PromptPlan(id=f"switch_on_{k}", text=on, before="campaign"),
            )
    return out


def all_prompts(plan: Plan) -> tuple[PromptPlan, ...]:
    """Every prompt a campaign of the plan may ask: the plan's ([[prompt]]) and the power
    switchings of its procedures (what `--answer` and the station may answer)."""
    return (*plan.prompt, *(p for ps in power_prompts(plan).values() for p in ps))


def run_procedures_of(
    plan: Plan,
    store: CampaignStore,
    quiet: bool,
    stop: Event,
    answers: Mapping[str, str] | None = None,
    terminal: IO[str] | None = None,
) -> bool:
    """Run and store the plan's procedures unless the campaign has them already; the stages an
    interrupted run did are kept, the one interrupted is redone. A compass powered by hand is
    switched when the operator answers the prompts (`answers`, the station or `terminal`).
    False: stopped part-way (by `stop` at the end of a stage, or a stop request while a prompt
    waits; the stages done are kept for `campaign resume`)."""
    if not plan.procedure:
        return True
    from rich.console import Console

    from gyrostand.acquisition.operator import OperatorLink
    from gyrostand.acquisition.procedures import (
        Progress,
        run_procedures,
        save_progress,
        store_procedures,
        stored_progress,
    )
    from gyrostand.stand.simconfig import simulator_config

    complete, done = stored_progress(store.sessions, store.campaign_id)
    if complete:
        return True
    procedures = resolved(plan)
    bus = plan.bus
    config = simulator_config(bus.simulator, speedup=bus.speedup, seed=bus.seed, timing=bus.timing)
    model = plan.settle.transient_model
    assert model is not None  # the plan's check
    if done:
        kept = ", ".join(k for k in done if not k.endswith("_s"))
        store.run_event("procedures", "info", f"the standard's procedures resumed: kept {kept}")

    def saved(stages: dict[str, object]) -> None:
        save_progress(store.sessions, store.campaign_id, stages)
        if stop.is_set():
            raise Stopped

    prompts = power_prompts(plan)
    console = None if quiet else Console(stderr=True)
    link = OperatorLink(store, plan, stop, answers or {}, terminal, console)

    def switch_on(k: int) -> None:
        for prompt in prompts.get(k, ()):
            if link.ask(prompt, "the standard's procedures") is not None:
                raise Stopped

    try:
        results = run_procedures(
            config,
            procedures,
            plan.reference,
            model,
            plan.stand_limits,
            plan.site.latitude_deg,
            Progress(done, saved),
            switch_on,
        )
    except Stopped:
        return False
    store_procedures(store.sessions, store.campaign_id, results)
    kinds = ", ".join(p.kind for p in procedures)
    store.run_event("procedures", "info", f"the standard's procedures run and stored: {kinds}")
    if not quiet:
        print(f"campaign {store.campaign_id}: the standard's procedures done ({kinds})")
    return True


class Stopped(Exception):
    """A stop asked for while the procedures ran (raised once a stage is saved)."""
