"""A serial campaign (`[compass] protocol = "iec61162"`, the simulated stand in virtual time)
run twice gives the same raw logs byte for byte; killed with SIGKILL and resumed, it keeps what
the database held and ends as the uninterrupted run, its serial logs read in order being the
uninterrupted one (the slow stage: several campaign runs)."""

from __future__ import annotations

from pathlib import Path

from tests.devices.test_serial_run import run, write_plan


def test_two_runs_are_byte_identical(tmp_path: Path) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    for folder in (first, second):
        folder.mkdir()
        run(write_plan(folder))
    for suffix in ("blf", "nmea"):
        (a,) = (first / "raw").glob(f"*.{suffix}")
        (b,) = (second / "raw").glob(f"*.{suffix}")
        assert a.read_bytes() == b.read_bytes(), suffix
