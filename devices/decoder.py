"""Frames -> `FrameBatch` for a campaign's heading source (and inclinometer): the stand's frames
by `frames.batch.BatchDecoder`, the headings by the source's adapter, the inclinometer's roll
samples by `devices.inclinometer`, on one campaign clock."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gyrostand.devices.cia406 import Cia406Heading, encoder_info
from gyrostand.devices.clock import (
    CIA402_LIVE_TIME_BASE,
    CIA402_STAND_CLOCK,
    VIRTUAL_TIME_BASE,
    ReceptionClock,
)
from gyrostand.devices.inclinometer import InclinometerDecoder, Mount
from gyrostand.devices.n2k_heading import Nmea2000Heading
from gyrostand.devices.source import SourceInfo
from gyrostand.devices.stand_frames import stand_source_info
from gyrostand.frames.batch import COMPASS_BUS, BatchDecoder, FrameBatch, RawFrames
from gyrostand.stand.encoder import Encoder
from gyrostand.stand.protocol import Codec


class SourceDecoder:
    """A CAN heading source and/or an inclinometer beside the stand's frames (same stream: one
    bus, or the merged stream of the stand's and the compass's buses, `own_bus`: then every
    frame of the compass's bus is the source's or nobody's, but its error frames, which count
    as the stand's do); without a heading source the headings are the stand DBC's."""

    def __init__(
        self,
        codec: Codec,
        source: Nmea2000Heading | Cia406Heading | None,
        inclinometer: InclinometerDecoder | None = None,
        own_bus: bool = False,
    ) -> None:
        self.stand = BatchDecoder(codec)
        self.own_bus = own_bus
        self.source = source
        self.inclinometer = inclinometer
        self.clock = ReceptionClock()

    def decode(self, raw: RawFrames) -> FrameBatch:
        claimed = np.zeros(len(raw), dtype=bool)
        if self.own_bus:  # (the inclinometer is on the stand's bus)
            claimed |= (raw.channel == COMPASS_BUS) & ~raw.is_error
        mine = None if self.source is None else self.source.claims(raw)  # (computed once)
        if mine is not None:
            claimed |= mine
        if self.inclinometer is not None:
            claimed |= self.inclinometer.claims(raw)
        stand = self.stand.decode(raw, skip=claimed)  # (its own heading frames, if any: unused)
        statuses = stand.statuses
        self.clock.observe(statuses.pos, statuses.t_ms, raw.timestamp[statuses.pos - raw.start])
        headings, others = stand.headings, list(stand.others)
        if self.source is not None:
            out = self.source.decode(raw, self.clock, mine)
            headings = out.headings
            others += [*out.invalid, *out.events]
        if self.inclinometer is not None:
            others += self.inclinometer.decode(raw, self.clock)
        others.sort(key=lambda x: x[0])
        return FrameBatch(headings, statuses, tuple(others), stand.end)


def frame_decoder(
    codec: Codec,
    protocol: str = "gyrostand",
    name: str | None = None,
    product: tuple[str, str] | None = None,
    encoder: Encoder | None = None,
    inclinometer: tuple[str, int, str, float] | None = None,
    own_bus: bool = False,
) -> BatchDecoder | SourceDecoder:
    """The decoder of a plan's [compass] (`Plan.heading_source`: `name`, NMEA 2000 NAME in
    hexadecimal; `product`, [instrument] model and serial; `encoder`, the CiA 406 encoder;
    `own_bus`, on a CAN bus of its own, `RawFrames.channel` COMPASS_BUS) and [inclinometer]
    (`Plan.inclinometer_mount`)."""
    sensor = None if inclinometer is None else InclinometerDecoder(Mount(*inclinometer))
    if protocol in ("gyrostand", "dbc"):
        return BatchDecoder(codec) if sensor is None else SourceDecoder(codec, None, sensor)
    bus = COMPASS_BUS if own_bus else None
    if protocol == "nmea2000":
        wanted = int(name, 16) if name is not None else None
        source = Nmea2000Heading(wanted, None if wanted else product, bus)
        return SourceDecoder(codec, source, sensor, own_bus)
    if protocol == "cia406" and encoder is not None:
        return SourceDecoder(codec, Cia406Heading(encoder, bus), sensor, own_bus)
    raise ValueError(f"heading source {protocol!r} is not runnable yet")


def source_info(
    codec: Codec,
    protocol: str = "gyrostand",
    virtual: bool = False,
    stand: str = "gyrostand",
    encoder: Encoder | None = None,
) -> SourceInfo:
    """What the engine and the campaign record need of the source (`virtual`: a simulated
    stand in virtual time, whose time base is the simulation's; `stand`: the plan's [stand]
    protocol, whose clock is the campaign's; `encoder`: the CiA 406 encoder,
    `CompassPlan.encoder()`)."""
    if protocol in ("gyrostand", "dbc"):
        return stand_source_info(codec, protocol)
    if protocol == "nmea2000":
        info = Nmea2000Heading.info
        base = VIRTUAL_TIME_BASE if virtual else info.time_base
        if stand == "cia402":
            base = f"{base if virtual else CIA402_LIVE_TIME_BASE}; {CIA402_STAND_CLOCK}"
        return replace(info, time_base=base)
    if protocol == "cia406" and encoder is not None:
        return encoder_info(encoder, virtual)
    raise ValueError(f"heading source {protocol!r} is not runnable yet")
