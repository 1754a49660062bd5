"""Merging a stand's database into the lab database (`gyrostand db merge`).

A campaign is copied whole, table by table (`COPIED`, parents first, every foreign key mapped to
the new ids), onto the lab's instrument of the same model, serial and constants
(`queries.instrument_for`), and gets a `CampaignOrigin`: the database it was recorded in
(`database_identity`; a campaign that was itself merged keeps its first origin), its id there and
the SHA-256 of its content (`content_sha256`: every copied row without its ids, the analysis runs
aside: they are derived, and the lab may add its own).

Raw CAN logs are files, not rows: with `raw_logs` (the CLI's `--raw-dir`) each verified segment
(its SHA-256 recorded) is copied into the lab's folder under a content-addressed name, and the
lab's record names the copy; the copying comes last, before the commit, and a copy that fails
merges nothing. A file's path is where it is kept, not what it holds: no part of the content.

Merging is idempotent: a campaign whose origin is in the lab with the same content is "already
merged"; so is one of the lab's own campaigns coming back through another database, which is
skipped when its content differs there (the lab keeps its own). With other content, the lab's
copy is replaced (keeping its id) only while it is not completed and nothing was done to it in
the lab (its content is still the merged one, no analysis run since); otherwise that is a
conflict, and nothing at all is merged. Campaigns being acquired (lease held) or left running
are skipped. All of it is one transaction of the lab database.
"""

from __future__ import annotations

import hashlib
import json
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Any, Protocol

from sqlalchemy import Row, RowMapping, Table, delete, func, insert, select, text
from sqlalchemy.orm import Session, sessionmaker

from gyrostand import SOFTWARE_VERSION
from gyrostand.db.lease import held_elsewhere
from gyrostand.db.models import (
    AnalysisRun,
    Base,
    Campaign,
    CampaignLabel,
    CampaignOrigin,
    CampaignRemoval,
    Event,
    Instrument,
    MeasuredMotionRow,
    Observation,
    ProcedureRun,
    RawLogSegment,
    Series,
    SignOff,
    Trial,
)
from gyrostand.db.queries import as_utc, instrument_for
from gyrostand.db.session import writer

COPIED = (
    CampaignLabel,
    Trial,
    Series,
    Observation,
    MeasuredMotionRow,
    Event,
    RawLogSegment,
    SignOff,
    AnalysisRun,
    ProcedureRun,
)
"""The tables of a campaign's rows, besides the campaign row: each has one non-nullable foreign
key to the campaign or to another of them."""
DERIVED = (AnalysisRun,)  # copied, but no part of the content
MATCHED = (Instrument,)  # the lab's own row of the same model, serial and constants
PER_DATABASE = (CampaignOrigin, CampaignRemoval)  # never copied
MERGE_LOCK = 0x67796D7267  # PostgreSQL advisory lock key of merges ("gymrg")
LOCATION = {"raw_log_segment": "path"}  # where a file is kept: no part of the content
LATER = ("measured_motion",)  # tables added since content hashes were first recorded: in the
# content only when they have rows, so a campaign merged before keeps its hash
IDENTITIES = uuid.UUID("5a0c8f1e-9b7d-4c1e-8f2a-67796d657267")  # namespace of database_identity

Values = dict[str, Any]  # a row: column -> value


class MergeRefused(ValueError):
    """Nothing was merged: a conflict, or a source that is the lab itself (one line)."""


RawLogCopy = tuple[str, str, str]  # the stand's path, the lab's path, the SHA-256 recorded


class RawLogs(Protocol):
    """Where the lab keeps merged raw logs, and the copying (files are the caller's business)."""

    def lab_path(self, origin: str, path: str, sha256: str) -> str:
        """The lab's path of the stand's verified raw log `path` of a campaign from `origin`."""
        ...

    def copy(self, files: Sequence[RawLogCopy]) -> None:
        """Copy the files, each checked against its SHA-256; MergeRefused (and none left
        copied) when one cannot be."""
        ...


@dataclass(frozen=True)
class CampaignRows:
    """A campaign's rows, table by table (the campaign's first, parents before children), each
    by id, with wall times as aware UTC; and its instrument."""

    instrument: Values
    tables: dict[str, list[Values]]

    @property
    def campaign(self) -> Values:
        return self.tables["campaign"][0]


