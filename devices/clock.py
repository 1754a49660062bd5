"""The campaign clock for sources timed by reception.

The campaign clock is the stand's: every stand status carries the stand time it was sent at,
and the acquisition stamps every frame with its reception time (SocketCAN: the kernel's receive
timestamp; the host clock, shared by all buses and ports). For each stand status,

    offset = reception ms - stand ms  (= the clocks' offset + the status's latency, >= the offset)

and a heading received at r ms is at stand time r - offset, with the offset the smallest of the
last WINDOW statuses before it (the minimum drops the latency's jitter; a window, not all, so
that the two clocks' drift is followed). Statuses only from before the heading in the stream,
so the result does not depend on how the stream is cut into batches (replay = live).

In virtual time the simulated devices' reception times are the stand time itself: the offset is
0 and every heading keeps the simulation's time exactly.
"""

from __future__ import annotations

import numpy as np

WINDOW = 32  # stand statuses (16 s at the simulated stand's 2 Hz)
NO_CLOCK = -1  # campaign time of a frame received before the first stand status

TIME_BASE = (
    "reception time (CAN: SocketCAN kernel timestamps) on the stand clock, offset = minimum of "
    f"(reception - stand time) over the last {WINDOW} stand statuses"
)
VIRTUAL_TIME_BASE = (
    "reception time on the stand clock; virtual time: the simulated compass's frames are "
    "received at their stand time"
)


class ReceptionClock:
    """Reception times -> campaign (stand) clock, from the stand statuses seen so far."""

    def __init__(self, window: int = WINDOW) -> None:
        self.window = window
        self._pos = np.zeros(0, dtype=np.int64)  # the last statuses: stream positions ...
        self._offset = np.zeros(0)  # ... and (reception - stand time), ms

    def observe(self, pos: np.ndarray, stand_ms: np.ndarray, rx_s: np.ndarray) -> None:
        """Take the stand statuses of a batch (stream order)."""
        self._pos = np.concatenate((self._pos[-(2 * self.window) :], pos))
        self._offset = np.concatenate((self._offset[-(2 * self.window) :], rx_s * 1000 - stand_ms))

    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        """Campaign ms of frames at stream positions `pos` received at `rx_s`; NO_CLOCK before
        the first status."""
        last = np.searchsorted(self._pos, pos) - 1  # the last status before each frame
        smallest = self._offset.copy()  # over the window ending at each status
        for k in range(1, self.window):
            smallest[k:] = np.minimum(smallest[k:], self._offset[:-k])
        offset = smallest[np.maximum(last, 0)] if len(smallest) else np.zeros(len(pos))
        t_ms = np.round(rx_s * 1000 - offset).astype(np.int64)
        return np.where(last >= 0, t_ms, NO_CLOCK)
