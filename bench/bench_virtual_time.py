"""The paper campaign (examples/paper.toml) on the in-process simulated stand in virtual time:
wall time of the acquisition stage, frames/s end to end (stand -> bus -> acquisition -> SQLite +
raw BLF), and the ratio to the ingest path alone on the same machine in the same run
(bench_ingest.py's measurement, 300 000 campaign frames, not pinned here). Then the same
campaign with the other core kept busy: the stored observations must be identical.

Targets (issues 14, 37): acquisition <= 8 s on a 2-core machine; bounded by ingest, not by a
speed-up. The CPU seconds of the whole process are printed beside the wall time, the simulated
stand's thread apart (a loaded machine stretches the wall time, hardly the CPU time).

Run: .venv/bin/python bench/bench_virtual_time.py [--profile]  (--profile: the top five costs
per frame of the campaign thread and of the simulated stand's thread, from cProfile, instead)"""

from __future__ import annotations

import argparse
import cProfile
import itertools
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import closing, contextmanager
from pathlib import Path
from typing import Any

from acquisition_stream import campaign_frames, paper_plan
from bench_ingest import ours
from top_costs import print_costs, profiled_method

from gyrostand.acquisition.runner import run_live
from gyrostand.acquisition.store import CampaignStore
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.logfile import read_raw_frames
from gyrostand.plan.model import load_plan, revised
from gyrostand.stand.simulator import Simulator

ROOT = Path(__file__).resolve().parents[1]
INGEST_FRAMES = 300_000  # bench_ingest.py's default


@contextmanager
def thread_cpu(cls: type, name: str) -> Iterator[list[float]]:
    """The CPU seconds of every call of `cls.name` (a thread's run loop), in the thread."""
    spent: list[float] = []
    original = getattr(cls, name)

    def wrapper(self: Any) -> None:
        start = time.thread_time()
        try:
            original(self)
        finally:
            spent.append(time.thread_time() - start)

    setattr(cls, name, wrapper)
    try:
        yield spent
    finally:
        setattr(cls, name, original)


def campaign(
    folder: Path, profile: cProfile.Profile | None = None
) -> tuple[float, float, float, int, list[tuple]]:
    """Run the paper plan into `folder`: (wall and CPU seconds of run_live, CPU seconds of the
    simulated stand's thread among them, frames, observations); `profile` profiles the
    campaign thread."""
    plan = load_plan(ROOT / "examples" / "paper.toml")
    db = folder / "paper.sqlite"
    plan = revised(plan, campaign={"database": str(db), "raw_log_dir": str(folder / "raw")})
    store = CampaignStore.create(open_database(sqlite_url(db)), plan)
    with thread_cpu(Simulator, "_run") as stand:
        start, cpu = time.perf_counter(), time.process_time()
        if profile is None:
            result = run_live(plan, store, quiet=True)
        else:
            result = profile.runcall(run_live, plan, store, quiet=True)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    assert result.outcome == "completed", result
    assert result.raw_log is not None
    frames = sum(len(raw) for raw in read_raw_frames(result.raw_log))
    with closing(sqlite3.connect(db)) as conn:
        rows = conn.execute(
            "SELECT series_id, k, value_deg FROM observation ORDER BY id"
        ).fetchall()
    return wall, cpu, sum(stand), frames, rows


def profiled() -> None:
    """The top five costs per frame of both threads."""
    main_thread = cProfile.Profile()
    with profiled_method(Simulator, "_run") as stand, tempfile.TemporaryDirectory() as tmp:
        _, _, _, frames, _ = campaign(Path(tmp), main_thread)
    print(f"paper campaign, virtual time, {frames:,} frames, under cProfile")
    print_costs("campaign thread (decode, engine, SQLite, raw BLF)", main_thread, frames)
    print_costs("simulated stand's thread", stand, frames)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", action="store_true", help="the top costs, from cProfile")
    if parser.parse_args().profile:
        profiled()
        return
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "idle").mkdir()
        wall, cpu, stand, frames, idle_rows = campaign(folder / "idle")
        print(f"paper campaign, virtual time: {frames:,} frames in {wall:.2f} s wall", end="")
        rest = cpu - stand
        print(f" ({cpu:.2f} s CPU: the simulated stand's thread {stand:.2f}, the rest {rest:.2f})")
        rate = frames / wall
        print(f"end to end (stand -> bus -> acquisition -> SQLite + BLF): {rate:,.0f} frames/s")
        stream = list(itertools.islice(campaign_frames(paper_plan(":memory:")), INGEST_FRAMES))
        run = ours(stream, folder, True)
        ingest = run.rate
        print(f"ingest alone (bench_ingest's path, {run.done:,} frames): {ingest:,.0f} frames/s")
        print(f"end to end / ingest: {rate / ingest:.2f}")
        print(f"target acquisition <= 8 s: {'OK' if wall <= 8 else 'ABOVE TARGET'}")
        (folder / "busy").mkdir()
        hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        try:
            busy_wall, busy_cpu, _, busy_frames, busy_rows = campaign(folder / "busy")
        finally:
            hog.kill()
        print(
            f"with the other core busy: {busy_frames:,} frames in {busy_wall:.2f} s wall "
            f"({busy_cpu:.2f} s CPU); "
            f"observations {'identical' if busy_rows == idle_rows else 'DIFFERENT'}"
        )


if __name__ == "__main__":
    main()
