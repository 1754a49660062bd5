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

from gyrostand.devices.framing import Framer, Received
from gyrostand.devices.nmea0183 import Alarm, Heading, Invalid, Other, RateOfTurn, decode
from gyrostand.devices.source import (
    NO_SEQUENCE,
    UNNUMBERED,
    ByteChunks,
    CampaignClock,
    SourceEvent,
    SourceInfo,
    SourceOutput,
)
from gyrostand.frames.batch import Headings
from gyrostand.stand.protocol import InvalidFrame

PROTOCOL = "iec61162"
SERIAL_ID = 0  # InvalidFrame.arbitration_id of a serial line's pieces (a line has no ids)
BAUD_CHECK_BYTES = 256  # bytes after which a stream with no good sentence is a wrong baud rate
ALARM_KIND = "compass alarm"
WRONG_BAUD_KIND = "wrong baud rate"


def wrong_baud(port: str, baud: int) -> str:
    """The one line naming a port that gives bytes but no sentence."""
    return f"{port}: no NMEA sentences at {baud} baud: wrong baud rate?"


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

    def __init__(self, baud: int, port: str = "serial port", resolution_deg: float = 0.1) -> None:
        self.port = port
        self.baud = baud
        self.info = SourceInfo(
            protocol=PROTOCOL,
            resolution_deg=resolution_deg,
            time_base=(
                f"reception: the first byte of each sentence on {port} at {baud} baud "
                "(read time less its bytes' time on the wire)"
            ),
            sequence=UNNUMBERED,
        )
        self._framer = Framer(baud)
        self._alarms: dict[str, Alarm] = {}  # the last of each alarm, to tell its changes
        self._good_bytes = 0
        self._other_bytes = 0
        self._baud_told = False
        self.kinds: Counter[str] = Counter()  # sentences and junk received, by kind

    @property
    def stats(self) -> LineStats:
        return LineStats(self._good_bytes, self._other_bytes)

    def decode(self, chunks: ByteChunks, clock: CampaignClock) -> SourceOutput:
        pieces: list[Received] = []
        for i, (data, t_s) in enumerate(zip(chunks.data, chunks.t_s.tolist(), strict=True)):
            pieces += self._framer.feed(t_s, data, chunks.start + i)
        return self._output(pieces, len(chunks.data), clock)

    def close(self, clock: CampaignClock) -> SourceOutput:
        """The end of the stream: a sentence cut by it is truncated."""
        return self._output(self._framer.close(), 0, clock)

    def _output(self, pieces: list[Received], n_chunks: int, clock: CampaignClock) -> SourceOutput:
        pos = np.array([p.pos for p in pieces], dtype=np.int64)
        t_ms = clock.to_campaign_ms(pos, np.array([p.time_s for p in pieces], dtype=np.float64))
        rows: list[int] = []
        headings: list[float] = []
        invalid: list[tuple[int, InvalidFrame]] = []
        events: list[SourceEvent] = []
        for i, piece in enumerate(pieces):
            if piece.junk is not None:
                reason: str | None = self._junk(piece)
            else:
                reason = self._take(
                    decode(piece.data), i, int(t_ms[i]), piece, rows, headings, events
                )
            if reason is not None:
                invalid.append((piece.pos, InvalidFrame(SERIAL_ID, reason, piece.data)))
        if self.stats.wrong_baud() and not self._baud_told:
            self._baud_told = True
            last = (int(pos[-1]), int(t_ms[-1])) if pieces else (0, None)
            message = wrong_baud(self.port, self.baud)
            events.append(SourceEvent(*last, WRONG_BAUD_KIND, "error", message))
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

    def _take(
        self,
        decoded: Heading | RateOfTurn | Alarm | Invalid | Other,
        row: int,
        t_ms: int,
        piece: Received,
        rows: list[int],
        headings: list[float],
        events: list[SourceEvent],
    ) -> str | None:
        """Use one decoded sentence; the reason when it gives nothing usable."""
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
            if self._alarms.get(decoded.key) != decoded:
                self._alarms[decoded.key] = decoded
                events.append(
                    SourceEvent(piece.pos, t_ms, ALARM_KIND, decoded.severity, decoded.text)
                )
            return None
        kind = decoded.sentence if isinstance(decoded, Heading) else "ROT"
        self.kinds[kind] += 1
        if decoded.invalid is not None:
            return decoded.invalid
        if isinstance(decoded, Heading):
            assert decoded.heading_deg is not None
            rows.append(row)
            headings.append(decoded.heading_deg)
        return None