def _tables() -> list[Table]:
    """The campaign's tables, parents before children."""
    names = {"campaign"} | {model.__tablename__ for model in COPIED}
    return [t for t in Base.metadata.sorted_tables if t.name in names]


def _references(table: Table) -> dict[str, str]:
    """The table's foreign key columns and the tables they refer to."""
    return {fk.parent.name: fk.column.table.name for fk in table.foreign_keys}


def _plain(row: RowMapping) -> Values:
    return {k: as_utc(v) if isinstance(v, datetime) else v for k, v in row.items()}


def campaign_rows(session: Session, campaign_id: int) -> CampaignRows:
    """Every row of the campaign in the `COPIED` tables (and its instrument)."""
    tables: dict[str, list[Values]] = {}
    for table in _tables():
        if table.name == "campaign":
            where = table.c.id == campaign_id
        else:
            (key,) = (
                fk
                for fk in table.foreign_keys
                if not fk.parent.nullable and fk.column.table.name in tables
            )
            where = key.parent.in_([row["id"] for row in tables[key.column.table.name]])
        rows = session.execute(select(table).where(where).order_by(table.c.id)).mappings()
        tables[table.name] = [_plain(row) for row in rows]
    instrument = Instrument.__table__
    found = session.execute(
        select(instrument).where(instrument.c.id == tables["campaign"][0]["instrument_id"])
    )
    return CampaignRows(_plain(found.mappings().one()), tables)


def _json(value: Any) -> str:
    if isinstance(value, datetime):
        return value.isoformat()
    raise TypeError(f"{type(value).__name__} is not JSON")


def content_sha256(rows: CampaignRows) -> str:
    """SHA-256 of the campaign's content: its instrument and rows as canonical JSON, ids left out
    (a foreign key as the position of its row among the campaign's rows of that table), the
    `DERIVED` tables and the files' `LOCATION` left out. A copy has the same content as its
    original, wherever its raw logs are kept."""
    position = {
        name: {row["id"]: i for i, row in enumerate(rs)} for name, rs in rows.tables.items()
    }
    document: dict[str, Any] = {
        "instrument": {k: v for k, v in rows.instrument.items() if k != "id"}
    }
    derived = {model.__tablename__ for model in DERIVED}
    for table in _tables():
        if table.name in derived or (table.name in LATER and not rows.tables[table.name]):
            continue
        keys = _references(table)
        document[table.name] = [
            {
                name: value if name not in keys or value is None else position[keys[name]][value]
                for name, value in row.items()
                if name not in ("id", LOCATION.get(table.name))
                and (name not in keys or keys[name] in position)
            }
            for row in rows.tables[table.name]
        ]
    text_ = json.dumps(document, sort_keys=True, separators=(",", ":"), default=_json)
    return hashlib.sha256(text_.encode()).hexdigest()


def copy_campaign(session: Session, rows: CampaignRows, campaign_id: int | None = None) -> int:
    """Insert the campaign's rows (as `campaign_id`, or with new ids) on the matching
    instrument; the campaign's id."""
    instrument = instrument_for(
        session,
        rows.instrument["model"],
        rows.instrument["serial"],
        rows.instrument["constants_json"],
    )
    session.flush()
    new_ids: dict[str, dict[int, int]] = {"instrument": {rows.instrument["id"]: instrument.id}}
    for table in _tables():
        old = rows.tables[table.name]
        if not old:
            continue
        keys = _references(table)
        values = [
            {
                name: new_ids[keys[name]][value] if name in keys and value is not None else value
                for name, value in row.items()
                if name != "id"
            }
            for row in old
        ]
        if table.name == "campaign" and campaign_id is not None:
            values[0]["id"] = campaign_id
        inserted = session.execute(
            insert(table).returning(table.c.id, sort_by_parameter_order=True), values
        ).scalars()
        new_ids[table.name] = dict(zip((row["id"] for row in old), inserted, strict=True))
    return new_ids["campaign"][rows.campaign["id"]]


