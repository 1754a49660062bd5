"""bench/bench_ingest.py's rows for a compass speaking NMEA 2000 or read by a CiA 406 encoder
(issue 37): on a short clean campaign stream every frame reaches the campaign (loss 0) and the
campaign sees the stream as sent, with no gap and no silence (counts, not timing). Those sources
take their clock from the frames' reception times: the bench must deliver them at their stream
times, not at the instant it queued them (that made hundreds of gap events and silent trials,
each a database write, and the bench measured those instead of the ingest)."""

from __future__ import annotations

import itertools
import sqlite3
import sys
from contextlib import closing
from pathlib import Path

import pytest

from tests.acquisition.harness import ROOT

sys.path.insert(0, str(ROOT / "bench"))
from acquisition_stream import campaign_frames, paper_plan  # noqa: E402
from bench_ingest import ours  # noqa: E402

FRAMES = 5_000


@pytest.mark.parametrize("protocol", ["nmea2000", "cia406"])
def test_bench_row_loses_nothing_and_sees_no_gap(protocol: str, tmp_path: Path) -> None:
    plan = paper_plan(":memory:", protocol=protocol)
    frames = list(itertools.islice(campaign_frames(plan), FRAMES))
    run = ours(frames, tmp_path, True, protocol)
    assert (run.done, run.lost) == (FRAMES, 0)
    (database,) = tmp_path.glob("ours-*.sqlite")  # (each run its own)
    with closing(sqlite3.connect(database)) as db:
        kinds = dict(db.execute("SELECT kind, count(*) FROM event GROUP BY kind").fetchall())
        statuses = {s for (s,) in db.execute("SELECT status FROM trial")}
    assert kinds.get("frame gap", 0) == kinds.get("bus silence", 0) == 0, kinds
    assert kinds["command"] >= 1 and "failed" not in statuses, (kinds, statuses)
