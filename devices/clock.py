"""The campaign clock for sources timed by reception.

The campaign clock is the stand's: every stand status carries the stand time it was sent at,
and the acquisition stamps every frame with its reception time (SocketCAN: the kernel's receive
timestamp; the host clock, shared by all buses and ports). Over the last WINDOW statuses before a
frame (in the stream, so the result does not depend on how the stream is cut into batches:
replay = live):

    rate   = stand time / reception time elapsed since the first status: 1 for a real stand
             (any clock drift, ppm, is within RATE_SNAP of 1 and left to the offset), the
             speedup of a simulated stand in real time (estimated once it ran MIN_SPAN_MS)
    offset = min over the window of (rate x reception ms - stand ms)
             (the clocks' offset plus each status's latency, which is >= 0: the minimum drops
             the latency's jitter, the window follows the clocks' drift)

and a frame received at r ms is at stand time rate x r - offset.

In virtual time on the in-process bus the simulated devices' reception times are their stand
time itself: rate 1, offset 0, and every heading keeps the simulation's time exactly. (Over a real
bus a virtual-time stand's clock bears no relation to reception times: the plan refuses a
reception-timed compass there.)
"""

from __future__ import annotations

import numpy as np

WINDOW = 32  # stand statuses (16 s at the simulated stand's 2 Hz)
# stand time since the first status before a rate is estimated: short, as the headings before
# it are timed at rate 1 (a sped-up stand's then look 1/speedup apart, and the engine learns the
# heading interval from the first ones); the rate's error, latency jitter over this span, shrinks
# as the span grows
MIN_SPAN_MS = 2_000.0
RATE_SNAP = 1e-3  # a rate this close to 1 is 1 (clocks drift by ppm; this is latency jitter)
NO_CLOCK = -1  # campaign time of a frame received before the first stand status

TIME_BASE = (
    "reception time (CAN: SocketCAN kernel timestamps) on the stand clock: rate and offset "
    f"(minimum of reception - stand time) over the last {WINDOW} stand statuses"
)
CIA402_STAND_CLOCK = (
    "the stand clock of a CiA 402 stand, which has none of its own: the master's SYNC count x "
    "cycle_ms (the drive's communication cycle)"
)
CIA402_LIVE_TIME_BASE = (
    "reception time (CAN: SocketCAN kernel timestamps) on the stand clock of a CiA 402 stand: "
    "the master's SYNCs as its statuses (SYNC k at k x cycle_ms), rate and offset (minimum of "
    f"reception - stand time) over the last {WINDOW} SYNCs"
)
VIRTUAL_TIME_BASE = (
    "reception time on the stand clock; virtual time: the simulated compass's frames are "
    "received at their stand time"
)


class ReceptionClock:
    """Reception times -> campaign (stand) clock, from the stand statuses seen so far."""

    def __init__(self, window: int = WINDOW) -> None:
        self.window = window
        self.restart()

    def restart(self) -> None:
        """From no status (also: a new run of the campaign, whose reception times count anew,
        in a CiA 402 stand's raw log, `devices.cia402_log`)."""
        self._pos = np.zeros(0, dtype=np.int64)  # the last statuses: stream positions ...
        self._rx = np.zeros(0)  # ... reception ms
        self._stand = np.zeros(0)  # ... and stand ms
        self._first: tuple[float, float] | None = None  # (reception ms, stand ms) of the first
        self._fit: tuple[np.ndarray, np.ndarray] | None = None  # rate, offset per status

    def observe(self, pos: np.ndarray, stand_ms: np.ndarray, rx_s: np.ndarray) -> None:
        """Take the stand statuses of a batch (stream order)."""
        if self._first is None and len(pos):
            self._first = (float(rx_s[0]) * 1000.0, float(stand_ms[0]))
        keep = -(2 * self.window)
        self._pos = np.concatenate((self._pos[keep:], pos))
        self._rx = np.concatenate((self._rx[keep:], rx_s * 1000.0))
        self._stand = np.concatenate((self._stand[keep:], stand_ms.astype(np.float64)))
        self._fit = None

    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        """Campaign ms of frames at stream positions `pos` received at `rx_s`; NO_CLOCK before
        the first status."""
        n = len(self._pos)
        last = np.searchsorted(self._pos, pos) - 1  # the last status before each frame
        if n == 0:
            return np.full(len(pos), NO_CLOCK, dtype=np.int64)
        rate, offset = self._statuses_fit()
        at = np.maximum(last, 0)
        t_ms = np.round(rate[at] * rx_s * 1000.0 - offset[at]).astype(np.int64)
        return np.where(last >= 0, t_ms, NO_CLOCK)

    def _statuses_fit(self) -> tuple[np.ndarray, np.ndarray]:
        """Rate and offset at each status kept, computed once per `observe` (a live listener
        asks for one frame at a time: ~40 numpy operations a frame otherwise)."""
        if self._fit is not None:
            return self._fit
        assert self._first is not None
        span = self._stand - self._first[1]
        elapsed = self._rx - self._first[0]
        rate = np.where(
            (span >= MIN_SPAN_MS) & (elapsed > 0), span / np.where(elapsed > 0, elapsed, 1), 1.0
        )
        rate = np.where(np.abs(rate - 1.0) < RATE_SNAP, 1.0, rate)
        # offset of status i = min over its window (statuses i-window+1..i, from 0) of
        # (rate_i x rx - stand): once per status, then looked up per frame (a frame's own
        # window costed window x frames, 0.3 us a heading; this window x statuses)
        n = len(self._pos)
        i = np.arange(n)
        offset = np.full(n, np.inf)
        for k in range(min(self.window, n)):
            j = np.maximum(i - k, 0)
            offset = np.minimum(offset, rate * self._rx[j] - self._stand[j])
        self._fit = (rate, offset)
        return self._fit
