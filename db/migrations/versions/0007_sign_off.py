"""Sign-off: `sign_off` holds who tested and who checked a campaign (one row per role), as
entered at the operator station. The downgrade refuses while any campaign is signed (schema
0006 cannot hold the signatures).

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-23 21:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | Sequence[str] | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "sign_off",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("role", sa.String(length=16), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("signed_at", sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("role IN ('tested_by', 'checked_by')", name=op.f("ck_sign_off_role")),
        sa.CheckConstraint("length(name) > 0", name=op.f("ck_sign_off_name")),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_sign_off_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_sign_off")),
        sa.UniqueConstraint("campaign_id", "role", name=op.f("uq_sign_off_campaign_id_role")),
    )
    with op.batch_alter_table("sign_off") as batch:
        batch.create_index(batch.f("ix_sign_off_campaign_id"), ["campaign_id"], unique=False)


def downgrade() -> None:
    signed = op.get_bind().scalar(sa.text("SELECT count(*) FROM sign_off"))
    if signed:
        raise RuntimeError(
            f"cannot downgrade below schema 0007: {signed} sign-offs are stored, and schema "
            "0006 cannot hold them"
        )
    with op.batch_alter_table("sign_off") as batch:
        batch.drop_index(batch.f("ix_sign_off_campaign_id"))
    op.drop_table("sign_off")
