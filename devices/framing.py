"""A serial byte stream cut into IEC 61162-1 sentences, each timed by its reception.

A sentence has no time of its own: its time is when its first byte ('$' or '!') went onto the
wire. The port gives chunks of bytes with the time each was read; a UART frames a byte in 10 bits
(start, 8 data, stop: IEC 61162-1 §6.3), so a chunk of n bytes read at r, its last byte just
arrived, had its byte i start on the wire at r - (n - i) * 10 / baud. A sentence split over
chunks takes the time of the chunk holding its first byte.

Bytes that are no sentence are not dropped: a run of bytes outside sentences is "garbage", a
sentence cut short by the next '$' (or by the end of the stream) "truncated", and one with no end
within the standard's 82 characters "overlong"."""

from __future__ import annotations

import re
from dataclasses import dataclass

from gyrostand.devices.nmea0183 import MAX_SENTENCE_BYTES

BITS_PER_BYTE = 10  # start bit, 8 data bits, stop bit (IEC 61162-1 §6.3: 8N1)
_START = re.compile(rb"[$!]")
_START_OR_END = re.compile(rb"[$!\r\n]")
_BODY_MAX = MAX_SENTENCE_BYTES - 2  # without <CR><LF>
_TERMINATORS = b"\r\n"
_JUNK = re.compile(rb"[^\r\n]")
_HOLD_MAX = 4 * MAX_SENTENCE_BYTES  # bytes kept of a sentence with no end yet

GARBAGE = "garbage"
TRUNCATED = "truncated"
OVERLONG = "overlong"
BAD_TAG = "bad-tag-block"  # IEC 61162-450: a TAG block whose checksum is wrong


def byte_time_s(baud: int) -> float:
    """How long one byte takes on the wire."""
    return BITS_PER_BYTE / baud


@dataclass(frozen=True)
class Received:
    """A sentence (from '$' up to its <CR><LF>, excluded) or bytes that are none (`junk` says
    why), with the time its first byte went onto the wire."""

    time_s: float
    data: bytes
    junk: str | None = None


class Framer:
    """Cuts timed chunks of a byte stream into `Received` pieces, across chunk boundaries."""

    def __init__(self, baud: int) -> None:
        self.baud = baud
        self._byte_s = byte_time_s(baud)
        self._sentence: bytearray | None = None  # the sentence being received
        self._sentence_time = 0.0

    def feed(self, read_time_s: float, data: bytes) -> list[Received]:
        """The pieces completed by a chunk read at `read_time_s`."""
        n = len(data)
        out: list[Received] = []
        pos = 0
        while pos < n:
            if self._sentence is None:  # between sentences: line ends are no garbage
                m = _START.search(data, pos)
                end = m.start() if m else n
                junk = _JUNK.search(data, pos, end)
                if junk:
                    garbage = data[junk.start() : end].translate(None, _TERMINATORS)
                    t = self._time(read_time_s, n, junk.start())
                    out.append(Received(t, garbage, GARBAGE))
                if m is None:
                    break
                self._sentence = bytearray(data[end : end + 1])
                self._sentence_time = self._time(read_time_s, n, end)
                pos = end + 1
                continue
            m = _START_OR_END.search(data, pos)
            end = m.start() if m else n
            self._sentence += data[pos:end]
            if m is None:
                if len(self._sentence) > _HOLD_MAX:  # no end in sight: keep memory bounded
                    out.append(self._end(OVERLONG))
                break
            if data[end] in _TERMINATORS:
                out.append(self._end(OVERLONG if len(self._sentence) > _BODY_MAX else None))
                pos = end + 1
            else:  # a new sentence starts before this one ended
                out.append(self._end(TRUNCATED))
                pos = end
        return out

    def close(self) -> list[Received]:
        """The end of the stream: a sentence still being received is truncated."""
        return [] if self._sentence is None else [self._end(TRUNCATED)]

    def _end(self, junk: str | None) -> Received:
        assert self._sentence is not None
        piece = Received(self._sentence_time, bytes(self._sentence), junk)
        self._sentence = None
        return piece

    def _time(self, read_time_s: float, n: int, index: int) -> float:
        """When byte `index` of a chunk of n bytes read at read_time_s started on the wire."""
        return read_time_s - (n - index) * self._byte_s
