"""Retrying failed trials. A retry of trial i adds a new attempt beside the failed one: a Trial
row with the same index and plan values, the next attempt number and status "pending", and a
"retry" event naming the attempt it supersedes and why that one failed. The failed attempt is
left as it was, with its series, observations and events. The latest attempt is trial i for
everything else (`db.queries.latest_attempt`), so acquiring the new attempts is a resume."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.lease import take_lease
from gyrostand.db.models import Event, Trial
from gyrostand.db.queries import latest_attempt, stand_campaign
from gyrostand.db.session import writer


class RetryRefused(ValueError):
    """A trial that cannot be retried (no such trial, or not failed); one line naming why."""


@dataclass(frozen=True)
class RetriedTrial:
    """Trial `index` has the new attempt `attempt`, superseding one that failed for `reason`."""

    index: int
    attempt: int
    reason: str


def new_attempt(session: Session, failed: Trial) -> Trial:
    """Add (and flush) the next attempt of the failed trial `failed`, pending with the same plan
    values, and the "retry" event naming the attempt it supersedes and why that one failed."""
    attempt = Trial(
        campaign_id=failed.campaign_id,
        index=failed.index,
        attempt=failed.attempt + 1,
        role=failed.role,
        cmd_direction_deg=failed.cmd_direction_deg,
        cmd_amplitude_cm=failed.cmd_amplitude_cm,
        cmd_period_s=failed.cmd_period_s,
        status="pending",
    )
    session.add(attempt)
    session.flush()
    reason = failed.failure_reason or ""
    session.add(
        Event(
            campaign_id=failed.campaign_id,
            trial_id=attempt.id,
            kind="retry",
            severity="info",
            message=f"trial {failed.index}: attempt {attempt.attempt} supersedes attempt "
            f"{failed.attempt}, which failed: {reason}",
        )
    )
    return attempt


def retry_trials(
    sessions: sessionmaker[Session], campaign_id: int, indices: Sequence[int] | None
) -> tuple[RetriedTrial, ...]:
    """Add a new attempt of each trial in `indices` (None: of every trial whose latest attempt
    failed), holding the campaign's lease, which this process keeps for the acquisition that
    follows. Refused, with nothing written: CampaignNotFound, NotOnTheStand (db.queries),
    CampaignBusy (another process holds the lease), RetryRefused (no such trial, or its latest
    attempt did not fail)."""
    with sessions() as session:
        stand_campaign(session, campaign_id)
    take_lease(sessions, campaign_id)
    with writer(sessions).begin() as session:  # under the lease: nobody acquires meanwhile
        campaign = stand_campaign(session, campaign_id)
        latest = {
            t.index: t
            for t in session.scalars(
                select(Trial).where(Trial.campaign_id == campaign_id, latest_attempt())
            )
        }
        wanted = sorted(
            {i for i, t in latest.items() if t.status == "failed"}
            if indices is None
            else set(indices)
        )
        for index in wanted:
            trial = latest.get(index)
            if trial is None:
                raise RetryRefused(
                    f"campaign {campaign_id} has no trial {index} (its trials are 1 to "
                    f"{max(latest, default=0)})"
                )
            if trial.status != "failed":
                raise RetryRefused(
                    f"trial {index} is {trial.status}: only a failed trial can be retried"
                )
        retried = []
        for index in wanted:
            failed = latest[index]
            attempt = new_attempt(session, failed)
            retried.append(RetriedTrial(index, attempt.attempt, failed.failure_reason or ""))
        if retried and campaign.status == "completed":
            campaign.status = "paused"  # it has trials to acquire again
    return tuple(retried)
