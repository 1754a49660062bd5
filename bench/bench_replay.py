"""Offline replay of a recorded campaign log: frames/s and memory.

Makes (once, cached in the temp folder) a BLF log of a long campaign on the simulated stand: the
paper's six trials repeated until the log holds --frames frames (default 10 million), recorded in
lockstep with the campaign engine. Then replays it as `gyrostand replay` does (numpy BLF reader ->
vectorised DBC decoder -> engine -> SQLite) and prints frames/s and the resident memory growth.
Targets: >= 1 000 000 frames/s, memory growth <= 50 MiB.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import threading
import time
from pathlib import Path

from acquisition_stream import campaign_frames, paper_plan, rss_mib, write_log

from gyrostand.acquisition.runner import replay
from gyrostand.db.session import open_database, sqlite_url
from gyrostand.frames.batch import BatchDecoder
from gyrostand.frames.logfile import read_raw_frames
from gyrostand.stand.protocol import Codec

FRAMES_PER_PAPER_CAMPAIGN = 900_000  # the six trials of examples/paper.toml at 10 Hz


def cached_log(frames: int) -> tuple[Path, int]:
    repeats = max(1, math.ceil(frames / FRAMES_PER_PAPER_CAMPAIGN))
    plan = paper_plan(":memory:", repeats)  # the log is only valid for this very plan
    name = f"gyrostand-bench-replay-x{repeats}-{plan.sha256[:12]}.blf"
    path = Path(tempfile.gettempdir()) / name
    if not path.exists():
        t0 = time.perf_counter()
        partial = path.with_suffix(".part.blf")
        n = write_log(partial, campaign_frames(plan))
        partial.rename(path)
        print(f"made {path} ({n:,} frames) in {time.perf_counter() - t0:.0f} s")
    return path, repeats


class PeakRss:
    """Samples this process's resident memory in the background."""

    def __init__(self) -> None:
        self.peak = rss_mib()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(0.02):
            self.peak = max(self.peak, rss_mib())

    def __enter__(self) -> PeakRss:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000_000)
    args = parser.parse_args()
    log, repeats = cached_log(args.frames)

    t0 = time.perf_counter()
    n = 0
    decoder = BatchDecoder(Codec())
    for raw in read_raw_frames(log):
        decoder.decode(raw)
        n += len(raw)
    read_decode = n / (time.perf_counter() - t0)

    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "replay.sqlite"
        plan = paper_plan(str(db), repeats)
        sessions = open_database(sqlite_url(db))
        base = rss_mib()
        with PeakRss() as rss:
            t0 = time.perf_counter()
            result = replay(plan, sessions, [log])
            seconds = time.perf_counter() - t0
        growth = rss.peak - base

    rate = n / seconds
    print(f"log: {log.name}, {n:,} frames, {log.stat().st_size / 2**20:.0f} MiB")
    print(f"read + decode only:            {read_decode:>12,.0f} frames/s")
    print(
        f"replay (read, decode, check, aggregate, store): {rate:,.0f} frames/s "
        f"({seconds:.1f} s; target >= 1,000,000) {'OK' if rate >= 1e6 else 'BELOW TARGET'}"
    )
    print(
        f"campaign {result.outcome}: {result.trials_completed} trials completed, "
        f"{result.trials_failed} failed, {result.observations} observations"
    )
    print(
        f"resident memory: {base:.0f} MiB before, peak {rss.peak:.0f} MiB, growth "
        f"{growth:.1f} MiB (target <= 50) {'OK' if growth <= 50 else 'ABOVE TARGET'}"
    )


if __name__ == "__main__":
    main()
