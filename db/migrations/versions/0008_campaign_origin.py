"""Merging stand databases into a lab database (`gyrostand db merge`): `campaign_origin` holds
where a merged campaign comes from (the identity of the database it was recorded in, its id
there, the SHA-256 of its content, from which file, when, by which software). The downgrade
refuses while any campaign is merged (schema 0007 cannot hold their origin).

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-24 10:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | Sequence[str] | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
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
