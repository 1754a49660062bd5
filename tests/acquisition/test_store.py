"""The one resume rule: a process killed after a trial's last observation was committed but
before the trial was marked completed (waiting for the stand's stop acknowledgement); the
lease; a re-run. Each on both database back ends (`db_url`: SQLite and PostgreSQL)."""

import subprocess
import sys
import time
from dataclasses import replace

import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from gyrostand.acquisition.engine import Engine, ObservationResult
from gyrostand.acquisition.runner import resume_store
from gyrostand.acquisition.store import CampaignStore, ReRunMismatch
from gyrostand.analysis.settle import SettleOutcome
from gyrostand.cli import app
from gyrostand.db.lease import CampaignBusy, held_elsewhere
from gyrostand.db.models import Campaign, Event, Observation, Trial
from gyrostand.db.queries import ResumePoint, campaign_summary, first_incomplete_series
from gyrostand.db.session import open_database
from gyrostand.plan.model import parse_plan
from tests.acquisition.harness import plan_text

THREE = [(45.0, 24.0, 6.0, "fit"), (315.0, 20.0, 5.0, "fit"), (30.0, 20.0, 6.0, "fit")]


def killed_after_trial_2(url: str) -> CampaignStore:
    """Trial 1 completed, trial 2 with both series holding N = 3 observations but "running"."""
    sessions = open_database(url)
    store = CampaignStore.create(sessions, parse_plan(plan_text(THREE)))
    for trial in (1, 2):
        store.trial_started(trial)
        for j in (1, 2):
            for k in (1, 2, 3):
                value = 100.0 + 0.1 * (j - 1)
                store.observation(ObservationResult(trial, j, k, value, 0, 1, 10, 0, ""))
            if trial == 1:
                store.series_completed(trial, j)
    store.trial_completed(1, None)
    store.flush()  # (as the engine's call that wrote it ends)
    return store


def test_writes_are_held_until_an_observation_or_flush_and_stored_in_order(db_url: str) -> None:
    """An observation commits at once, with the writes held back before it; the others wait
    for it or for `flush`: what is stored is always a prefix of the engine's writes."""
    sessions = open_database(db_url)
    store = CampaignStore.create(sessions, parse_plan(plan_text(THREE)))

    def stored() -> tuple[int, list[str], int]:
        with sessions() as session:
            writes = session.scalar(select(Campaign.engine_writes))
            kinds = session.scalars(select(Event.kind).order_by(Event.id)).all()
            return writes, list(kinds), session.scalar(select(func.count(Observation.id)))

    store.trial_started(1)
    store.event("command", "info", "stop", 1)
    assert stored() == (0, [], 0)  # held
    store.observation(ObservationResult(1, 1, 1, 100.0, 0, 1, 10, 0, ""))
    assert stored() == (3, ["command"], 1)
    store.event("frame gap", "warning", "1 frame", 1, 1)
    store.series_completed(1, 1)
    assert stored() == (3, ["command"], 1)
    store.run_event("raw log", "info", "a run's event")  # after the held ones, in order
    assert stored() == (5, ["command", "frame gap", "raw log"], 1)
    store.event("command", "info", "start", 1)
    store.flush()
    assert stored() == (6, ["command", "frame gap", "raw log", "command"], 1)
    with sessions() as session:
        assert session.scalar(select(Trial.status).where(Trial.index == 1)) == "running"


class Sent:
    def __init__(self) -> None:
        self.commands: list = []

    def issue(self, command, now_ms: int) -> None:  # noqa: ANN001
        self.commands.append(command)


