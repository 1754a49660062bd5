"""A serial campaign (`[compass] protocol = "iec61162"`, the simulated stand in virtual time)
run twice gives the same raw logs byte for byte; killed with SIGKILL and resumed, it keeps what
the database held and ends as the uninterrupted run, its serial logs read in order being the
uninterrupted one (the slow stage: several campaign runs)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gyrostand.acquisition import bus
from tests.acquisition.killing import kill_and_resume, serial_pieces, small_containers
from tests.devices.test_serial_run import SERIAL, run, write_plan


def test_two_runs_are_byte_identical(tmp_path: Path) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    for folder in (first, second):
        folder.mkdir()
        run(write_plan(folder))
    for suffix in ("blf", "nmea"):
        (a,) = (first / "raw").glob(f"*.{suffix}")
        (b,) = (second / "raw").glob(f"*.{suffix}")
        assert a.read_bytes() == b.read_bytes(), suffix


def test_kill_9_then_resume_equals_the_uninterrupted_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """kill -9 at random moments (`tests.acquisition.killing`): nothing committed is lost, the
    resumed campaign equals the uninterrupted one row for row, its CAN and serial logs read in
    order equal the uninterrupted ones."""
    monkeypatch.setattr(bus, "raw_log_writer", small_containers)
    run = kill_and_resume(tmp_path, kills=2, seed=7, compass=SERIAL)
    assert run.problems == ()
    assert run.kills >= 1
    assert len(serial_pieces(list(run.segments))) > 1000