def database_identity(session: Session) -> str | None:
    """The identity of the database (None: it recorded no campaign of its own): a UUID derived
    from the first campaign recorded in it (not merged into it), from its creation time and plan
    hash. Copies of the file keep it; nothing random is stored, so two runs of one seed still
    make equal databases (tests/acquisition/test_virtual_time.py)."""
    first = session.execute(
        select(Campaign.created_at, Campaign.plan_hash)
        .where(~select(CampaignOrigin.id).where(CampaignOrigin.campaign_id == Campaign.id).exists())
        .order_by(Campaign.id)
        .limit(1)
    ).first()
    if first is None:
        return None
    return str(uuid.uuid5(IDENTITIES, f"{as_utc(first.created_at).isoformat()} {first.plan_hash}"))


@dataclass(frozen=True)
class CampaignMerge:
    """What the merge did (or, dry, would do) with one campaign of the stand: `outcome` merged,
    replaced (an earlier, incomplete copy), identical (already merged) or skipped (`reason`)."""

    source_id: int
    outcome: str
    lab_id: int | None
    stand: str | None  # the campaign's label stand, if any
    reason: str = ""
    raw_logs: int = 0  # raw log files copied to the lab (or, dry, to be copied)


@dataclass(frozen=True)
class MergeResult:
    """The stand database's identity and what became of each of its campaigns."""

    source_database: str | None
    campaigns: tuple[CampaignMerge, ...]

    def count(self, outcome: str) -> int:
        return sum(c.outcome == outcome for c in self.campaigns)


def merge_database(
    stand: sessionmaker[Session],
    lab: sessionmaker[Session],
    merged_from: str,
    *,
    dry_run: bool,
    raw_logs: RawLogs | None = None,
) -> MergeResult:
    """Merge every campaign of the `stand` database into the `lab` database in one transaction
    (a `dry_run` reads only: an insert would draw ids from PostgreSQL's sequences, which no
    rollback gives back), their raw logs copied by `raw_logs` if given; MergeRefused (nothing
    merged) on a conflict."""
    with stand() as source, writer(lab)() as target:
        if target.get_bind().dialect.name == "postgresql":  # one merge at a time
            target.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": MERGE_LOCK})
        identity, lab_identity = database_identity(source), database_identity(target)
        if identity is not None and identity == lab_identity:
            raise MergeRefused(f"{merged_from} is the lab database itself (or a copy of it)")
        merger = _Merger(
            stand, source, target, identity, lab_identity, merged_from, raw_logs, dry_run
        )
        ids = source.scalars(select(Campaign.id).order_by(Campaign.id)).all()
        done = tuple(merger.merge(i) for i in ids)
        if dry_run:
            target.rollback()
        else:
            if raw_logs is not None and merger.files:
                raw_logs.copy(merger.files)
            target.commit()
    return MergeResult(identity, done)


