"""The operator's prompts to switch a compass powered by hand ([[procedure]] power = "manual"):
asked by the acquisition before each run-up, answered like the plan's [[prompt]] (the station,
the terminal or `--answer`)."""

from __future__ import annotations

from gyrostand.plan.model import Plan, PromptPlan


def power_prompts(plan: Plan) -> dict[int, tuple[PromptPlan, ...]]:
    """By run-up, the operator's prompts to switch a compass powered by hand (`power =
    "manual"`): on for run-up 1 (settling); off, then on, for each further one (repeatability)."""
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
