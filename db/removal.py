"""Removing campaigns from a database (`gyrostand campaign remove`): in one transaction, each
campaign's rows go (the database's foreign keys cascade) and a `CampaignRemoval` row stays,
with the SHA-256 of its content and a record of what it was; its raw log files are kept, or
deleted once the removal is committed when no campaign left refers to them."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from gyrostand.db.lease import held_elsewhere
from gyrostand.db.merge import campaign_rows, content_sha256
from gyrostand.db.models import (
    PROCEDURES_RAW_LOG,
    Campaign,
    CampaignOrigin,
    CampaignRemoval,
    Instrument,
    ProcedureRun,
    RawLogSegment,
)
from gyrostand.db.queries import as_utc
from gyrostand.db.session import writer


class RemovalRefused(ValueError):
    """Nothing was removed (one line naming the campaign and why)."""


@dataclass(frozen=True)
class Removed:
    """A removed campaign: its id, the SHA-256 of its content, the id of its removal record,
    and its raw log files (deleted, or kept where they are)."""

    campaign_id: int
    content_sha256: str
    removal_id: int
    raw_logs: tuple[str, ...]


def _record(session: Session, campaign: Campaign) -> dict[str, Any]:
    """What the campaign was, for its removal record."""
    instrument = session.get_one(Instrument, campaign.instrument_id)
    origin = session.scalar(select(CampaignOrigin).where(CampaignOrigin.campaign_id == campaign.id))
    return {
        "instrument": {"model": instrument.model, "serial": instrument.serial},
        "status": campaign.status,
        "source": campaign.source,
        "operator": campaign.operator,
        "created_at": as_utc(campaign.created_at).isoformat(),
        "finished_at": None
        if campaign.finished_at is None
        else as_utc(campaign.finished_at).isoformat(),
        "plan_hash": campaign.plan_hash,
        "labels": {label.key: label.value for label in campaign.labels},
        "origin": None
        if origin is None
        else {
            "source_database": origin.source_database,
            "source_campaign_id": origin.source_campaign_id,
            "merged_from": origin.merged_from,
        },
        "raw_logs": [
            {"path": log.path, "sha256": log.sha256, "frames": log.frames}
            for log in campaign.raw_logs
        ]
        + [
            {"path": log["path"], "sha256": log.get("sha256"), "frames": log.get("frames")}
            for log in _procedures_log(session, campaign.id)
        ],
        "analysis_runs": len(campaign.analysis_runs),
    }


def _procedures_log(session: Session, campaign_id: int | None = None) -> list[dict[str, Any]]:
    """The procedures' raw logs recorded with the campaign's procedures (all campaigns' with
    None): a campaign stopped before its trials began has no raw log segment but this one."""
    query = select(ProcedureRun.results_json)
    if campaign_id is not None:
        query = query.where(ProcedureRun.campaign_id == campaign_id)
    return [r[PROCEDURES_RAW_LOG] for r in session.scalars(query) if PROCEDURES_RAW_LOG in r]


def remove_campaigns(
    sessions: sessionmaker[Session],
    campaign_ids: Sequence[int],
    *,
    removed_by: str,
    reason: str | None,
    delete_raw_logs: bool,
    software_version: str,
    files_of: Callable[[str], Sequence[Path]] = lambda log: (Path(log),),
) -> list[Removed]:
    """Remove the campaigns in one transaction (RemovalRefused, nothing removed: a campaign
    that is not there, or that a live process is acquiring), recording each removal; then,
    with `delete_raw_logs`, delete the files (`files_of` a raw log: it and the logs beside
    it) of their raw logs no remaining campaign refers to."""
    ids = list(dict.fromkeys(campaign_ids))
    removed: list[Removed] = []
    with writer(sessions).begin() as session:
        for campaign_id in ids:
            campaign = session.get(Campaign, campaign_id)
            if campaign is None:
                raise RemovalRefused(f"no campaign {campaign_id} in the database; nothing removed")
            if held_elsewhere(sessions, campaign_id):
                raise RemovalRefused(
                    f"campaign {campaign_id} is being acquired by a live process: stop it "
                    "first; nothing removed"
                )
            logs = tuple(log.path for log in campaign.raw_logs)
            logs += tuple(log["path"] for log in _procedures_log(session, campaign_id))
            record = CampaignRemoval(
                campaign_id=campaign_id,
                content_sha256=content_sha256(campaign_rows(session, campaign_id)),
                record=_record(session, campaign),
                removed_by=removed_by,
                reason=reason,
                raw_logs=("deleted" if delete_raw_logs else "kept") if logs else "none",
                software_version=software_version,
            )
            session.add(record)
            session.delete(campaign)
            session.flush()
            removed.append(Removed(campaign_id, record.content_sha256, record.id, logs))
        still_used = set(session.scalars(select(RawLogSegment.path)))
        still_used.update(log["path"] for log in _procedures_log(session))
    if delete_raw_logs:
        for log in {p for r in removed for p in r.raw_logs} - still_used:
            for path in files_of(log):
                path.unlink(missing_ok=True)
    return removed


def newest_instrument(sessions: sessionmaker[Session]) -> int:
    """The highest instrument id so far (0: none), for `discard_campaign`."""
    with sessions() as session:
        return session.scalar(select(func.max(Instrument.id))) or 0


def discard_campaign(sessions: sessionmaker[Session], campaign_id: int, instruments: int) -> None:
    """Take out a campaign this process has just made and that failed before anyone saw it
    (a replay stopped part-way): its rows go (foreign keys cascade) with no removal record,
    and so does its instrument when it is newer than `instruments` (`newest_instrument`
    before the campaign was made) and no campaign refers to it: the database is as it was."""
    with writer(sessions).begin() as session:
        campaign = session.get(Campaign, campaign_id)
        if campaign is None:
            return
        instrument = campaign.instrument_id
        session.delete(campaign)
        session.flush()
        used = session.scalar(select(Campaign.id).where(Campaign.instrument_id == instrument))
        if instrument > instruments and used is None:
            session.delete(session.get_one(Instrument, instrument))