def test_status_resume_point_and_engine_agree(db_url: str) -> None:
    store = killed_after_trial_2(db_url)
    with store.sessions() as session:
        resume = first_incomplete_series(session, store.campaign_id)
        summary = campaign_summary(session, store.campaign_id)
    third = summary.trials[2]
    assert resume == ResumePoint(third.trial_id, 3, 1, None, 1)  # "next: trial 3"
    assert summary.resume == resume and summary.observations_stored == 12
    progress = store.progress()
    assert progress[2].completed and progress[2].series_done == {1, 2}
    assert not progress[3].completed
    sent = Sent()
    engine = Engine(parse_plan(plan_text(THREE)), store, sent, progress)
    assert engine.todo == []  # trial 3 is the only one taken up: trial 2 is not rocked again
    assert [c.kind for c in sent.commands] == ["stop"]  # trial 3 starts from still, series 1


def test_a_commands_event_is_stored_before_the_stand_gets_it(db_url: str) -> None:
    """Write-ahead: killed just after a command went out, the database still says it was sent."""
    store = killed_after_trial_2(db_url)
    seen: list[list[str]] = []

    class Reading:
        def issue(self, command, now_ms: int) -> None:  # noqa: ANN001
            with store.sessions() as session:  # another session: only what is committed
                found = select(Event.message).where(Event.kind == "command")
                seen.append(list(session.scalars(found).all()))

    Engine(parse_plan(plan_text(THREE)), store, Reading(), store.progress())
    assert seen == [["stop"]]


def test_resume_completes_the_acquired_trial_with_an_event(db_url: str) -> None:
    """(what a resume that restarts the stand does first: `run_live`)"""
    store = killed_after_trial_2(db_url)
    _, resumed = resume_store(store.sessions, store.campaign_id)
    resumed.complete_acquired()
    with store.sessions() as session:
        statuses = session.scalars(select(Trial.status).order_by(Trial.index)).all()
        events = session.scalars(select(Event).where(Event.kind == "resume")).all()
    assert statuses == ["completed", "completed", "pending"]
    completed = [e for e in events if "completed on resume" in e.message]
    assert len(completed) == 1 and "trial 2 completed on resume" in completed[0].message
    resume_store(store.sessions, store.campaign_id)[1].complete_acquired()  # nothing more
    with store.sessions() as session:
        events = session.scalars(select(Event).where(Event.kind == "resume")).all()
    assert sum("completed on resume" in e.message for e in events) == 1
    assert sum(e.message.startswith("resumed by process") for e in events) == 2


def stopped_in_trial_2(url: str, criterion: str) -> CampaignStore:
    """Trial 1 completed; trial 2's first series settled by `criterion` and 2 of its N = 3
    observations committed when the run stopped."""
    sessions = open_database(url)
    store = CampaignStore.create(sessions, parse_plan(plan_text(THREE)))
    for trial, stored in ((1, 3), (2, 2)):
        store.trial_started(trial)
        for j in (1, 2) if trial == 1 else (1,):
            store.series_settled(trial, j, 0, SettleOutcome(criterion, 600.0, 100.0, 0.002))
            for k in range(1, stored + 1):
                store.observation(ObservationResult(trial, j, k, 100.0, 0, 1, 10, 0, ""))
            if trial == 1:
                store.series_completed(trial, j)
    store.trial_completed(1, None)
    store.flush()  # (as the engine's call that wrote it ends)
    return store


def test_a_trial_stopped_in_a_compensated_series_is_redone(db_url: str) -> None:
    """Its observations were taken in the transient and the record that compensates them is
    gone: a resume that restarts the stand fails that attempt, keeps it, and acquires a new one."""
    store = stopped_in_trial_2(db_url, "compensated")
    _, resumed = resume_store(store.sessions, store.campaign_id)
    resumed.redo_uncompensated()
    resumed.complete_acquired()
    with store.sessions() as session:
        trials = session.execute(
            select(Trial.index, Trial.attempt, Trial.status, Trial.failure_reason).order_by(
                Trial.index, Trial.attempt
            )
        ).all()
        resume = first_incomplete_series(session, store.campaign_id)
        retry = session.scalars(select(Event.message).where(Event.kind == "retry")).one()
        kept = session.scalar(select(func.count(Observation.id)))
    assert [t[:3] for t in trials] == [
        (1, 1, "completed"),
        (2, 1, "failed"),
        (2, 2, "pending"),
        (3, 1, "pending"),
    ]
    assert trials[1].failure_reason.startswith("stopped in compensated series 1: its observ")
    assert retry.startswith("trial 2: attempt 2 supersedes attempt 1, which failed: stopped in")
    assert (
        kept == 8
        and resume is not None
        and (resume.trial_index, resume.j, resume.next_k) == (2, 1, 1)
    )
    resumed.trial_started(2)  # the engine's writes go to the new attempt
    resumed.observation(ObservationResult(2, 1, 1, 100.5, 0, 1, 10, 0, ""))
    with store.sessions() as session:
        attempt = session.scalars(
            select(Trial.attempt)
            .join(Trial.series)
            .join(Observation)
            .where(Observation.value_deg == 100.5)
        ).one()
    assert attempt == 2


