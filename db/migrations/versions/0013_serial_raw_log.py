"""A serial compass's raw log beside each raw CAN log (IEC 61162-450 TAG-block lines, the CAN
log's name with `.nmea`): its lines and hash in the segment's row. Empty for segments of
compasses on CAN, as for all segments before.

Revision ID: 0013
Revises: 0010
Create Date: 2026-11-27 16:15:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0013"
down_revision: str | Sequence[str] | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("raw_log_segment") as batch:
        batch.add_column(sa.Column("serial_lines", sa.BigInteger(), nullable=True))
        batch.add_column(sa.Column("serial_sha256", sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("raw_log_segment") as batch:
        batch.drop_column("serial_sha256")
        batch.drop_column("serial_lines")
