"""Campaign labels: `campaign_label` holds key = value labels of a campaign (the factory that
made the unit, its production lot, the stand that tested it), set by `campaign run --tag` and
`import --tag`; fleet statistics group campaigns by one key.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-23 18:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | Sequence[str] | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "campaign_label",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("key", sa.String(length=64), nullable=False),
        sa.Column("value", sa.String(length=200), nullable=False),
        sa.CheckConstraint("length(key) >= 1", name=op.f("ck_campaign_label_key")),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_campaign_label_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_campaign_label")),
        sa.UniqueConstraint("campaign_id", "key", name=op.f("uq_campaign_label_campaign_id_key")),
    )


def downgrade() -> None:
    labelled = op.get_bind().scalar(sa.text("SELECT count(*) FROM campaign_label"))
    if labelled:
        raise RuntimeError(
            f"cannot downgrade below schema 0006: {labelled} campaign labels are stored, "
            "and schema 0005 cannot hold them"
        )
    op.drop_table("campaign_label")
