"""The stand's CAN frames and a serial compass's bytes as one stream for the engine.

The two arrive on different lines; the engine wants one stream in order. The serial pieces go
between the stand's frames by when they were in (their first byte's time, to the millisecond the
raw log keeps, plus their length on the wire), after the frames of the same time; the stand's
frames keep their own order. A piece later than a batch's last frame waits for the next batch,
so only times decide the order: a replay of the two raw logs, cut into other batches, gives the
same stream. The stand's statuses give the campaign clock (`devices.clock.ReceptionClock`), the
serial source times each sentence on it (`devices.iec61162`)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace

import numpy as np

from gyrostand.devices.clock import ReceptionClock
from gyrostand.devices.framing import Received, byte_time_s
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.source import ByteChunks
from gyrostand.devices.tagblock import reception_ms
from gyrostand.frames.batch import BatchDecoder, FrameBatch, RawFrames
from gyrostand.frames.stream_clock import StreamClock
from gyrostand.stand.protocol import Codec


class SerialSourceDecoder:
    """Stand frames + the serial source's pieces -> one `FrameBatch` per batch of stand frames.

    The pieces come from `take` (the chunks the port has read since the last batch) or, in a
    replay, from `replayed(horizon_us)` (the raw log's pieces up to that time at least).
    `stand_time`: the stand's frames timed by the stand time they carry (virtual time, where it
    is also the serial line's time and the raw log's: `frames.stream_clock`)."""

    def __init__(
        self,
        codec: Codec,
        source: Iec61162Source,
        take: Callable[[], ByteChunks] | None = None,
        *,
        replayed: Callable[[int], Iterable[Received]] | None = None,
        stand_time: bool = False,
    ) -> None:
        self.stand = BatchDecoder(codec)
        self.source = source
        self.take = take
        self.replayed = replayed
        self.clock = ReceptionClock()
        self._stream_clock = StreamClock() if stand_time else None
        self._byte_us = byte_time_s(source.baud) * 1e6
        self._held: list[tuple[int, Received]] = []  # pieces after the last batch's frames
        self.end = 0  # merged stream position of the next frame or piece
        self.frame_pos = np.zeros(0, dtype=np.int64)  # the last batch's frames' positions
        self.pieces: list[Received] = []  # ... and its pieces (for the raw log)
        self.piece_pos = np.zeros(0, dtype=np.int64)

    def _key_us(self, piece: Received) -> int:
        """When a piece was in, us: its logged reception ms plus its bytes' time on the wire."""
        return reception_ms(piece.time_s) * 1000 + round(len(piece.data) * self._byte_us)

    def _arrived(self, horizon_us: int) -> list[Received]:
        if self.replayed is not None:
            return list(self.replayed(horizon_us))
        assert self.take is not None
        chunks = self.take()
        pieces: list[Received] = []
        for data, t_s in zip(chunks.data, chunks.t_s.tolist(), strict=True):
            pieces += self.source.frame(t_s, data)
        return pieces

    def decode(self, raw: RawFrames) -> FrameBatch:
        stand = self.stand.decode(replace(raw, start=0))
        if self._stream_clock is not None:  # (in place: the raw log's timestamps too)
            raw.timestamp[:] = self._stream_clock.times_s(stand, 0)
        n = len(raw)
        latest = np.maximum.accumulate(np.round(raw.timestamp * 1e6).astype(np.int64))
        horizon = int(latest[-1]) if n else -1
        self._held += [(self._key_us(p), p) for p in self._arrived(horizon)]
        self._held.sort(key=lambda kp: kp[0])  # (stable: the line's order at equal times)
        cut = next((i for i, (k, _) in enumerate(self._held) if k >= horizon), len(self._held))
        released, self._held = self._held[:cut], self._held[cut:]
        pieces = [p for _, p in released]
        # piece j goes before frame at[j]: after every frame of its time or earlier
        at = np.searchsorted(latest, np.array([k for k, _ in released], dtype=np.int64), "right")
        piece_pos = self.end + at + np.arange(len(pieces))
        frame_pos = self.end + np.arange(n) + np.searchsorted(at, np.arange(n), "right")
        self.end += n + len(pieces)
        self.frame_pos, self.pieces, self.piece_pos = frame_pos, pieces, piece_pos

        s = stand.statuses
        statuses = replace(s, pos=frame_pos[s.pos])
        self.clock.observe(statuses.pos, s.t_ms, raw.timestamp[s.pos])
        out = self.source.decode_pieces(pieces, self.clock, 0, piece_pos)
        others = [(int(frame_pos[p]), f) for p, f in stand.others]
        others = sorted((*others, *out.invalid, *out.events), key=lambda x: x[0])
        return FrameBatch(out.headings, statuses, tuple(others), self.end)

    @property
    def held(self) -> list[Received]:
        """The pieces waiting for a later frame."""
        return [p for _, p in self._held]

    def frames_before(self, pos: int) -> int:
        """How many of the last batch's frames come before stream position `pos`."""
        return int(np.searchsorted(self.frame_pos, pos))
