"""The plan's prompts ([[prompt]], `plan.model.PromptPlan`) as events of a campaign, in one format
for the acquisition (it asks, waits for the answer and polls for stop requests) and the station
(it answers and requests stops): a message is ``ID: TEXT`` for a prompt, ``ID: VALUE`` for its
answer."""

from __future__ import annotations

from collections.abc import Iterable

PROMPT, ANSWER, STOP_REQUEST = "prompt", "answer", "stop_request"
"""The event kinds."""


def message(prompt_id: str, text: str) -> str:
    return f"{prompt_id}: {text}"


def keyed(messages: Iterable[str]) -> dict[str, str]:
    """Messages by the ID they start with (the first one of each ID)."""
    found: dict[str, str] = {}
    for line in messages:
        key, _, value = line.partition(": ")
        found.setdefault(key, value)
    return found


def pending(asked: Iterable[str], answered: Iterable[str]) -> tuple[str, str] | None:
    """The first prompt (ID, text) of the `asked` messages that no `answered` one answers."""
    done = keyed(answered)
    return next(((k, text) for k, text in keyed(asked).items() if k not in done), None)
