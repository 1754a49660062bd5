"""Stand time of every frame of a stream (virtual time: the raw log's timestamps)."""

from __future__ import annotations

import numpy as np

from gyrostand.frames.batch import FrameBatch
from gyrostand.stand.protocol import ClockFrame


class StreamClock:
    """Stand time of every frame of the stream: its own (heading, status, SIM_CLOCK), else
    that of the last timed frame before it. In virtual time these are the raw log's timestamps,
    so the log does not depend on when frames were received."""

    def __init__(self) -> None:
        self._last_ms = 0

    def times_s(self, batch: FrameBatch, start: int) -> np.ndarray:
        n = batch.end - start
        t_ms = np.full(n, -1, dtype=np.int64)
        t_ms[batch.headings.pos - start] = batch.headings.t_ms
        t_ms[batch.statuses.pos - start] = batch.statuses.t_ms
        for pos, frame in batch.others:
            if isinstance(frame, ClockFrame):
                t_ms[pos - start] = frame.stand_time_ms
        timed = np.where(t_ms >= 0, np.arange(n), -1)
        np.maximum.accumulate(timed, out=timed)
        t_ms = np.where(timed >= 0, t_ms[np.maximum(timed, 0)], self._last_ms)
        if n:
            self._last_ms = int(t_ms[-1])
        return t_ms / 1000.0
