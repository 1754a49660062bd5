"""The heading source of each campaign: the compass's protocol, how its headings were timed
(the time base) and their resolution. Campaigns acquired before (stand runs and replays) all
read gyrostand's heading frame with the stand clock it carries: that is filled in, the
resolution left unknown (their DBC may be a lab's).

Revision ID: 0010
Revises: 0008
Create Date: 2026-11-27 13:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010"
down_revision: str | Sequence[str] | None = "0008"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

STAND_CLOCK = "stand clock carried in every heading frame"  # devices.stand_frames.STAND_CLOCK


def upgrade() -> None:
    with op.batch_alter_table("campaign") as batch:
        batch.add_column(sa.Column("heading_source", sa.String(length=16), nullable=True))
        batch.add_column(sa.Column("heading_time_base", sa.Text(), nullable=True))
        batch.add_column(sa.Column("heading_resolution_deg", sa.Float(), nullable=True))
    op.execute(
        sa.text(
            "UPDATE campaign SET heading_source = 'gyrostand', heading_time_base = :base "
            "WHERE source IN ('stand', 'replay')"
        ).bindparams(base=STAND_CLOCK)
    )


def downgrade() -> None:
    with op.batch_alter_table("campaign") as batch:
        batch.drop_column("heading_resolution_deg")
        batch.drop_column("heading_time_base")
        batch.drop_column("heading_source")
