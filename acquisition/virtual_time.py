"""The controller's side of virtual time (`stand.virtual_time`): SIM_SYNC frames that let the
simulated stand run ahead by a fixed lead of what has been processed (the stream times that make
the raw log's timestamps depend on the stream alone: `frames.stream_clock`)."""

from __future__ import annotations

import time

import can

from gyrostand.stand.virtual_time import DEFAULT_LEAD_MS, encode_sync

RESEND_WALL_S = 0.5  # idle: repeat the last SIM_SYNC (a stand process started after us)


class Grants:
    """Sends SIM_SYNC: before every command (which then takes effect at processed + lead) and
    whenever the processed stand time has moved on."""

    def __init__(self, bus: can.BusABC, lead_ms: int = DEFAULT_LEAD_MS, start_ms: int = 0) -> None:
        """`start_ms`: the stand clock where the run starts (`Engine`'s `start_ms`)."""
        self.bus = bus
        self.lead_ms = lead_ms
        self.start_ms = start_ms
        self._sent_ms: int | None = None
        self._sent_wall = 0.0

    def sync(self, processed_ms: int) -> None:
        """Tell the stand how far the stream has been processed (always sent)."""
        self.bus.send(encode_sync(processed_ms, self.lead_ms))
        self._sent_ms, self._sent_wall = processed_ms, time.monotonic()

    def progress(self, processed_ms: int) -> None:
        """After a batch: let the stand run on when the processed time advanced."""
        if self._sent_ms is None or processed_ms > self._sent_ms:
            self.sync(processed_ms)

    def idle(self) -> None:
        """Nothing arrived: repeat the last SIM_SYNC now and then (it changes nothing for a
        stand that already has it)."""
        if time.monotonic() - self._sent_wall >= RESEND_WALL_S:
            self.sync(self.start_ms if self._sent_ms is None else self._sent_ms)
