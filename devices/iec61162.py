"""The IEC 61162-1 (NMEA 0183) heading source: timed serial byte chunks -> `SourceOutput`.

Headings come from HDT or THS (mode A only) of any talker; every sentence or run of bytes that
gives no valid heading is an `InvalidFrame` with its reason (checksum, empty or missing field,
THS mode, garbage, truncated, overlong); alarms (ALR, ALF, HBT, proprietary $P...) become events
when they change. A serial line carries no counter: gaps are judged from time only. A stream
with no good sentence in its first bytes is named as a wrong baud rate."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from gyrostand.devices.clock import NO_CLOCK, WINDOW
from gyrostand.devices.framing import Framer, Received
from gyrostand.devices.nmea0183 import Alarm, Heading, Invalid, Other, decode
from gyrostand.devices.source import (
    NO_SEQUENCE,
    UNNUMBERED,
    ByteChunks,
    CampaignClock,
    SourceInfo,
    SourceOutput,
)
from gyrostand.devices.tagblock import TagBlockWriter, reception_ms
from gyrostand.frames.batch import DeviceEvent, Headings
from gyrostand.stand.protocol import InvalidFrame

PROTOCOL = "iec61162"
SERIAL_ID = 0  # InvalidFrame.arbitration_id of a serial line's pieces (a line has no ids)
BAUD_CHECK_BYTES = 256  # bytes after which a stream with no good sentence is a wrong baud rate
ALARM_KIND = "compass alarm"
WRONG_BAUD_KIND = "wrong baud rate"


def wrong_baud(port: str, baud: int) -> str:
    """The one line naming a port that gives bytes but no sentence."""
    return f"serial port {port}: no NMEA sentences at {baud} baud: wrong baud rate?"


@dataclass(frozen=True)
class LineStats:
    """What a serial line has given so far, in bytes: inside sentences with a good checksum,
    and everything else."""

    good_bytes: int
    other_bytes: int

    def wrong_baud(self) -> bool:
        """Bytes enough to hold several sentences, none of them good."""
        return self.good_bytes == 0 and self.other_bytes >= BAUD_CHECK_BYTES


class Iec61162Source:
    """One serial heading source; `decode` takes its chunks in stream order."""

    def __init__(
        self,
        baud: int,
        port: str = "(unnamed)",
        resolution_deg: float = 0.1,
        raw_log: TagBlockWriter | None = None,
    ) -> None:
        self.port = port
        self.raw_log = raw_log
        self.baud = baud
        self.info = SourceInfo(
            protocol=PROTOCOL,
            resolution_deg=resolution_deg,
            time_base=(
                f"reception of each sentence's first byte ({port}, {baud} baud: read time less "
                "its bytes' time on the wire) on the stand clock, offset = minimum of "
                f"(reception - stand time) over the last {WINDOW} stand statuses"
            ),
            sequence=UNNUMBERED,
            silence=f"serial port {port} silent",
        )
        self._framer = Framer(baud)
        self._alarms: dict[str, Alarm] = {}  # the last of each alarm, to tell its changes
        self._good_bytes = 0
        self._other_bytes = 0
        self._baud_told = False
        self._next_pos = 0  # stream position of the next piece: pieces are numbered
        self.kinds: Counter[str] = Counter()  # sentences and junk received, by kind

    @property
    def stats(self) -> LineStats:
        return LineStats(self._good_bytes, self._other_bytes)

    def decode(self, chunks: ByteChunks, clock: CampaignClock) -> SourceOutput:
        """Chunks read from the port (`ByteChunks.t_s`: when each read returned)."""
        pieces: list[Received] = []
        for data, t_s in zip(chunks.data, chunks.t_s.tolist(), strict=True):
            pieces += self.frame(t_s, data)
        return self.decode_pieces(pieces, clock, len(chunks.data))

    def frame(self, read_time_s: float, data: bytes) -> list[Received]:
        """The pieces a chunk read at `read_time_s` completes (to `decode_pieces` next)."""
        return self._framer.feed(read_time_s, data)

    def close(self, clock: CampaignClock) -> SourceOutput:
        """The end of the stream: a sentence cut by it is truncated."""
        return self.decode_pieces(self.close_pieces(), clock)

    def close_pieces(self) -> list[Received]:
        """The end of the stream, framed: a sentence cut by it is truncated."""
        return self._framer.close()

    def decode_pieces(
        self,
        pieces: list[Received],
        clock: CampaignClock,
        n_chunks: int = 0,
        positions: np.ndarray | None = None,
    ) -> SourceOutput:
        """Framed pieces, as `decode` makes them or a raw log gives them back (replay).

        A piece's stream position is its number on the line (every sentence and every run of
        junk counts), the line number in the raw log, unless `positions` (a stream merged with
        the stand's) gives it; its reception time is rounded to the millisecond the raw log
        keeps, so a replay times everything as the live run did."""
        if self.raw_log is not None:
            self.raw_log.write(pieces)
        pos = np.arange(self._next_pos, self._next_pos + len(pieces), dtype=np.int64)
        self._next_pos += len(pieces)
        if positions is not None:
            pos = np.asarray(positions, dtype=np.int64)
        rx_ms = np.array([reception_ms(p.time_s) for p in pieces], dtype=np.int64)
        t_ms = clock.to_campaign_ms(pos, rx_ms / 1000.0)
        rows: list[int] = []
        headings: list[float] = []
        invalid: list[tuple[int, InvalidFrame]] = []
        events: list[tuple[int, DeviceEvent]] = []
        for i, piece in enumerate(pieces):
            result = self._junk(piece) if piece.junk is not None else self._take(piece)
            if isinstance(result, float) and t_ms[i] == NO_CLOCK:
                reason = "heading received before the stand's first status (no clock)"
                invalid.append((int(pos[i]), InvalidFrame(SERIAL_ID, reason, piece.data)))
            elif isinstance(result, float):
                rows.append(i)
                headings.append(result)
            elif isinstance(result, Alarm):
                events.append((int(pos[i]), DeviceEvent(ALARM_KIND, result.severity, result.text)))
            elif result is not None:
                invalid.append((int(pos[i]), InvalidFrame(SERIAL_ID, result, piece.data)))
        if self.stats.wrong_baud() and not self._baud_told:
            self._baud_told = True
            message = wrong_baud(self.port, self.baud)
            last = int(pos[-1]) if pieces else 0
            events.append((last, DeviceEvent(WRONG_BAUD_KIND, "error", message)))
        index = np.array(rows, dtype=np.int64)
        out = Headings(
            pos=pos[index],
            t_ms=t_ms[index].astype(np.int64),
            heading_deg=np.array(headings, dtype=np.float64),
            valid=np.ones(len(index), dtype=bool),
            counter=np.full(len(index), NO_SEQUENCE, dtype=np.int64),
        )
        return SourceOutput(out, tuple(invalid), tuple(events), np.ones(n_chunks, dtype=bool))

    def _junk(self, piece: Received) -> str:
        """Why a piece of junk is no sentence."""
        assert piece.junk is not None
        self.kinds[piece.junk] += 1
        self._other_bytes += len(piece.data)
        return f"{piece.junk} bytes ({len(piece.data)})"

    def _take(self, piece: Received) -> float | Alarm | str | None:
        """One sentence: its valid heading, an alarm that changed (an event), why it gives
        nothing usable, or None (a valid sentence that is not a heading)."""
        decoded = decode(piece.data)
        if isinstance(decoded, Invalid):
            self.kinds["invalid"] += 1
            self._other_bytes += len(piece.data)
            return decoded.reason
        self._good_bytes += len(piece.data)
        if isinstance(decoded, Other):
            self.kinds[decoded.sentence] += 1
            return None
        if isinstance(decoded, Alarm):
            self.kinds["alarm"] += 1
            if self._alarms.get(decoded.key) == decoded:
                return None
            self._alarms[decoded.key] = decoded
            return decoded
        self.kinds[decoded.sentence if isinstance(decoded, Heading) else "ROT"] += 1
        if decoded.invalid is not None:
            return decoded.invalid
        return decoded.heading_deg if isinstance(decoded, Heading) else None
