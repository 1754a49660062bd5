"""Trial attempts: which attempt is trial i (the latest), and migration 0004, which keeps every
row both ways and refuses to downgrade while a trial has more than one attempt."""

import sqlite3
from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import create_engine
from sqlalchemy.orm import Session

from gyrostand.db.models import Campaign, Event, Observation, Trial
from gyrostand.db.queries import (
    EarlierAttempt,
    ResumePoint,
    campaign_summary,
    current_trials,
    first_incomplete_series,
    load_campaign,
    trial_progress,
)
from gyrostand.db.session import alembic_config, open_database, sqlite_url
from tests.db.conftest import make_campaign

TABLES = ("instrument", "campaign", "trial", "series", "observation", "event")
PREVIOUS = "0003"


def observed(session: Session, n_trials: int) -> Campaign:
    """A campaign whose trials each hold 3 observations per series and an event."""
    campaign = make_campaign(session, n_trials=n_trials)
    for trial in campaign.trials:
        for s in trial.series:
            s.observations = [Observation(k=k, value_deg=0.1 * k + s.j) for k in (1, 2, 3)]
        session.add(Event(campaign=campaign, trial_id=trial.id, kind="command", severity="info",
                          message=f"trial {trial.index}"))  # fmt: skip
    session.flush()
    return campaign


def retried(session: Session, campaign: Campaign, index: int) -> Trial:
    """Trial `index` failed, and a pending second attempt of it."""
    first = next(t for t in campaign.trials if t.index == index)
    first.status, first.failure_reason = "failed", "bus silence"
    second = Trial(campaign=campaign, index=index, attempt=2, role=first.role,
                   cmd_direction_deg=332, cmd_amplitude_cm=24, cmd_period_s=8)  # fmt: skip
    session.add(second)
    session.flush()
    return second


def state(db: Path) -> tuple[list[str], dict[str, list[tuple]]]:
    """The schema version and every row of the data tables (the trial's own columns by name,
    so that they compare across the schemas)."""
    with sqlite3.connect(db) as conn:
        version = [r[0] for r in conn.execute("SELECT version_num FROM alembic_version")]
        rows = {t: sorted(conn.execute(f"SELECT * FROM {t}")) for t in TABLES if t != "trial"}
        rows["trial"] = sorted(
            conn.execute('SELECT id, campaign_id, "index", role, status, failure_reason FROM trial')
        )
    return version, rows


def downgrade(db: Path, revision: str) -> None:
    engine = create_engine(sqlite_url(db))
    config = alembic_config()
    try:
        with engine.begin() as connection:
            config.attributes["connection"] = connection
            command.downgrade(config, revision)
    finally:
        engine.dispose()


def test_the_latest_attempt_is_the_trial(db_path: Path) -> None:
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        campaign = observed(session, n_trials=2)
        campaign.trials[0].status = "completed"
        second = retried(session, campaign, 2)
        ids = campaign.id, campaign.trials[0].id, second.id
    with sessions() as session:
        progress = trial_progress(session, ids[0])
        assert [(t.trial_id, t.index, t.attempt, t.status) for t in progress] == [
            (ids[1], 1, 1, "completed"),
            (ids[2], 2, 2, "pending"),
        ]
        assert progress[0].observations_by_j == {1: 3, 2: 3} and progress[0].earlier == ()
        assert progress[1].observations_by_j == {}
        assert progress[1].earlier == (EarlierAttempt(1, "failed", "bus silence"),)
        assert first_incomplete_series(session, ids[0]) == ResumePoint(ids[2], 2, 1, None, 1)
        summary = campaign_summary(session, ids[0])
        assert (summary.trials_completed, summary.trials_failed) == (1, 0)
        assert summary.observations_stored == 6  # the failed attempt's 6 are its own
        loaded = load_campaign(session, ids[0])
        assert [(t.index, t.attempt) for t in loaded.trials] == [(1, 1), (2, 1), (2, 2)]
        assert [t.id for t in current_trials(reversed(loaded.trials))] == [ids[1], ids[2]]


def test_migration_0004_round_trip_keeps_every_row(db_path: Path) -> None:
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        observed(session, n_trials=2)
    sessions.kw["bind"].dispose()
    downgrade(db_path, "0004")  # later migrations' columns aside
    version, rows = state(db_path)
    assert version == ["0004"] and len(rows["observation"]) == 12 and len(rows["event"]) == 2

    downgrade(db_path, PREVIOUS)
    assert state(db_path) == ([PREVIOUS], rows)
    with sqlite3.connect(db_path) as conn:
        assert "attempt" not in {r[1] for r in conn.execute("PRAGMA table_info(trial)")}
        with pytest.raises(sqlite3.IntegrityError, match="trial.campaign_id, trial.index"):
            conn.execute(
                'INSERT INTO trial (campaign_id, "index", role, cmd_direction_deg,'
                " cmd_amplitude_cm, cmd_period_s, status) VALUES (1, 1, 'fit', 0, 1, 1, 'pending')"
            )

    open_database(sqlite_url(db_path)).kw["bind"].dispose()  # upgrades to the head
    downgrade(db_path, "0004")
    assert state(db_path) == (["0004"], rows)
    with sqlite3.connect(db_path) as conn:
        assert conn.execute("SELECT attempt FROM trial").fetchall() == [(1,), (1,)]


def test_downgrade_refuses_while_a_trial_has_two_attempts(db_path: Path) -> None:
    sessions = open_database(sqlite_url(db_path))
    with sessions.begin() as session:
        retried(session, observed(session, n_trials=2), 1)
    sessions.kw["bind"].dispose()
    before = state(db_path)
    with pytest.raises(RuntimeError) as refused:
        downgrade(db_path, PREVIOUS)
    assert str(refused.value) == (
        "cannot downgrade below schema 0004: retried trials have more than one attempt "
        "(campaign 1 trial 1: 2 attempts), and schema 0003 holds one per trial"
    )
    assert state(db_path) == before
