"""The measured motion of each rocking series, per measuring source (inclinometer, drive
position, the stand's own report): A, tau, K where known, phase, their scatter and how many
cycles. Earlier campaigns keep only the trial's meas_* (the stand's reports, averaged).

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-27 16:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011"
down_revision: str | Sequence[str] | None = "0010"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "measured_motion",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("series_id", sa.Integer(), nullable=False),
        sa.Column("source", sa.String(length=32), nullable=False),
        sa.Column("amplitude_cm", sa.Float(), nullable=False),
        sa.Column("amplitude_se_cm", sa.Float(), nullable=False),
        sa.Column("amplitude_sd_cm", sa.Float(), nullable=False),
        sa.Column("period_s", sa.Float(), nullable=False),
        sa.Column("period_se_s", sa.Float(), nullable=False),
        sa.Column("period_sd_s", sa.Float(), nullable=False),
        sa.Column("direction_deg", sa.Float(), nullable=True),
        sa.Column("phase_deg", sa.Float(), nullable=True),
        sa.Column("phase_sd_deg", sa.Float(), nullable=True),
        sa.Column("first_cycle_ms", sa.BigInteger(), nullable=True),
        sa.Column("n_cycles", sa.Integer(), nullable=True),
        sa.Column("n_samples", sa.Integer(), nullable=False),
        sa.CheckConstraint(
            "source IN ('inclinometer', 'drive position', 'stand report')",
            name=op.f("ck_measured_motion_source"),
        ),
        sa.CheckConstraint("amplitude_cm >= 0", name=op.f("ck_measured_motion_amplitude")),
        sa.CheckConstraint("period_s > 0", name=op.f("ck_measured_motion_period")),
        sa.CheckConstraint("n_samples >= 1", name=op.f("ck_measured_motion_n_samples")),
        sa.CheckConstraint(
            "n_cycles IS NULL OR n_cycles >= 1", name=op.f("ck_measured_motion_n_cycles")
        ),
        sa.ForeignKeyConstraint(
            ["series_id"],
            ["series.id"],
            name=op.f("fk_measured_motion_series_id_series"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_measured_motion")),
        sa.UniqueConstraint(
            "series_id", "source", name=op.f("uq_measured_motion_series_id_source")
        ),
    )


def downgrade() -> None:
    op.drop_table("measured_motion")
