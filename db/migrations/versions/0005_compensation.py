"""Compensated observations: `observation.compensation_deg` is the fitted transient subtracted
from the stored raw reading `value_deg` (NULL: not compensated), `series.compensation_se_deg` the
standard error the compensated series mean carries (the settle point's, from the transient fit).

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-23 19:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | Sequence[str] | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("observation") as batch:
        batch.add_column(sa.Column("compensation_deg", sa.Float(), nullable=True))
    with op.batch_alter_table("series") as batch:
        batch.add_column(sa.Column("compensation_se_deg", sa.Float(), nullable=True))
        batch.create_check_constraint(
            op.f("ck_series_compensation_se"),
            "compensation_se_deg IS NULL OR compensation_se_deg >= 0",
        )


def downgrade() -> None:
    compensated = op.get_bind().scalar(
        sa.text("SELECT count(*) FROM observation WHERE compensation_deg IS NOT NULL")
    )
    if compensated:
        raise RuntimeError(
            f"cannot downgrade below schema 0005: {compensated} observations are compensated, "
            "and schema 0004 cannot hold their compensation"
        )
    with op.batch_alter_table("series") as batch:
        batch.drop_constraint(op.f("ck_series_compensation_se"), type_="check")
        batch.drop_column("compensation_se_deg")
    with op.batch_alter_table("observation") as batch:
        batch.drop_column("compensation_deg")
