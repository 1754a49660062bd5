"""Constraints make bad states impossible: each bad row is rejected by the database itself, on
SQLite and on PostgreSQL (`db_url`), naming the same constraint."""

from collections.abc import Callable

import pytest
from sqlalchemy import func, select, text
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.models import AnalysisRun, Campaign, Event, Observation, Series, Trial
from gyrostand.db.session import open_database
from tests.db.conftest import make_campaign


@pytest.fixture
def sessions(db_url: str) -> sessionmaker[Session]:
    """A fresh database on each back end (this module's, not tests/db/conftest.py's SQLite)."""
    return open_database(db_url)


def violated(error: IntegrityError) -> str:
    """The constraint an IntegrityError names, alike on both back ends: the constraint's name
    (SQLite gives a unique constraint's columns: named here as `db.models.NAMING` names it),
    or "foreign key"."""
    diag = getattr(error.orig, "diag", None)  # psycopg
    if diag is not None:
        return "foreign key" if error.orig.sqlstate == "23503" else diag.constraint_name
    message = str(error.orig)
    if message.startswith("UNIQUE constraint failed: "):
        columns = message.removeprefix("UNIQUE constraint failed: ").split(", ")
        table = columns[0].split(".")[0]
        return f"uq_{table}_" + "_".join(c.split(".")[1] for c in columns)
    if message == "FOREIGN KEY constraint failed":
        return "foreign key"
    return message.removeprefix("CHECK constraint failed: ")


def rejected(sessions: sessionmaker[Session], spoil: Callable[[Session, Campaign], None]) -> str:
    """Apply `spoil` to a fresh valid campaign; return the constraint it violates (an
    IntegrityError must be raised)."""
    with sessions() as session, pytest.raises(IntegrityError) as caught:
        campaign = make_campaign(session)
        spoil(session, campaign)
        session.flush()
    return violated(caught.value)


def test_valid_campaign_is_stored(sessions: sessionmaker[Session]) -> None:
    with sessions.begin() as session:
        campaign = make_campaign(session, n_trials=2)
        campaign.trials[0].series[0].observations = [
            Observation(k=k, value_deg=0.1 * k) for k in (1, 2)
        ]
    with sessions() as session:
        assert session.scalar(select(func.count()).select_from(Observation)) == 2
        assert session.scalar(select(func.count()).select_from(Series)) == 4
        stored = session.scalars(select(Campaign)).one()
        assert [t.index for t in stored.trials] == [1, 2]
        assert stored.status == "planned" and stored.source == "stand"
        assert stored.earth_rate_rad_s == 7.3e-5 and stored.gravity_cm_s2 == 981.0


def add_observation(k: int) -> Callable[[Session, Campaign], None]:
    def spoil(session: Session, campaign: Campaign) -> None:
        campaign.trials[0].series[0].observations.append(Observation(k=k, value_deg=1.0))

    return spoil


@pytest.mark.parametrize(
    ("spoil", "constraint"),
    [
        (lambda s, c: setattr(c, "status", "done"), "ck_campaign_status"),
        (lambda s, c: setattr(c, "source", "guess"), "ck_campaign_source"),
        (lambda s, c: setattr(c, "n_obs", 1), "ck_campaign_n_obs"),
        (lambda s, c: setattr(c, "latitude_deg", 90.0), "ck_campaign_latitude"),
        (lambda s, c: setattr(c, "plan_hash", "abc"), "ck_campaign_plan_hash"),
        (lambda s, c: setattr(c.trials[0], "role", "both"), "ck_trial_role"),
        (lambda s, c: setattr(c.trials[0], "status", "done"), "ck_trial_status"),
        (lambda s, c: setattr(c.trials[0], "status", "failed"), "ck_trial_failed_has_reason"),
        (lambda s, c: setattr(c.trials[0], "index", 0), "ck_trial_index"),
        (lambda s, c: setattr(c.trials[0], "attempt", 0), "ck_trial_attempt"),
        (lambda s, c: setattr(c.trials[0], "cmd_direction_deg", 360.0), "ck_trial_cmd_direction"),
        (lambda s, c: setattr(c.trials[0], "cmd_period_s", 0.0), "ck_trial_cmd_period"),
        (lambda s, c: setattr(c.trials[0].series[0], "j", 3), "ck_series_j"),
        (lambda s, c: setattr(c.trials[0].series[0], "status", "x"), "ck_series_status"),
        (lambda s, c: setattr(c.trials[0].series[0], "summary_n", 1), "ck_series_summary_n"),
        (add_observation(0), "ck_observation_k"),
    ],
)
def test_check_constraints(
    sessions: sessionmaker[Session], spoil: Callable[[Session, Campaign], None], constraint: str
) -> None:
    assert rejected(sessions, spoil) == constraint


def test_unique_series_k(sessions: sessionmaker[Session]) -> None:
    def twice(session: Session, campaign: Campaign) -> None:
        add_observation(3)(session, campaign)
        session.flush()
        add_observation(3)(session, campaign)

    assert rejected(sessions, twice) == "uq_observation_series_id_k"


def test_unique_trial_j_and_campaign_index(sessions: sessionmaker[Session]) -> None:
    message = rejected(sessions, lambda s, c: c.trials[0].series.append(Series(j=1)))
    assert message == "uq_series_trial_id_j"

    def same_index(session: Session, campaign: Campaign) -> None:
        campaign.trials.append(
            Trial(index=1, role="fit", cmd_direction_deg=0, cmd_amplitude_cm=1, cmd_period_s=1)
        )

    assert rejected(sessions, same_index) == "uq_trial_campaign_id_index_attempt"


def test_foreign_keys_are_enforced(sessions: sessionmaker[Session]) -> None:
    def orphan(session: Session, campaign: Campaign) -> None:
        session.add(Observation(series_id=999_999, k=1, value_deg=0.0))

    assert rejected(sessions, orphan) == "foreign key"
    with sessions() as session, pytest.raises(IntegrityError):
        session.execute(
            text("INSERT INTO series (trial_id, j, status) VALUES (424242, 1, 'pending')")
        )


def test_event_and_analysis_run_checks(sessions: sessionmaker[Session]) -> None:
    def bad_event(session: Session, campaign: Campaign) -> None:
        campaign.events.append(Event(kind="bus", severity="fatal", message="x"))

    assert rejected(sessions, bad_event) == "ck_event_severity"

    def bad_run(session: Session, campaign: Campaign) -> None:
        campaign.analysis_runs.append(
            AnalysisRun(inputs_hash="short", results_json={}, software_version="t")
        )

    assert rejected(sessions, bad_run) == "ck_analysis_run_inputs_hash"


def test_deleting_a_campaign_cascades_in_the_database(sessions: sessionmaker[Session]) -> None:
    with sessions.begin() as session:
        campaign = make_campaign(session)
        add_observation(1)(session, campaign)
        campaign.events.append(Event(kind="note", severity="info", message="m"))
    with sessions.begin() as session:  # plain SQL: the FK's ON DELETE CASCADE does the work
        session.execute(text("DELETE FROM campaign"))
    with sessions() as session:
        for table in ("trial", "series", "observation", "event"):
            assert session.execute(text(f"SELECT count(*) FROM {table}")).scalar() == 0
