"""A compensated series' share in the period and damping error its compensation used:
`series.compensation_shared` (JSON, `analysis.gls.SharedError`: the compensated mean's
sensitivity to the period and damping ratio, their covariance, which record and when; NULL: not
compensated, or compensated before this schema). The analysis fits model 1.1 by generalised
least squares on it. The downgrade refuses while any is stored (schema 0021 cannot hold it).

Revision ID: 0023
Revises: 0021
Create Date: 2026-12-02 03:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0023"
down_revision: str | Sequence[str] | None = "0021"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("series") as batch:
        batch.add_column(sa.Column("compensation_shared", sa.JSON(), nullable=True))


def downgrade() -> None:
    stored = op.get_bind().scalar(
        sa.text("SELECT count(*) FROM series WHERE compensation_shared IS NOT NULL")
    )
    if stored:
        raise RuntimeError(
            f"cannot downgrade below schema 0023: {stored} series hold their share in the "
            "period and damping error, and schema 0021 cannot hold it"
        )
    with op.batch_alter_table("series") as batch:
        batch.drop_column("compensation_shared")
