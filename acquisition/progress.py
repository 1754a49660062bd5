"""Progress of a campaign on stderr: a live rich display on a terminal; plain lines otherwise
(CI, nohup, a pipe), so that a 15-hour run shows where it is in its log."""

from __future__ import annotations

import json
import math
import os
import statistics
import time
from dataclasses import asdict
from pathlib import Path
from types import TracebackType

import numpy as np
from rich.console import Console
from rich.live import Live
from rich.table import Table

from gyrostand.acquisition.engine import Phase, Snapshot
from gyrostand.db.queries import live_watch_of
from gyrostand.frames.batch import Headings

HEARTBEAT_WALL_S = 60.0  # plain lines: the state again after this long without a line
LIVE_FILE_WALL_S = 0.1  # the live file while a page watches: rewritten at most this often
UNWATCHED_WALL_S = 2.0  # ... while none does (a page's first view, a killed run's last state)
WATCHED_WALL_S = 2.0  # a page watches while the station touched the watch file this recently
LIVE_TRACE_SPAN_MS = 1_200_000  # the live file's heading trace: the last 20 min of stand time
LIVE_TRACE_BUCKETS = 300  # ... as the lowest and highest valid reading of each of these slices


def _duration(seconds: float) -> str:
    seconds = max(0, round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h:d}:{m:02d}:{s:02d}"


def _series(j: int) -> str:
    return f"j={j} ({'before rocking' if j == 1 else 'rocking'})"


class ProgressDisplay:
    """`update(snapshot)` as often as you like. On a terminal the screen refreshes a few times a
    second; otherwise `PlainProgress` writes a line per step; nothing with `quiet`."""

    def __init__(self, *, quiet: bool = False, console: Console | None = None) -> None:
        self.console = console or Console(stderr=True)
        self.enabled = not quiet and self.console.is_terminal
        self.plain = None if quiet or self.enabled else PlainProgress(self.console)
        self._live: Live | None = None
        self._wall0 = time.monotonic()
        self._stand0: int | None = None
        self._last = 0.0

    def __enter__(self) -> ProgressDisplay:
        if self.enabled:
            self._live = Live(console=self.console, refresh_per_second=4, transient=False)
            self._live.__enter__()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._live is not None:
            self._live.__exit__(exc_type, exc, tb)

    def update(self, snap: Snapshot) -> None:
        if self.plain is not None:
            self.plain.update(snap)
        if self._live is None:
            return
        now = time.monotonic()
        if now - self._last < 0.2 and snap.phase is not Phase.DONE:
            return
        self._last = now
        self._live.update(self.render(snap, now))

    def render(self, snap: Snapshot, now: float) -> Table:
        if self._stand0 is None:
            self._stand0 = snap.now_ms
        wall = now - self._wall0
        rate = (snap.now_ms - self._stand0) / 1000 / wall if wall > 0 else 0.0
        table = Table.grid(padding=(0, 2))
        table.add_column(style="bold")
        table.add_column()
        series = "before rocking" if snap.j == 1 else "rocking"
        table.add_row("trial", f"{snap.trial}/{snap.n_trials}")
        table.add_row("series", f"j={snap.j} ({series})")
        table.add_row("observation", f"{snap.k}/{snap.n_obs}")
        table.add_row("phase", snap.phase.value)
        if snap.settle_spread_deg is not None:
            table.add_row("settle", f"window means within +-{snap.settle_spread_deg:.4f} deg")
        if snap.values_deg:
            spread = statistics.stdev(snap.values_deg) if len(snap.values_deg) > 1 else 0.0
            mean = statistics.fmean(snap.values_deg)
            table.add_row("series mean", f"{mean:.4f} deg  (s = {spread:.4f} deg)")
        eta_stand = snap.remaining_ms / 1000
        eta_wall = eta_stand / rate if rate > 0 else float("nan")
        wall_text = _duration(eta_wall) if eta_wall == eta_wall else "?"
        table.add_row("stand time", _duration(snap.now_ms / 1000))
        table.add_row("ETA", f"stand {_duration(eta_stand)}, wall {wall_text}")
        return table


