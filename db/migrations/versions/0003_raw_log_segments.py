"""Raw-log segments: every raw CAN log file of a campaign (the first run's and one per resume,
killed ones included) with its hash, instead of one path on the campaign; and the count of the
acquisition engine's committed writes (a resumed simulation skips them when it re-runs).

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23 14:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | Sequence[str] | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "raw_log_segment",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("path", sa.Text(), nullable=False),
        sa.Column("start", sa.String(length=16), nullable=False),
        sa.Column("first_frame", sa.BigInteger(), nullable=False),
        sa.Column("frames", sa.BigInteger(), nullable=True),
        sa.Column("sha256", sa.String(length=64), nullable=True),
        sa.Column("ending", sa.String(length=16), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("seq >= 1", name=op.f("ck_raw_log_segment_seq")),
        sa.CheckConstraint(
            "start IN ('new', 'continued', 'restarted')", name=op.f("ck_raw_log_segment_start")
        ),
        sa.CheckConstraint(
            "ending IS NULL OR ending IN ('closed', 'killed')",
            name=op.f("ck_raw_log_segment_ending"),
        ),
        sa.CheckConstraint("first_frame >= 0", name=op.f("ck_raw_log_segment_first_frame")),
        sa.CheckConstraint("frames IS NULL OR frames >= 0", name=op.f("ck_raw_log_segment_frames")),
        sa.CheckConstraint(
            "sha256 IS NULL OR length(sha256) = 64", name=op.f("ck_raw_log_segment_sha256")
        ),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_raw_log_segment_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_raw_log_segment")),
        sa.UniqueConstraint("campaign_id", "seq", name=op.f("uq_raw_log_segment_campaign_id_seq")),
    )
    bind = op.get_bind()
    bind.execute(
        sa.text(
            "INSERT INTO raw_log_segment (campaign_id, seq, path, start, first_frame, sha256,"
            " ending, created_at)"
            " SELECT id, 1, raw_log_path, 'new', 0, raw_log_sha256,"
            " CASE WHEN raw_log_sha256 IS NULL THEN NULL ELSE 'closed' END, created_at"
            " FROM campaign WHERE raw_log_path IS NOT NULL"
        )
    )
    with op.batch_alter_table("campaign") as batch:
        batch.add_column(
            sa.Column("engine_writes", sa.Integer(), nullable=False, server_default="0")
        )
        batch.create_check_constraint(op.f("ck_campaign_engine_writes"), "engine_writes >= 0")
        batch.drop_constraint(op.f("ck_campaign_raw_log_sha256"), type_="check")
        batch.drop_column("raw_log_path")
        batch.drop_column("raw_log_sha256")


def downgrade() -> None:
    with op.batch_alter_table("campaign") as batch:
        batch.add_column(sa.Column("raw_log_path", sa.Text(), nullable=True))
        batch.add_column(sa.Column("raw_log_sha256", sa.String(length=64), nullable=True))
        batch.create_check_constraint(
            op.f("ck_campaign_raw_log_sha256"),
            "raw_log_sha256 IS NULL OR length(raw_log_sha256) = 64",
        )
        batch.drop_constraint(op.f("ck_campaign_engine_writes"), type_="check")
        batch.drop_column("engine_writes")
    op.get_bind().execute(
        sa.text(
            "UPDATE campaign SET raw_log_path = s.path, raw_log_sha256 = s.sha256"
            " FROM raw_log_segment s WHERE s.campaign_id = campaign.id AND s.seq = 1"
        )
    )
    op.drop_table("raw_log_segment")
