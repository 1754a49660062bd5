"""The heading source "gyrostand" / "dbc": the heading frame of the stand's own DBC (shipped or
the lab's), decoded by `frames.batch.BatchDecoder` with the stand's frames. It carries the stand's
clock and a 4-bit counter, so its headings are on the campaign clock as they come."""

from __future__ import annotations

from gyrostand.devices.source import COUNTER_4BIT, SourceInfo
from gyrostand.stand.protocol import Codec

STAND_CLOCK = "stand clock carried in every heading frame"


def stand_source_info(codec: Codec, protocol: str = "gyrostand") -> SourceInfo:
    """The heading frame's resolution is its DBC signal's scale."""
    ref = codec.signal_map.heading
    signal = codec.database.get_message_by_name(ref.message).get_signal_by_name(ref.signal)
    return SourceInfo(protocol, float(signal.scale), STAND_CLOCK, COUNTER_4BIT)


GYROSTAND = SourceInfo("gyrostand", 0.001, STAND_CLOCK, COUNTER_4BIT)  # the shipped DBC's
