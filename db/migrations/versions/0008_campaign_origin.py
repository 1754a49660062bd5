"""Merging stand databases into a lab database (`gyrostand db merge`): `database_identity` holds
the database's one UUID, `campaign_origin` where a merged campaign comes from (that UUID, its id
there, the SHA-256 of its content, from which file, when, by which software).

The UUID of a database that already holds campaigns is derived from its first campaign (its
created_at and plan hash), so two copies of one stand file upgraded apart still name the same
database; an empty database gets a random one. The downgrade refuses while any campaign is
merged (schema 0007 cannot hold their origin).

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-24 10:00:00
"""

import uuid
from collections.abc import Sequence
from datetime import UTC, datetime

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | Sequence[str] | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

NAMESPACE = uuid.UUID("5a0c8f1e-9b7d-4c1e-8f2a-67796d657267")  # gyrostand database identities


def _identity(bind: sa.Connection) -> str:
    """The UUID of the database: from its first campaign, else random."""
    campaign = sa.table(
        "campaign",
        sa.column("id", sa.Integer),
        sa.column("created_at", sa.DateTime(timezone=True)),
        sa.column("plan_hash", sa.String),
    )
    first = bind.execute(
        sa.select(campaign.c.created_at, campaign.c.plan_hash).order_by(campaign.c.id).limit(1)
    ).first()
    if first is None:
        return str(uuid.uuid4())
    created = first.created_at
    if created.tzinfo is not None:  # PostgreSQL; SQLite gives the UTC wall time back naive
        created = created.astimezone(UTC).replace(tzinfo=None)
    return str(uuid.uuid5(NAMESPACE, f"{created.isoformat()} {first.plan_hash}"))


def upgrade() -> None:
    identity = op.create_table(
        "database_identity",
        sa.Column("uuid", sa.String(length=36), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("length(uuid) = 36", name=op.f("ck_database_identity_uuid")),
        sa.PrimaryKeyConstraint("uuid", name=op.f("pk_database_identity")),
    )
    op.bulk_insert(identity, [{"uuid": _identity(op.get_bind()), "created_at": datetime.now(UTC)}])
    op.create_table(
        "campaign_origin",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("source_database", sa.String(length=36), nullable=False),
        sa.Column("source_campaign_id", sa.Integer(), nullable=False),
        sa.Column("content_sha256", sa.String(length=64), nullable=False),
        sa.Column("merged_from", sa.Text(), nullable=False),
        sa.Column("merged_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("software_version", sa.String(length=64), nullable=False),
        sa.CheckConstraint(
            "length(content_sha256) = 64", name=op.f("ck_campaign_origin_content_sha256")
        ),
        sa.CheckConstraint(
            "source_campaign_id >= 1", name=op.f("ck_campaign_origin_source_campaign_id")
        ),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_campaign_origin_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_campaign_origin")),
        sa.UniqueConstraint("campaign_id", name=op.f("uq_campaign_origin_campaign_id")),
        sa.UniqueConstraint(
            "source_database",
            "source_campaign_id",
            name=op.f("uq_campaign_origin_source_database_source_campaign_id"),
        ),
    )


def downgrade() -> None:
    merged = op.get_bind().scalar(sa.text("SELECT count(*) FROM campaign_origin"))
    if merged:
        raise RuntimeError(
            f"cannot downgrade below schema 0008: {merged} merged campaigns are stored, and "
            "schema 0007 cannot hold their origin"
        )
    op.drop_table("campaign_origin")
    op.drop_table("database_identity")
