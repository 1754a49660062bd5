"""The stand's CAN frames and a serial compass's bytes as one stream for the engine.

The two arrive on different lines; the engine wants one stream in order. Each batch merges the
stand's frames (by reception time) and the serial pieces (by when their last byte was in: their
first byte's time plus their length on the wire) into one numbering, stand frames first at
equal times. The stand's statuses
give the campaign clock (`devices.clock.ReceptionClock`), the serial source times each sentence
on it (`devices.iec61162`). Only times decide the order, so a replay of the two raw logs cut
into other batches gives the same stream."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gyrostand.devices.clock import ReceptionClock
from gyrostand.devices.framing import Received, byte_time_s
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.source import ByteChunks
from gyrostand.frames.batch import BatchDecoder, FrameBatch, RawFrames
from gyrostand.stand.protocol import Codec


class SerialSourceDecoder:
    """Stand frames + the serial source's chunks (`take`: what the port has read since the
    last batch) -> one `FrameBatch` per batch of stand frames."""

    def __init__(
        self, codec: Codec, source: Iec61162Source, take: Callable[[], ByteChunks]
    ) -> None:
        self.stand = BatchDecoder(codec)
        self.source = source
        self.take = take
        self.clock = ReceptionClock()
        self._next = 0  # merged stream position of the next frame or piece

    def decode(self, raw: RawFrames) -> FrameBatch:
        chunks = self.take()
        pieces: list[Received] = []
        for data, t_s in zip(chunks.data, chunks.t_s.tolist(), strict=True):
            pieces += self.source.frame(t_s, data)
        byte_s = byte_time_s(self.source.baud)  # when each piece was in, however chunks cut it
        done = [p.time_s + len(p.data) * byte_s for p in pieces]
        n, m = len(raw), len(pieces)
        order = np.argsort(np.concatenate((raw.timestamp, np.array(done))), kind="stable")
        merged = np.empty(n + m, dtype=np.int64)
        merged[order] = np.arange(self._next, self._next + n + m)
        frame_pos, piece_pos = merged[:n], merged[n:]
        self._next += n + m

        stand = self.stand.decode(replace(raw, start=0))
        s = stand.statuses
        statuses = replace(s, pos=frame_pos[s.pos])
        self.clock.observe(statuses.pos, s.t_ms, raw.timestamp[s.pos])
        out = self.source.decode_pieces(pieces, self.clock, len(chunks.data), piece_pos)
        others = [(int(frame_pos[p]), f) for p, f in stand.others]
        others = sorted((*others, *out.invalid, *out.events), key=lambda x: x[0])
        return FrameBatch(out.headings, statuses, tuple(others), self._next)
