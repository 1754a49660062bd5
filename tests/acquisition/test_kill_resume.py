"""kill -9 at random moments of a simulated campaign in virtual time (`killing`): at every kill
nothing committed was lost or changed, and after the last resume the database equals an
uninterrupted run's row for row (wall-clock columns and the kill/resume bookkeeping aside), its
raw log segments read in order equal the uninterrupted log frame for frame. A resume of a killed
simulation re-runs it from the start in virtual time and skips the writes the database holds
(`CampaignStore.re_run`): the same seed gives the same frames, so the result is exact.

8 kills here on SQLite, 2 on PostgreSQL (each re-runs the campaign up to its moment);
validation/kill_resume.py does 30 per campaign over several seeds."""

from pathlib import Path

import pytest

from gyrostand.acquisition import bus
from tests.conftest import NewDatabase

from .killing import kill_and_resume, small_containers


def test_kill_9_at_random_moments_then_resume_equals_the_uninterrupted_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, new_db_url: NewDatabase
) -> None:
    monkeypatch.setattr(bus, "raw_log_writer", small_containers)
    kills = 8 if new_db_url.backend == "sqlite" else 2
    run = kill_and_resume(tmp_path, kills=kills, seed=18, urls=(new_db_url(), new_db_url()))
    assert run.problems == ()
    assert run.kills >= kills * 3 // 4  # (a run may finish before its moment comes)
    assert sum(bool(s.frames) for s in run.segments[:-1]) >= min(2, run.kills - 1)  # (frames)
