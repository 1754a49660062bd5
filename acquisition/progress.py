"""Live progress of a campaign on the terminal (rich), silent when stderr is not a terminal."""

from __future__ import annotations

import statistics
import time
from types import TracebackType

from rich.console import Console
from rich.live import Live
from rich.table import Table

from gyrostand.acquisition.engine import Phase, Snapshot


def _duration(seconds: float) -> str:
    seconds = max(0, round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h:d}:{m:02d}:{s:02d}"


class ProgressDisplay:
    """`update(snapshot)` as often as you like; the screen refreshes a few times a second."""

    def __init__(self, *, quiet: bool = False, console: Console | None = None) -> None:
        self.console = console or Console(stderr=True)
        self.enabled = not quiet and self.console.is_terminal
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
