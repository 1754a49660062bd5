"""The operator's side of a live run, through the database's events (`plan.prompts`), so that
the station (any process, any host) and the terminal reach the acquisition alike: the plan's
prompts before a trial ("prompt" event, then the engine waits for an "answer" event) and
safe-stop requests ("stop_request" events, polled at the acquisition loop's checkpoints)."""

from __future__ import annotations

import select as os_select
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import IO

from rich.console import Console
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.models import Event
from gyrostand.plan.model import Plan, PromptPlan
from gyrostand.plan.prompts import ANSWER, PROMPT, STOP_REQUEST, keyed, message

POLL_S = 0.2
"""How often the database is asked for an answer or a stop request (wall time)."""


def messages(session: Session, campaign_id: int, kind: str) -> list[str]:
    """The campaign's event messages of `kind`, oldest first."""
    where = (Event.campaign_id == campaign_id, Event.kind == kind)
    return list(session.scalars(select(Event.message).where(*where).order_by(Event.id)))


def answers(session: Session, campaign_id: int) -> dict[str, str]:
    """The stored answers by prompt ID."""
    return keyed(messages(session, campaign_id, ANSWER))


def record_answers(
    store: CampaignStore, prompts: tuple[PromptPlan, ...], given: Mapping[str, str]
) -> None:
    """The prompts and their answers (already checked) as events."""
    for prompt in prompts:
        store.run_event(PROMPT, "info", message(prompt.id, prompt.text))
        store.run_event(ANSWER, "info", message(prompt.id, given[prompt.id]))


@dataclass
class OperatorLink:
    """The engine's `Operator` in a live run: answers come from `given` (the command line),
    the database (the station) or, with `terminal`, a line typed there; `waiting()` is called
    while it waits (the runner refreshes its display). Stop requests count after event
    `since`: the run's "resume" event (0 for a new campaign: every request counts)."""

    store: CampaignStore
    plan: Plan
    stop: threading.Event
    given: Mapping[str, str] = field(default_factory=dict)
    terminal: IO[str] | None = None
    console: Console | None = None
    waiting: Callable[[], None] = lambda: None
    since: int = field(init=False, default=0)
    _polled: float = field(init=False, default=0.0)

    def __post_init__(self) -> None:
        with self.store.sessions() as session:
            self.since = (
                session.scalar(
                    select(func.max(Event.id)).where(
                        Event.campaign_id == self.store.campaign_id, Event.kind == "resume"
                    )
                )
                or 0
            )

    def stop_requested(self) -> str | None:
        """Why to stop now: a signal, or a stop request in the database (asked at most every
        POLL_S)."""
        if self.stop.is_set():
            return "stopped by signal: stand told to stop rocking"
        now = time.monotonic()
        if now - self._polled < POLL_S:
            return None
        self._polled = now
        with self.store.sessions() as session:
            request = session.scalar(
                select(Event.message).where(
                    Event.campaign_id == self.store.campaign_id,
                    Event.kind == STOP_REQUEST,
                    Event.id > self.since,
                )
            )
        return None if request is None else f"{request}: stand told to stop rocking"

    def before_trial(self, trial: int) -> str | None:
        for prompt in self.plan.prompts_before(trial):
            stopped = self.ask(prompt, "before the next trial")
            if stopped is not None:
                return stopped
        return None

    def ask(self, prompt: PromptPlan, when: str) -> str | None:
        """Ask `prompt` (said to come `when`) and wait for its answer (None), unless answered
        in an earlier run of the campaign; or why the campaign is to stop. A prompt an earlier
        run asked and left unanswered (stopped while it waited) is the same prompt, still
        pending: asked again without a second "prompt" event."""
        with self.store.sessions() as session:
            if prompt.id in answers(session, self.store.campaign_id):
                return None
            asked = keyed(messages(session, self.store.campaign_id, PROMPT))
        if prompt.id not in asked:
            self.store.run_event(PROMPT, "info", message(prompt.id, prompt.text))
        return self._wait(prompt, when)

    def _wait(self, prompt: PromptPlan, when: str) -> str | None:
        """Until `prompt` is answered (None) or the campaign is to stop (why)."""
        if prompt.id in self.given:
            self.store.run_event(ANSWER, "info", message(prompt.id, self.given[prompt.id]))
            return None
        self._say(f"{when}: {prompt.text} ({self._how(prompt)})")
        while True:
            self.waiting()
            if (why := self.stop_requested()) is not None:
                return why
            with self.store.sessions() as session:
                if prompt.id in answers(session, self.store.campaign_id):
                    return None
            line = self._typed()
            if line is None:
                continue
            try:
                value = prompt.answer(line)
            except ValueError as exc:
                self._say(str(exc))
                continue
            self.store.run_event(ANSWER, "info", message(prompt.id, value))
            return None

    def _how(self, prompt: PromptPlan) -> str:
        where = "type it here or answer" if self.terminal is not None else "answer"
        what = "yes" if prompt.kind == "confirm" else "the answer"
        return f"{where} {what} at the station"

    def _say(self, line: str) -> None:
        if self.console is not None:
            self.console.print(line, markup=False, highlight=False)

    def _typed(self) -> str | None:
        """A line typed on the terminal within POLL_S, else None (after waiting POLL_S)."""
        if self.terminal is None:
            self.stop.wait(POLL_S)
            return None
        ready, _, _ = os_select.select([self.terminal], [], [], POLL_S)
        line = self.terminal.readline() if ready else None
        if line == "":  # end of input: the station answers
            self.terminal = None
        return line or None
