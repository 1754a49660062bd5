"""Frames -> `FrameBatch` for a campaign's heading source: the stand's frames by
`frames.batch.BatchDecoder`, the headings by the source's adapter, on one campaign clock."""

from __future__ import annotations

from dataclasses import replace

from gyrostand.devices.cia406 import Cia406Heading, encoder_info
from gyrostand.devices.clock import VIRTUAL_TIME_BASE, ReceptionClock
from gyrostand.devices.n2k_heading import Nmea2000Heading
from gyrostand.devices.source import SourceInfo
from gyrostand.devices.stand_frames import stand_source_info
from gyrostand.frames.batch import BatchDecoder, FrameBatch, RawFrames
from gyrostand.stand.encoder import Encoder
from gyrostand.stand.protocol import Codec


class SourceDecoder:
    """A CAN heading source beside the stand's frames (same stream: one bus, or the merged
    stream of the stand's and the compass's buses)."""

    def __init__(self, codec: Codec, source: Nmea2000Heading | Cia406Heading) -> None:
        self.stand = BatchDecoder(codec)
        self.source = source
        self.clock = ReceptionClock()

    def decode(self, raw: RawFrames) -> FrameBatch:
        claimed = self.source.claims(raw)
        stand = self.stand.decode(raw, skip=claimed)  # (its own heading frames, if any: unused)
        statuses = stand.statuses
        self.clock.observe(statuses.pos, statuses.t_ms, raw.timestamp[statuses.pos - raw.start])
        out = self.source.decode(raw, self.clock)
        others = sorted((*stand.others, *out.invalid, *out.events), key=lambda x: x[0])
        return FrameBatch(out.headings, statuses, tuple(others), stand.end)


def frame_decoder(
    codec: Codec,
    protocol: str = "gyrostand",
    name: str | None = None,
    product: tuple[str, str] | None = None,
    encoder: Encoder | None = None,
) -> BatchDecoder | SourceDecoder:
    """The decoder of a plan's [compass] (`Plan.heading_source`: `name`, NMEA 2000 NAME in
    hexadecimal; `product`, [instrument] model and serial; `encoder`, the CiA 406 encoder)."""
    if protocol in ("gyrostand", "dbc"):
        return BatchDecoder(codec)
    if protocol == "nmea2000":
        wanted = int(name, 16) if name is not None else None
        return SourceDecoder(codec, Nmea2000Heading(wanted, None if wanted else product))
    if protocol == "cia406" and encoder is not None:
        return SourceDecoder(codec, Cia406Heading(encoder))
    raise ValueError(f"heading source {protocol!r} is not runnable yet")


def source_info(
    codec: Codec, protocol: str = "gyrostand", virtual: bool = False, encoder: Encoder | None = None
) -> SourceInfo:
    """What the engine and the campaign record need of the source (`virtual`: a simulated
    stand in virtual time, whose time base is the simulation's; `encoder`: the CiA 406
    encoder, `CompassPlan.encoder()`)."""
    if protocol in ("gyrostand", "dbc"):
        return stand_source_info(codec, protocol)
    if protocol == "nmea2000":
        info = Nmea2000Heading.info
        return replace(info, time_base=VIRTUAL_TIME_BASE) if virtual else info
    if protocol == "cia406" and encoder is not None:
        return encoder_info(encoder, virtual)
    raise ValueError(f"heading source {protocol!r} is not runnable yet")