def test_a_trial_stopped_in_a_bounded_series_continues(db_url: str) -> None:
    store = stopped_in_trial_2(db_url, "estimate")
    _, resumed = resume_store(store.sessions, store.campaign_id)
    resumed.redo_uncompensated()
    with store.sessions() as session:
        resume = first_incomplete_series(session, store.campaign_id)
        attempts = session.scalar(select(func.max(Trial.attempt)))
    assert attempts == 1 and (resume.trial_index, resume.j, resume.next_k) == (2, 1, 3)


def status_line(url: str) -> str:
    result = CliRunner().invoke(app, ["campaign", "status", "1", "--db", url])
    assert result.exit_code == 0, result.output
    return result.output.splitlines()[0]


HOLD = """
import sys, time
from gyrostand.db.lease import take_lease
from gyrostand.db.session import open_database
take_lease(open_database(sys.argv[1]), 1)
print("held", flush=True)
time.sleep(600)
"""


def test_the_lease_stops_a_second_process_and_dies_with_its_holder(db_url: str) -> None:
    store = killed_after_trial_2(db_url)
    store.set_status("running")
    url = str(store.sessions.kw["bind"].url)
    store.lease.release()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, url], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        assert held_elsewhere(store.sessions, 1)
        assert "campaign 1 (stand): running," in status_line(db_url)
        with pytest.raises(CampaignBusy, match="campaign 1 is being acquired by another process"):
            resume_store(store.sessions, 1)
    finally:
        holder.kill()  # kill -9: the operating system drops the lock
        holder.wait()
    # SQLite's file lock goes with the process; PostgreSQL's server drops the advisory lock
    # once it sees the client's socket close, a moment later
    deadline = time.monotonic() + 30
    while held_elsewhere(store.sessions, 1) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not held_elsewhere(store.sessions, 1)
    assert "campaign 1 (stand): interrupted (left running by a process that is gone" in (
        status_line(db_url)
    )
    _, resumed = resume_store(store.sessions, 1)
    with store.sessions() as session:
        kinds = session.scalars(select(Event.kind).order_by(Event.id)).all()
    assert kinds[-2:] == ["interrupted", "resume"]


def test_a_re_run_skips_the_committed_writes_and_checks_each_observation(db_url: str) -> None:
    """`CampaignStore.re_run`: the writes earlier runs committed are skipped in order, an
    observation re-derived differently is refused, and writes past them are stored."""
    store = killed_after_trial_2(db_url)
    committed = 2 + 2 * 2 * 3 + 2 + 1  # trials started, observations, series and trial completed
    again = CampaignStore(store.sessions, store.campaign_id)
    store.lease.release()
    assert again.re_run() == committed
    again.trial_started(1)
    first = ObservationResult(1, 1, 1, 100.0, 0, 1, 10, 0, "")
    again.observation(first)  # equal to the stored one: skipped
    with pytest.raises(ReRunMismatch, match="trial 1 series 1 observation 2"):
        again.observation(replace(first, k=2, value_deg=100.5))
    with store.sessions() as session:
        assert session.scalar(select(func.count(Observation.id))) == 12
