"""Removing campaigns (`gyrostand campaign remove`): `campaign_removal` keeps what each removed
campaign was (its content's SHA-256 and a record of it), who removed it, when, why, and what
became of its raw logs. The downgrade refuses while any removal is recorded (schema 0015
cannot hold it).

Revision ID: 0021
Revises: 0015
Create Date: 2026-11-27 19:20:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0021"
down_revision: str | Sequence[str] | None = "0020"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "campaign_removal",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("content_sha256", sa.String(length=64), nullable=False),
        sa.Column("record", sa.JSON(), nullable=False),
        sa.Column("removed_by", sa.String(length=200), nullable=False),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.Column("raw_logs", sa.String(length=16), nullable=False),
        sa.Column("removed_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("software_version", sa.String(length=64), nullable=False),
        sa.CheckConstraint(
            "length(content_sha256) = 64", name=op.f("ck_campaign_removal_content_sha256")
        ),
        sa.CheckConstraint("length(removed_by) > 0", name=op.f("ck_campaign_removal_removed_by")),
        sa.CheckConstraint(
            "raw_logs IN ('kept', 'deleted', 'none')", name=op.f("ck_campaign_removal_raw_logs")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_campaign_removal")),
    )
    op.create_index(
        op.f("ix_campaign_removal_campaign_id"), "campaign_removal", ["campaign_id"], unique=False
    )


def downgrade() -> None:
    removed = op.get_bind().scalar(sa.text("SELECT count(*) FROM campaign_removal"))
    if removed:
        raise RuntimeError(
            f"cannot downgrade below schema 0021: {removed} campaign removals are recorded, and "
            "schema 0015 cannot hold them"
        )
    op.drop_index(op.f("ix_campaign_removal_campaign_id"), table_name="campaign_removal")
    op.drop_table("campaign_removal")
