"""Query helpers: resume point, campaign summary, instrument reuse, known constants."""

import pytest
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.models import Event, Observation, Series
from gyrostand.db.queries import (
    CampaignNotFound,
    ResumePoint,
    campaign_constants,
    campaign_summary,
    first_incomplete_series,
    instrument_for,
    load_campaign,
)
from tests.db.conftest import make_campaign


def observe(series: Series, n: int) -> None:
    series.observations += [Observation(k=k, value_deg=0.5 * k) for k in range(1, n + 1)]


def test_resume_point_walks_trials_and_series(sessions: sessionmaker[Session]) -> None:
    with sessions.begin() as session:
        campaign = make_campaign(session, n_trials=3)
        first, second, third = campaign.trials
        observe(first.series[0], 5)  # N = 5 observations: done, even though still "observing"
        first.series[0].status = "observing"
        observe(first.series[1], 3)
        first.series[1].status = "observing"
        session.flush()
        ids = (campaign.id, first.id, first.series[1].id)
    with sessions() as session:
        assert first_incomplete_series(session, ids[0]) == ResumePoint(ids[1], 1, 2, ids[2], 4)

    with sessions.begin() as session:
        campaign = load_campaign(session, ids[0])
        first, second, third = campaign.trials
        observe(first.series[1], 0)
        first.series[1].observations += [Observation(k=k, value_deg=0.0) for k in (4, 5)]
        first.series[1].status = first.status = "completed"
        second.status, second.failure_reason = "failed", "stand refused: amplitude out of range"
        session.delete(third.series[1])  # the runner may create series lazily
        third.series[0].status = "completed"
        third_id = third.id
    with sessions() as session:
        assert first_incomplete_series(session, ids[0]) == ResumePoint(third_id, 3, 2, None, 1)

    with sessions.begin() as session:
        third = load_campaign(session, ids[0]).trials[2]
        third.status, third.failure_reason = "failed", "bus silent for 5 s"
    with sessions() as session:
        assert first_incomplete_series(session, ids[0]) is None
        with pytest.raises(CampaignNotFound):
            first_incomplete_series(session, 41)


def test_campaign_summary_counts(sessions: sessionmaker[Session]) -> None:
    with sessions.begin() as session:
        campaign = make_campaign(session, n_trials=2)
        observe(campaign.trials[0].series[0], 5)
        observe(campaign.trials[0].series[1], 2)
        campaign.status = "running"
        campaign.trials[1].status, campaign.trials[1].failure_reason = "failed", "stand timeout"
        campaign.events += [
            Event(kind="gap", severity="warning", message="2 frames lost"),
            Event(kind="gap", severity="warning", message="1 frame lost"),
            Event(kind="timeout", severity="error", message="no ack"),
        ]
        campaign_id = campaign.id
    with sessions() as session:
        summary = campaign_summary(session, campaign_id)
    assert summary.status == "running" and summary.instrument == "Kurs-4 #0001"
    assert [t.observations_by_j for t in summary.trials] == [{1: 5, 2: 2}, {1: 0, 2: 0}]
    assert summary.observations_stored == 7
    assert (summary.trials_completed, summary.trials_failed) == (0, 1)
    assert summary.trials[1].failure_reason == "stand timeout"
    assert summary.events_by_severity == {"info": 0, "warning": 2, "error": 1}
    assert summary.resume is not None and (summary.resume.j, summary.resume.next_k) == (2, 3)


def test_missing_campaign(sessions: sessionmaker[Session]) -> None:
    with sessions() as session:
        with pytest.raises(CampaignNotFound, match="no campaign 41"):
            load_campaign(session, 41)
        with pytest.raises(CampaignNotFound, match="no campaign 41"):
            campaign_summary(session, 41)


def test_instrument_reused_only_with_equal_constants(sessions: sessionmaker[Session]) -> None:
    with sessions.begin() as session:
        a = instrument_for(session, "Kurs-4", "7", {"lp_gcm2s2": 6.57e6, "h1_gcm2s": 1.55e8})
        session.flush()
        assert (
            instrument_for(session, "Kurs-4", "7", {"h1_gcm2s": 1.55e8, "lp_gcm2s2": 6.57e6}) is a
        )
        assert (
            instrument_for(session, "Kurs-4", "7", {"lp_gcm2s2": 6.6e6, "h1_gcm2s": 1.55e8})
            is not a
        )


def test_campaign_constants(sessions: sessionmaker[Session]) -> None:
    with sessions() as session:
        campaign = make_campaign(session)
        assert campaign_constants(campaign) == {
            "lp_gcm2s2": 6.57e6,
            "latitude_deg": 46.5,
            "earth_rate_rad_s": 7.3e-5,
            "gravity_cm_s2": 981.0,
        }
