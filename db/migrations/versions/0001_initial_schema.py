"""Initial schema: instrument, campaign, trial, series, observation, event, analysis run.

Revision ID: 0001
Revises: (none)
Create Date: 2026-11-22 03:08:29.813765
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "instrument",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("model", sa.String(length=200), nullable=False),
        sa.Column("serial", sa.String(length=200), nullable=False),
        sa.Column("constants_json", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_instrument")),
    )
    op.create_table(
        "campaign",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("instrument_id", sa.Integer(), nullable=False),
        sa.Column("plan_toml", sa.Text(), nullable=False),
        sa.Column("plan_hash", sa.String(length=64), nullable=False),
        sa.Column("operator", sa.String(length=200), nullable=False),
        sa.Column("latitude_deg", sa.Float(), nullable=False),
        sa.Column("earth_rate_rad_s", sa.Float(), nullable=False),
        sa.Column("gravity_cm_s2", sa.Float(), nullable=False),
        sa.Column("n_obs", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("software_version", sa.String(length=64), nullable=False),
        sa.Column("raw_log_path", sa.Text(), nullable=True),
        sa.Column("raw_log_sha256", sa.String(length=64), nullable=True),
        sa.CheckConstraint(
            "source IN ('stand', 'import', 'replay')", name=op.f("ck_campaign_source")
        ),
        sa.CheckConstraint(
            "status IN ('planned', 'running', 'paused', 'completed', 'failed', 'stopped')",
            name=op.f("ck_campaign_status"),
        ),
        sa.CheckConstraint("earth_rate_rad_s > 0", name=op.f("ck_campaign_earth_rate")),
        sa.CheckConstraint(
            "finished_at IS NULL OR started_at IS NULL OR finished_at >= started_at",
            name=op.f("ck_campaign_finished_after_start"),
        ),
        sa.CheckConstraint("gravity_cm_s2 > 0", name=op.f("ck_campaign_gravity")),
        sa.CheckConstraint(
            "latitude_deg > -90 AND latitude_deg < 90", name=op.f("ck_campaign_latitude")
        ),
        sa.CheckConstraint("length(plan_hash) = 64", name=op.f("ck_campaign_plan_hash")),
        sa.CheckConstraint("n_obs >= 2", name=op.f("ck_campaign_n_obs")),
        sa.CheckConstraint(
            "raw_log_sha256 IS NULL OR length(raw_log_sha256) = 64",
            name=op.f("ck_campaign_raw_log_sha256"),
        ),
        sa.ForeignKeyConstraint(
            ["instrument_id"], ["instrument.id"], name=op.f("fk_campaign_instrument_id_instrument")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_campaign")),
    )
    op.create_index(op.f("ix_campaign_instrument_id"), "campaign", ["instrument_id"])
    op.create_table(
        "analysis_run",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("inputs_hash", sa.String(length=64), nullable=False),
        sa.Column("results_json", sa.JSON(), nullable=False),
        sa.Column("software_version", sa.String(length=64), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("length(inputs_hash) = 64", name=op.f("ck_analysis_run_inputs_hash")),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_analysis_run_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_analysis_run")),
    )
    op.create_index(op.f("ix_analysis_run_campaign_id"), "analysis_run", ["campaign_id"])
    op.create_table(
        "trial",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("index", sa.Integer(), nullable=False),
        sa.Column("role", sa.String(length=16), nullable=False),
        sa.Column("cmd_direction_deg", sa.Float(), nullable=False),
        sa.Column("cmd_amplitude_cm", sa.Float(), nullable=False),
        sa.Column("cmd_period_s", sa.Float(), nullable=False),
        sa.Column("meas_direction_deg", sa.Float(), nullable=True),
        sa.Column("meas_amplitude_cm", sa.Float(), nullable=True),
        sa.Column("meas_period_s", sa.Float(), nullable=True),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("failure_reason", sa.Text(), nullable=True),
        sa.Column("summary_delta_mean_deg", sa.Float(), nullable=True),
        sa.Column("summary_delta_var_deg2", sa.Float(), nullable=True),
        sa.Column("summary_n", sa.Integer(), nullable=True),
        sa.CheckConstraint("role IN ('fit', 'control')", name=op.f("ck_trial_role")),
        sa.CheckConstraint(
            "status != 'failed' OR failure_reason IS NOT NULL",
            name=op.f("ck_trial_failed_has_reason"),
        ),
        sa.CheckConstraint(
            "status IN ('pending', 'running', 'completed', 'failed')", name=op.f("ck_trial_status")
        ),
        sa.CheckConstraint('"index" >= 1', name=op.f("ck_trial_index")),
        sa.CheckConstraint("cmd_amplitude_cm >= 0", name=op.f("ck_trial_cmd_amplitude")),
        sa.CheckConstraint(
            "cmd_direction_deg >= 0 AND cmd_direction_deg < 360",
            name=op.f("ck_trial_cmd_direction"),
        ),
        sa.CheckConstraint("cmd_period_s > 0", name=op.f("ck_trial_cmd_period")),
        sa.CheckConstraint(
            "meas_amplitude_cm IS NULL OR meas_amplitude_cm >= 0",
            name=op.f("ck_trial_meas_amplitude"),
        ),
        sa.CheckConstraint(
            "meas_period_s IS NULL OR meas_period_s > 0", name=op.f("ck_trial_meas_period")
        ),
        sa.CheckConstraint(
            "summary_delta_var_deg2 IS NULL OR summary_delta_var_deg2 >= 0",
            name=op.f("ck_trial_summary_var"),
        ),
        sa.CheckConstraint("summary_n IS NULL OR summary_n >= 2", name=op.f("ck_trial_summary_n")),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_trial_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_trial")),
        sa.UniqueConstraint("campaign_id", "index", name=op.f("uq_trial_campaign_id_index")),
    )
    op.create_table(
        "series",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("j", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("settle_started_ms", sa.BigInteger(), nullable=True),
        sa.Column("settle_done_ms", sa.BigInteger(), nullable=True),
        sa.Column("settle_estimate_deg", sa.Float(), nullable=True),
        sa.Column("summary_mean_deg", sa.Float(), nullable=True),
        sa.Column("summary_variance_deg2", sa.Float(), nullable=True),
        sa.Column("summary_n", sa.Integer(), nullable=True),
        sa.CheckConstraint(
            "status IN ('pending', 'settling', 'observing', 'completed', 'failed')",
            name=op.f("ck_series_status"),
        ),
        sa.CheckConstraint("j IN (1, 2)", name=op.f("ck_series_j")),
        sa.CheckConstraint(
            "settle_done_ms IS NULL OR settle_started_ms IS NULL"
            " OR settle_done_ms >= settle_started_ms",
            name=op.f("ck_series_settle_order"),
        ),
        sa.CheckConstraint("summary_n IS NULL OR summary_n >= 2", name=op.f("ck_series_summary_n")),
        sa.CheckConstraint(
            "summary_variance_deg2 IS NULL OR summary_variance_deg2 >= 0",
            name=op.f("ck_series_summary_variance"),
        ),
        sa.ForeignKeyConstraint(
            ["trial_id"], ["trial.id"], name=op.f("fk_series_trial_id_trial"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_series")),
        sa.UniqueConstraint("trial_id", "j", name=op.f("uq_series_trial_id_j")),
    )
    op.create_table(
        "event",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.Integer(), nullable=True),
        sa.Column("series_id", sa.Integer(), nullable=True),
        sa.Column("stand_time_ms", sa.BigInteger(), nullable=True),
        sa.Column("wall_time", sa.DateTime(timezone=True), nullable=False),
        sa.Column("kind", sa.String(length=64), nullable=False),
        sa.Column("severity", sa.String(length=16), nullable=False),
        sa.Column("message", sa.Text(), nullable=False),
        sa.CheckConstraint(
            "severity IN ('info', 'warning', 'error')", name=op.f("ck_event_severity")
        ),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            name=op.f("fk_event_campaign_id_campaign"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["series_id"], ["series.id"], name=op.f("fk_event_series_id_series"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["trial_id"], ["trial.id"], name=op.f("fk_event_trial_id_trial"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_event")),
    )
    op.create_index(op.f("ix_event_campaign_id"), "event", ["campaign_id"])
    op.create_table(
        "observation",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("series_id", sa.Integer(), nullable=False),
        sa.Column("k", sa.Integer(), nullable=False),
        sa.Column("value_deg", sa.Float(), nullable=False),
        sa.Column("window_start_ms", sa.BigInteger(), nullable=True),
        sa.Column("window_end_ms", sa.BigInteger(), nullable=True),
        sa.Column("frames_used", sa.Integer(), nullable=True),
        sa.Column("frames_lost", sa.Integer(), nullable=True),
        sa.Column("flags", sa.String(length=200), nullable=False),
        sa.CheckConstraint(
            "frames_lost IS NULL OR frames_lost >= 0", name=op.f("ck_observation_frames_lost")
        ),
        sa.CheckConstraint(
            "frames_used IS NULL OR frames_used >= 0", name=op.f("ck_observation_frames_used")
        ),
        sa.CheckConstraint("k >= 1", name=op.f("ck_observation_k")),
        sa.CheckConstraint(
            "window_end_ms IS NULL OR window_start_ms IS NULL OR window_end_ms >= window_start_ms",
            name=op.f("ck_observation_window_order"),
        ),
        sa.ForeignKeyConstraint(
            ["series_id"],
            ["series.id"],
            name=op.f("fk_observation_series_id_series"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_observation")),
        sa.UniqueConstraint("series_id", "k", name=op.f("uq_observation_series_id_k")),
    )


def downgrade() -> None:
    op.drop_table("observation")
    op.drop_index(op.f("ix_event_campaign_id"), table_name="event")
    op.drop_table("event")
    op.drop_table("series")
    op.drop_table("trial")
    op.drop_index(op.f("ix_analysis_run_campaign_id"), table_name="analysis_run")
    op.drop_table("analysis_run")
    op.drop_index(op.f("ix_campaign_instrument_id"), table_name="campaign")
    op.drop_table("campaign")
    op.drop_table("instrument")