class PlainProgress:
    """Progress as plain lines, for output that is not a terminal. A line when the engine
    enters a phase of a series, per completed observation and when a trial ends; the state
    again after `heartbeat_s` of wall time without a line. Every line ends with the stand time
    and the ETA in stand time: its content depends on the engine's snapshots only, never on the
    wall clock.

    Snapshots come after each batch of frames; in virtual time one batch may hold several
    steps. The observations of a series that the engine left for the next one were all taken
    (it moves on only then) and get their lines; a trial's end is not told apart from a
    failure here (`campaign status` has the outcome)."""

    def __init__(self, console: Console, heartbeat_s: float = HEARTBEAT_WALL_S) -> None:
        self.console = console
        self.heartbeat_s = heartbeat_s
        self._key: tuple[int, int] | None = None  # (trial, j) of the last snapshot
        self._phase: Phase | None = None
        self._done = 0  # observations of that series known to be taken
        self._base = 0  # ... taken before this run (resume)
        self._n_obs = 0
        self._n_trials = 0
        self._last_line = time.monotonic()

    def update(self, snap: Snapshot) -> None:
        key = (snap.trial, snap.j)
        if self._key is not None and key != self._key:
            self._left(snap)
        if snap.phase is Phase.DONE or snap.trial == 0:
            self._key = None
            return
        if key != self._key:
            self._key, self._phase, self._n_obs = key, None, snap.n_obs
            self._n_trials = snap.n_trials
            self._base = max(0, snap.k - 1 - len(snap.values_deg))
            self._done = self._base
        while self._done < self._base + len(snap.values_deg):
            self._observed(snap)
        if snap.phase is not self._phase:
            self._phase = snap.phase
            if snap.phase is not Phase.OBSERVE:
                self._line(f"{self._where()}: {snap.phase.value}", snap)
        elif time.monotonic() - self._last_line >= self.heartbeat_s:
            self._line(f"{self._where()}: {self._state(snap)}", snap)

    def _left(self, snap: Snapshot) -> None:
        """The engine left the series of `_key` (for the next series, or the next trial)."""
        assert self._key is not None
        trial, j = self._key
        if snap.trial == trial and j == 1 and snap.j == 2:
            while self._done < self._n_obs:
                self._observed(snap)
        if snap.trial != trial:
            self._line(f"trial {trial}/{self._n_trials} ended", snap)

    def _observed(self, snap: Snapshot) -> None:
        self._done += 1
        self._line(f"{self._where()}: observation {self._done}/{self._n_obs} done", snap)

    def _where(self) -> str:
        assert self._key is not None
        trial, j = self._key
        return f"trial {trial}/{self._n_trials}, {_series(j)}"

    @staticmethod
    def _state(snap: Snapshot) -> str:
        if snap.phase is Phase.SETTLE and snap.settle_spread_deg is not None:
            return f"settling, window means within +-{snap.settle_spread_deg:.4f} deg"
        if snap.phase is Phase.OBSERVE:
            return f"observing {snap.k}/{snap.n_obs}"
        return snap.phase.value

    def _line(self, text: str, snap: Snapshot) -> None:
        self._last_line = time.monotonic()
        self.console.print(
            f"{text}; stand time {_duration(snap.now_ms / 1000)}, "
            f"ETA stand {_duration(snap.remaining_ms / 1000)}",
            markup=False,
            highlight=False,
            emoji=False,
            soft_wrap=True,
        )


class LiveFile:
    """The engine's latest snapshot as JSON (the `Snapshot` fields, phase as text, the wall
    time and `heading_trace`: [stand s, deg] of the valid headings of the last 20 minutes of
    stand time, lowest and highest of each 4 s slice), rewritten at most every `every_s` of
    wall time by replacing the file (a reader never sees half of it), for the operator station
    to show a running campaign between the database's writes; deleted when the run ends (the
    database then holds everything). A file that cannot be written is given up on: the
    acquisition does not depend on it. Only while a page watches (the station touches the watch
    file, `live_watch_of`) every `every_s`; else every `unwatched_s` (each write costs ~1 ms:
    at 10 a second, 5 % of a campaign in virtual time)."""

    def __init__(
        self, path: Path, every_s: float = LIVE_FILE_WALL_S, unwatched_s: float = UNWATCHED_WALL_S
    ) -> None:
        self.path = path
        self.watch = live_watch_of(path)
        self.every_s = every_s
        self.unwatched_s = unwatched_s
        self._last = -math.inf
        self._failed = False
        self._slice_ms = LIVE_TRACE_SPAN_MS // LIVE_TRACE_BUCKETS
        self._extremes: dict[int, tuple[float, float]] = {}  # slice -> lowest, highest

    def headings(self, headings: Headings) -> None:
        """Fold a batch's valid headings into the trace (vectorised: once per batch)."""
        valid = headings.valid.astype(bool)
        if self._failed or not valid.any():
            return
        order = np.argsort(headings.t_ms[valid], kind="stable")
        slices = headings.t_ms[valid][order] // self._slice_ms
        values = headings.heading_deg[valid][order]
        keys, starts = np.unique(slices, return_index=True)
        lows = np.minimum.reduceat(values, starts)
        highs = np.maximum.reduceat(values, starts)
        for key, low, high in zip(keys.tolist(), lows.tolist(), highs.tolist(), strict=True):
            if key in self._extremes:
                was = self._extremes[key]
                low, high = min(low, was[0]), max(high, was[1])
            self._extremes[key] = (low, high)
        oldest = int(keys[-1]) - LIVE_TRACE_BUCKETS
        for key in [k for k in self._extremes if k <= oldest]:
            del self._extremes[key]

    def _trace(self) -> list[tuple[float, float]]:
        trace = []
        for key in sorted(self._extremes):
            t_s = (key + 0.5) * self._slice_ms / 1000
            low, high = self._extremes[key]
            trace += [(t_s, low), (t_s, high)] if high > low else [(t_s, low)]
        return trace

    def update(self, snap: Snapshot) -> None:
        now = time.monotonic()
        if self._failed or now - self._last < self.every_s:
            return
        if now - self._last < self.unwatched_s and not self._watched():
            return
        self._last = now
        record = {
            **asdict(snap),
            "phase": snap.phase.value,
            "wall_time": time.time(),
            "heading_trace": self._trace(),
        }
        tmp = self.path.with_suffix(".tmp")
        try:
            tmp.write_text(json.dumps(record), encoding="utf-8")
            os.replace(tmp, self.path)
        except OSError:
            self._failed = True

    def _watched(self) -> bool:
        try:
            return time.time() - self.watch.stat().st_mtime < WATCHED_WALL_S
        except OSError:
            return False

    def close(self) -> None:
        self.path.unlink(missing_ok=True)
        self.path.with_suffix(".tmp").unlink(missing_ok=True)
        self.watch.unlink(missing_ok=True)
