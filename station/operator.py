"""The operator's actions that reach a running acquisition through the database, whichever
process or host runs it (`acquisition.operator` polls for them): an answer to the prompt it
waits for, and a safe-stop request. Also the plan's prompts before the campaign, answered in
the start form."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from gyrostand.db.models import Event
from gyrostand.db.queries import stand_campaign
from gyrostand.plan.model import Plan, PromptPlan, parse_plan
from gyrostand.plan.prompts import ANSWER, PROMPT, STOP_REQUEST, message, pending
from gyrostand.plan.switching import all_prompts

FIELD = "answer-"
"""The start form's field of a prompt's answer: answer-ID."""
UNIT_FIELDS = (("instrument", "model"), ("instrument", "serial"), ("campaign", "operator"))
"""The start form's fields TABLE.KEY of the plan: the device under test and who runs it."""


def pending_prompt(session: Session, campaign_id: int) -> tuple[str, str] | None:
    """The prompt (ID, text) the acquisition waits for an answer to, if any."""
    rows = session.execute(
        select(Event.kind, Event.message)
        .where(Event.campaign_id == campaign_id, Event.kind.in_((PROMPT, ANSWER)))
        .order_by(Event.id)
    ).all()
    return pending((m for k, m in rows if k == PROMPT), (m for k, m in rows if k == ANSWER))


class ActionRefused(ValueError):
    """An answer or a stop that cannot be stored (one line why)."""


def waiting_for(session: Session, campaign_id: int) -> dict[str, Any] | None:
    """The prompt the acquisition waits for (id, text, kind), or None."""
    pending = pending_prompt(session, campaign_id)
    if pending is None:
        return None
    prompt = _prompt(session, campaign_id, pending[0])
    return {"id": prompt.id, "text": prompt.text, "kind": prompt.kind}


def _prompt(session: Session, campaign_id: int, prompt_id: str) -> PromptPlan:
    plan = parse_plan(stand_campaign(session, campaign_id).plan_toml)
    prompt = next((p for p in all_prompts(plan) if p.id == prompt_id), None)
    if prompt is None:
        raise ActionRefused(f"the campaign's plan has no prompt {prompt_id!r}")
    return prompt


def answer(session: Session, campaign_id: int, prompt_id: str, value: str) -> str:
    """Store the answer to the prompt the acquisition waits for; the stored answer."""
    pending = pending_prompt(session, campaign_id)
    if pending is None or pending[0] != prompt_id:
        raise ActionRefused(f"{prompt_id}: not asked now (answered already?)")
    try:
        stored = _prompt(session, campaign_id, prompt_id).answer(value)
    except ValueError as exc:
        raise ActionRefused(str(exc)) from None
    session.add(Event(campaign_id=campaign_id, kind=ANSWER, severity="info",
                      message=message(prompt_id, stored)))  # fmt: skip
    return stored


def request_stop(session: Session, campaign_id: int) -> None:
    """A safe-stop request the acquisition acts on at its next checkpoint."""
    session.add(Event(campaign_id=campaign_id, kind=STOP_REQUEST, severity="info",
                      message="safe stop requested at the station"))  # fmt: skip


def start_answers(plan: Plan, form: Mapping[str, Any]) -> tuple[dict[str, str], list[str]]:
    """The start form's answers to the plan's prompts before the campaign, and its problems
    ("[[prompt]] ID: ..." lines, one per prompt not answered well)."""
    answers, problems = {}, []
    for prompt in plan.prompts_before("campaign"):
        try:
            answers[prompt.id] = prompt.answer(str(form.get(FIELD + prompt.id, "")))
        except ValueError as exc:
            problems.append(f"[[prompt]] {exc}")
    return answers, problems


def unit_values(plan: Plan, form: Mapping[str, Any]) -> dict[str, str]:
    """The start form's device under test and operator (TABLE.KEY: value), the plan's values
    where the form has none."""
    values = {}
    for table, key in UNIT_FIELDS:
        name = f"{table}.{key}"
        values[name] = str(form.get(name, getattr(getattr(plan, table), key))).strip()
    return values


def with_unit(plan: Plan, values: Mapping[str, str]) -> tuple[str, list[str]]:
    """The plan's text with the start form's device under test and operator in it (tomlkit
    keeps the rest of the file as written: the text is unchanged when they are), and its
    problems ("[table] key: ..." lines)."""
    import tomlkit

    document = tomlkit.parse(plan.text)
    problems = []
    for name, value in values.items():
        table, key = name.split(".")
        if not value:
            problems.append(f"[{table}] {key}: must not be empty")
        elif value != getattr(getattr(plan, table), key):
            document[table][key] = value  # type: ignore[index]
    return tomlkit.dumps(document), problems
