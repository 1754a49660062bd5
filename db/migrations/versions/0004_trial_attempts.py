"""Trial attempts: retrying a failed trial adds a row with the same index and the next attempt
(`trial.attempt`, 1 for the first); the unique key becomes (campaign_id, index, attempt). Every
existing trial is its first attempt. The downgrade refuses while any trial has more than one
attempt (schema 0003 holds one row per trial: it would have to drop data).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23 15:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | Sequence[str] | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("trial") as batch:
        batch.add_column(sa.Column("attempt", sa.Integer(), server_default="1", nullable=False))
        batch.drop_constraint(op.f("uq_trial_campaign_id_index"), type_="unique")
        batch.create_unique_constraint(
            op.f("uq_trial_campaign_id_index_attempt"), ["campaign_id", "index", "attempt"]
        )
        batch.create_check_constraint(op.f("ck_trial_attempt"), "attempt >= 1")


def downgrade() -> None:
    retried = op.get_bind().execute(
        sa.text(
            'SELECT campaign_id, "index", count(*) FROM trial GROUP BY campaign_id, "index"'
            ' HAVING count(*) > 1 ORDER BY campaign_id, "index"'
        )
    )
    found = [f"campaign {c} trial {i}: {n} attempts" for c, i, n in retried]
    if found:
        raise RuntimeError(
            "cannot downgrade below schema 0004: retried trials have more than one attempt ("
            + "; ".join(found)
            + "), and schema 0003 holds one per trial"
        )
    with op.batch_alter_table("trial") as batch:
        batch.drop_constraint(op.f("ck_trial_attempt"), type_="check")
        batch.drop_constraint(op.f("uq_trial_campaign_id_index_attempt"), type_="unique")
        batch.create_unique_constraint(op.f("uq_trial_campaign_id_index"), ["campaign_id", "index"])
        batch.drop_column("attempt")
