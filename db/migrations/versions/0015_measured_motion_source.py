"""Where a trial's measured motion (meas_*) comes from: "stand report" (a stand controller's
own STAND_MOTION reports: every trial measured before) or "drive position" (a CiA 402 drive's
actual position, fitted by gyrostand).

Revision ID: 0015
Revises: 0010
Create Date: 2026-11-27 16:15:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015"
down_revision: str | Sequence[str] | None = "0013"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("trial") as batch:
        batch.add_column(sa.Column("meas_source", sa.String(length=32), nullable=True))
    op.execute(
        sa.text("UPDATE trial SET meas_source = 'stand report' WHERE meas_amplitude_cm IS NOT NULL")
    )


def downgrade() -> None:
    with op.batch_alter_table("trial") as batch:
        batch.drop_column("meas_source")
