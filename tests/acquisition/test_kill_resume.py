"""kill -9 at random moments of a simulated campaign in virtual time (`killing`): at every kill
nothing committed was lost or changed, and after the last resume the database equals an
uninterrupted run's row for row (wall-clock columns and the kill/resume bookkeeping aside), its
raw log segments read in order equal the uninterrupted log frame for frame. A resume of a killed
simulation re-runs it from the start in virtual time and skips the writes the database holds
(`CampaignStore.re_run`): the same seed gives the same frames, so the result is exact.

8 kills here on SQLite, 2 on PostgreSQL (each re-runs the campaign up to its moment);
validation/kill_resume.py does 30 per campaign over several seeds."""

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import create_engine, text

from gyrostand.acquisition import bus
from tests.conftest import NewDatabase

from .killing import (
    forked,
    frames,
    kill_and_resume,
    segments,
    small_containers,
    snapshot,
    write_plan,
)


def test_kill_9_at_random_moments_then_resume_equals_the_uninterrupted_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, new_db_url: NewDatabase
) -> None:
    monkeypatch.setattr(bus, "raw_log_writer", small_containers)
    kills = 8 if new_db_url.backend == "sqlite" else 2
    run = kill_and_resume(tmp_path, kills=kills, seed=18, urls=(new_db_url(), new_db_url()))
    assert run.problems == ()
    assert run.kills >= kills * 3 // 4  # (a run may finish before its moment comes)
    # a run killed after two writes of its own went past the earlier logs: it logged frames
    assert len(run.advanced) >= 2
    assert all(run.segments[i].frames for i in run.advanced)


def test_a_run_killed_after_its_last_write_is_resumed_to_the_whole_raw_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A simulation killed after it committed its last observation, before it closed its raw
    log (made here by hand from a finished run: the campaign left "running", its log open and cut
    at half, as kill -9 leaves them): the resume re-runs it in virtual time, so that the frames
    the killed run never wrote out are derived again, instead of "nothing left to acquire"."""
    monkeypatch.setattr(bus, "raw_log_writer", small_containers)
    reference, killed = tmp_path / "reference", tmp_path / "killed"
    urls = []
    for folder in (reference, killed):
        folder.mkdir()
        urls.append(f"sqlite:///{folder / 'db.sqlite'}")
        assert forked(["campaign", "run", str(write_plan(folder, urls[-1], 18)), "--quiet"]) == 0
    [log] = segments(urls[1])
    log.path.write_bytes(log.path.read_bytes()[: log.path.stat().st_size // 2])
    engine = create_engine(urls[1])
    with engine.begin() as conn:
        conn.execute(text("UPDATE campaign SET status = 'running'"))
        conn.execute(text("UPDATE raw_log_segment SET ending = NULL, frames = NULL"))
    engine.dispose()
    assert forked(["campaign", "resume", "1", "--db", urls[1], "--quiet"]) == 0
    logs = segments(urls[1])
    assert [(s.start, s.ending) for s in logs] == [("new", "killed"), ("continued", "closed")]
    assert 0 < logs[0].frames < logs[1].first_frame + logs[1].frames
    got, want = frames([s.path for s in logs]), frames([s.path for s in segments(urls[0])])
    assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
    assert snapshot(urls[1]) == snapshot(urls[0])