@dataclass(frozen=True)
class _Merger:
    stand: sessionmaker[Session]
    source: Session
    target: Session
    identity: str | None
    lab_identity: str | None
    merged_from: str
    raw_logs: RawLogs | None
    dry_run: bool
    files: list[RawLogCopy] = field(default_factory=list)  # to copy before the commit

    def merge(self, campaign_id: int) -> CampaignMerge:
        label = self.source.scalar(
            select(CampaignLabel.value).where(
                CampaignLabel.campaign_id == campaign_id, CampaignLabel.key == "stand"
            )
        )
        status = self.source.execute(
            select(Campaign.status).where(Campaign.id == campaign_id)
        ).scalar_one()
        why = _busy(self.stand, campaign_id, status)
        if why:
            return CampaignMerge(campaign_id, "skipped", None, label, why)
        rows = campaign_rows(self.source, campaign_id)
        digest = content_sha256(rows)
        origin = self._origin(campaign_id)
        if origin[0] == self.lab_identity and self.target.get(Campaign, origin[1]) is not None:
            return self._own(campaign_id, label, digest, origin[1])
        earlier = self.target.execute(
            select(
                CampaignOrigin.campaign_id, CampaignOrigin.content_sha256, CampaignOrigin.merged_at
            ).where(
                CampaignOrigin.source_database == origin[0],
                CampaignOrigin.source_campaign_id == origin[1],
            )
        ).first()
        if earlier is not None and earlier.content_sha256 == digest:
            return CampaignMerge(campaign_id, "identical", earlier.campaign_id, label)
        if earlier is not None:
            self._check_replaceable(campaign_id, rows, earlier)
        copied = len(self.files)
        rows = self._relocated(rows, origin[0])
        if self.dry_run:  # what the merge would do, known now: nothing is written
            lab_id = None if earlier is None else earlier.campaign_id
            outcome = "merged" if earlier is None else "replaced"
            return CampaignMerge(
                campaign_id, outcome, lab_id, label, raw_logs=len(self.files) - copied
            )
        if earlier is None:
            lab_id = copy_campaign(self.target, rows)
            outcome = "merged"
        else:
            self.target.execute(
                delete(Campaign.__table__).where(Campaign.id == earlier.campaign_id)
            )
            lab_id = copy_campaign(self.target, rows, earlier.campaign_id)
            outcome = "replaced"
        self.target.add(
            CampaignOrigin(
                campaign_id=lab_id,
                source_database=origin[0],
                source_campaign_id=origin[1],
                content_sha256=digest,
                merged_from=self.merged_from,
                software_version=SOFTWARE_VERSION,
            )
        )
        self.target.flush()
        return CampaignMerge(campaign_id, outcome, lab_id, label, raw_logs=len(self.files) - copied)

    def _own(self, campaign_id: int, label: str | None, digest: str, lab_id: int) -> CampaignMerge:
        """The lab's own campaign `lab_id`, back through another database: nothing to copy."""
        if content_sha256(campaign_rows(self.target, lab_id)) == digest:
            return CampaignMerge(campaign_id, "identical", lab_id, label)
        why = f"lab campaign {lab_id} itself, changed since it left the lab (the lab keeps its own)"
        return CampaignMerge(campaign_id, "skipped", lab_id, label, why)

    def _relocated(self, rows: CampaignRows, origin: str) -> CampaignRows:
        """The rows with each verified raw log at its lab path (noted in `files` to copy)."""
        if self.raw_logs is None:
            return rows
        segments = []
        for row in rows.tables["raw_log_segment"]:
            if row["sha256"] is not None:
                path = self.raw_logs.lab_path(origin, row["path"], row["sha256"])
                self.files.append((row["path"], path, row["sha256"]))
                row = {**row, "path": path}
            segments.append(row)
        return replace(rows, tables={**rows.tables, "raw_log_segment": segments})

    def _origin(self, campaign_id: int) -> tuple[str, int]:
        """Where the campaign was recorded: its own origin if it was merged into the stand
        database, else that database."""
        own = self.source.execute(
            select(CampaignOrigin.source_database, CampaignOrigin.source_campaign_id).where(
                CampaignOrigin.campaign_id == campaign_id
            )
        ).first()
        if own is not None:
            return own[0], own[1]
        assert self.identity is not None  # a campaign of its own gives the database one
        return self.identity, campaign_id

    def _check_replaceable(self, campaign_id: int, rows: CampaignRows, earlier: Row[Any]) -> None:
        """MergeRefused unless the lab's earlier copy may be replaced (see the module doc)."""
        lab_id = earlier.campaign_id
        copy = campaign_rows(self.target, lab_id)
        what = f"campaign {campaign_id} of {self.merged_from} (merged as lab campaign {lab_id})"
        if copy.campaign["created_at"] != rows.campaign["created_at"]:
            problem = (
                "is another campaign than the one merged with its origin: the stand databases "
                "share one identity (was one copied from the other before use?)"
            )
        elif copy.campaign["status"] == "completed":
            problem = "has changed since it was merged, and the lab's copy is completed"
        elif content_sha256(copy) != earlier.content_sha256:
            problem = "has changed since it was merged, and so has the lab's copy"
        elif self.target.scalar(
            select(func.count())
            .select_from(AnalysisRun)
            .where(AnalysisRun.campaign_id == lab_id, AnalysisRun.created_at >= earlier.merged_at)
        ):
            problem = "has changed since it was merged, and the lab has analysed its copy"
        else:
            return
        raise MergeRefused(f"conflict: {what} {problem}; nothing merged")


def _busy(stand: sessionmaker[Session], campaign_id: int, status: str) -> str:
    """Why the campaign cannot be merged now ('' when it can)."""
    if held_elsewhere(stand, campaign_id):
        return "being acquired (a live process holds its lease)"
    if status == "running":
        return "left running by a process that is gone: resume or stop it on the stand first"
    return ""
