"""Series settle outcome: how each series settled, as a structured record (JSON) instead of event
text. Existing campaigns are filled in: early-settle series from their "early settle" event
(the last one of the series, as the report used to read it), band-settled series from their
settle times.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-23 10:00:00
"""

import json
import re
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | Sequence[str] | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# The event text 0.1.0 wrote (acquisition/early_settle.py at revision 0001); read once, here.
_OUTCOME = re.compile(
    r"settled by the estimate after (?P<settle>[\d.]+) s: settle point (?P<est>-?[\d.]+) deg "
    r"\(SE (?P<se>[\d.]+) deg, stable since (?P<stable>[\d.]+) s at (?P<at>-?[\d.]+) deg"
)
_BAND = re.compile(r"band criterion (?P<how>held|predicted) after (?P<band>[\d.]+) s")


def _from_event(message: str) -> dict[str, object] | None:
    m = _OUTCOME.match(message)
    if m is None:
        return None
    band = _BAND.search(message)
    return {
        "criterion": "estimate",
        "settle_s": float(m["settle"]),
        "estimate_deg": float(m["est"]),
        "standard_error_deg": float(m["se"]),
        "stable_since_s": float(m["stable"]),
        "stable_estimate_deg": float(m["at"]),
        "band_s": None if band is None else float(band["band"]),
        "band_measured": band is not None and band["how"] == "held",
    }


def upgrade() -> None:
    with op.batch_alter_table("series") as batch:
        batch.add_column(sa.Column("settle_outcome", sa.JSON(), nullable=True))
    bind = op.get_bind()
    outcomes: dict[int, dict[str, object]] = {}
    rows = bind.execute(
        sa.text(
            "SELECT id, settle_started_ms, settle_done_ms, settle_estimate_deg FROM series"
            " WHERE settle_started_ms IS NOT NULL AND settle_done_ms IS NOT NULL"
            " AND settle_estimate_deg IS NOT NULL"
        )
    )
    for series_id, started, done, estimate in rows:
        waited = (done - started) / 1000
        outcomes[series_id] = {
            "criterion": "band",
            "settle_s": waited,
            "estimate_deg": estimate,
            "standard_error_deg": None,
            "stable_since_s": None,
            "stable_estimate_deg": None,
            "band_s": waited,
            "band_measured": True,
        }
    events = bind.execute(
        sa.text(
            "SELECT series_id, message FROM event WHERE kind = 'early settle'"
            " AND series_id IS NOT NULL ORDER BY id"
        )
    )
    for series_id, message in events:
        found = _from_event(message)
        if found is not None:
            outcomes[series_id] = found
    for series_id, outcome in outcomes.items():
        bind.execute(
            sa.text("UPDATE series SET settle_outcome = :o WHERE id = :i"),
            {"o": json.dumps(outcome), "i": series_id},
        )


def downgrade() -> None:
    with op.batch_alter_table("series") as batch:
        batch.drop_column("settle_outcome")
