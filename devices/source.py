"""The interface every heading source adapter implements.

A heading source is a compass as the acquisition hears it: gyrostand's own heading frame
("gyrostand", "dbc"), NMEA 2000 PGN 127250 ("nmea2000"), IEC 61162 sentences ("iec61162"), a
CiA 406 encoder ("cia406"). Its adapter turns the source's native input into the arrays the
engine already consumes:

    native input                     adapter.decode(...)            -> SourceOutput
    CAN frames    (`RawFrames`)          |  headings: `Headings` on the campaign clock
    serial bytes  (`ByteChunks`)         |  invalid:  (stream position, `InvalidFrame`) per unusable
                                         |            message, its reason in one line
                                         |  events:   what the device tells besides headings
                                         |  claimed:  which input rows were the source's

so the engine, the store and the read side stay protocol-agnostic. The rules:

- `Headings.t_ms` is the CAMPAIGN clock (the stand's clock, ms). A source that carries the
  stand's time (gyrostand) gives it as is; one that carries no time is timed by reception
  (`SourceInfo.time_base` says which) and converted with a `CampaignClock`.
- `Headings.counter` follows `SourceInfo.sequence`: values in [0, modulo), or `NO_SEQUENCE`
  (-1) for a message without a sequence number (NMEA 2000 SID 255; every sentence of a serial
  source). Gaps next to such a message are judged from time only.
- Nothing is dropped silently: every message of the source that gives no valid heading is an
  `InvalidFrame` in `invalid` (with `valid` False headings for a "not valid" flag the engine
  counts itself); messages of other devices are not the source's (`claimed` False).
- `decode` never raises on bad input; state carried between calls (fast-packet reassembly,
  address claims, a serial line cut between chunks) lives in the adapter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from gyrostand.frames.batch import DeviceEvent, Headings, RawFrames
from gyrostand.stand.protocol import InvalidFrame

NO_SEQUENCE = -1  # Headings.counter of a message without a sequence number


@dataclass(frozen=True)
class SequenceRule:
    """How consecutive messages are numbered: `modulo` values 0..modulo-1 rolling over, or
    None (no numbering: gaps from time only)."""

    modulo: int | None
    description: str


COUNTER_4BIT = SequenceRule(16, "4-bit counter")
SID = SequenceRule(253, "SID (0-252; 255 = none)")
UNNUMBERED = SequenceRule(None, "no sequence number")


@dataclass(frozen=True)
class SourceInfo:
    """What the analysis and the report state about a heading source."""

    protocol: str  # the plan's [compass] protocol
    resolution_deg: float  # one step of the transmitted heading
    time_base: str  # how headings are timed, one line (stored with the campaign)
    sequence: SequenceRule
    silence: str = "bus silence"  # what no heading at all is, naming where it should come from


@dataclass(frozen=True)
class ByteChunks:
    """Timed byte chunks of a serial source: chunk i arrived at `t_s[i]` (host clock, s; the
    first byte's read time); `start` is the stream position of the first chunk."""

    start: int
    data: tuple[bytes, ...]
    t_s: np.ndarray


@dataclass(frozen=True)
class SourceOutput:
    headings: Headings
    invalid: tuple[tuple[int, InvalidFrame], ...]
    events: tuple[tuple[int, DeviceEvent], ...]  # (stream position, event)
    claimed: np.ndarray  # bool per input row (frame or chunk): the source's own


class CampaignClock(Protocol):
    """Reception times (host clock, s) of stream positions -> campaign clock (ms); positions
    before the clock is known give -1."""

    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray: ...


class HeadingSource(Protocol):
    info: SourceInfo

    def decode(self, raw: RawFrames, clock: CampaignClock) -> SourceOutput:
        """A CAN source's frames (a serial source takes `ByteChunks` instead)."""
        ...
