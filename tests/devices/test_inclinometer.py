"""The [inclinometer] heard in the stream beside the stand's frames: CiA 410 TPDO1 slopes and
J1939 SSI2 as roll samples on the campaign clock, in the plan's scale and axis; EMCY, boot-up
and a silence as events; the stand's frames decoded as before."""

from __future__ import annotations

import can
import pytest

from gyrostand.devices.decoder import SourceDecoder, frame_decoder
from gyrostand.devices.nmea2000 import can_id
from gyrostand.frames.batch import BatchDecoder, DeviceEvent, RawFrames, RollSample
from gyrostand.stand.protocol import Codec

CODEC = Codec()


def status(t_ms: int) -> list[can.Message]:
    """A still stand's status at stand time t_ms (received at t_ms: virtual time)."""
    frames = CODEC.encode_status(t_ms, False, 0.0, 0.0, 0.0, 0, 0.0)
    for m in frames:
        m.timestamp = t_ms / 1000.0
    return frames


def tpdo(node: int, x: int, y: int, t_s: float) -> can.Message:
    data = int(x).to_bytes(2, "little", signed=True) + int(y).to_bytes(2, "little", signed=True)
    return can.Message(arbitration_id=0x180 + node, is_extended_id=False, data=data, timestamp=t_s)


def decode(decoder: object, frames: list[can.Message]) -> list[object]:
    assert isinstance(decoder, SourceDecoder)
    batch = decoder.decode(RawFrames.from_messages(0, frames))
    return [x for _, x in batch.others]


def test_cia410_slopes_are_roll_samples_in_the_plans_scale_and_axis() -> None:
    x = frame_decoder(CODEC, inclinometer=("cia410", 4, "x", 0.01))
    y = frame_decoder(CODEC, inclinometer=("cia410", 4, "y", -0.001))
    frames = [*status(1000), tpdo(4, 1234, -250, 1.1), tpdo(5, 7, 7, 1.15), tpdo(4, -3, 9, 1.2)]
    xs = decode(x, frames)
    assert [(s.source, s.t_ms) for s in xs] == [("inclinometer", 1100), ("inclinometer", 1200)]  # type: ignore[attr-defined]
    assert [s.angle_deg for s in xs] == pytest.approx([12.34, -0.03])  # type: ignore[attr-defined]
    ys = decode(y, frames)
    assert [s.angle_deg for s in ys] == pytest.approx([0.25, -0.009])  # type: ignore[attr-defined]
    # the stand's own frames as the plain stand decoder gives them
    plain = BatchDecoder(CODEC).decode(RawFrames.from_messages(0, frames))
    ours = x.decode(RawFrames.from_messages(0, frames))  # type: ignore[union-attr]
    assert ours.statuses.t_ms.tolist() == plain.statuses.t_ms.tolist() == [1000]


def test_emcy_boot_up_and_silence_are_events() -> None:
    decoder = frame_decoder(CODEC, inclinometer=("cia410", 4, "x", 0.01))
    emcy = can.Message(
        arbitration_id=0x84,
        is_extended_id=False,
        timestamp=1.3,
        data=bytes([0x00, 0x50, 0x01, 0, 0, 0, 0, 0]),
    )
    boot = can.Message(arbitration_id=0x704, is_extended_id=False, data=bytes([0]), timestamp=1.0)
    frames = [*status(1000), boot, tpdo(4, 0, 0, 1.1), tpdo(4, 0, 0, 1.2), emcy, tpdo(4, 0, 0, 2.5)]
    events = [x for x in decode(decoder, frames) if isinstance(x, DeviceEvent)]
    assert [(e.kind, e.severity) for e in events] == [
        ("inclinometer", "info"),
        ("inclinometer EMCY", "error"),
        ("inclinometer silence", "warning"),
    ]
    assert "EMCY 0x5000, error register 0x01" in events[1].message
    assert "silent for 1.3 s" in events[2].message  # 1.2 s to 2.5 s, samples every 0.1 s


def test_samples_before_the_first_stand_status_have_no_campaign_time() -> None:
    decoder = frame_decoder(CODEC, inclinometer=("cia410", 4, "x", 0.01))
    found = decode(decoder, [tpdo(4, 100, 0, 0.5), *status(1000), tpdo(4, 200, 0, 1.1)])
    assert found == [RollSample("inclinometer", 1100, 200 * 0.01)]


def test_j1939_ssi2_pitch_and_roll() -> None:
    """SSI2 (PGN 61481): 3 bytes each, 1/32768 deg per bit, offset -250 deg (J1939-71)."""

    def ssi2(pitch_deg: float, roll_deg: float, sa: int, t_s: float) -> can.Message:
        raw = [round((v + 250.0) * 32768) for v in (pitch_deg, roll_deg)]
        data = b"".join(r.to_bytes(3, "little") for r in raw) + bytes(2)
        return can.Message(arbitration_id=can_id(61481, sa, 3), data=data, timestamp=t_s)

    pitch = frame_decoder(CODEC, inclinometer=("j1939", 0xE2, "x", 1.0))
    roll = frame_decoder(CODEC, inclinometer=("j1939", 0xE2, "y", -1.0))
    frames = [*status(1000), ssi2(2.5, -11.25, 0xE2, 1.1), ssi2(-9.0, -9.0, 0xE3, 1.2)]
    assert decode(pitch, frames) == [RollSample("inclinometer", 1100, 2.5)]
    assert decode(roll, frames) == [RollSample("inclinometer", 1100, 11.25)]
    unavailable = ssi2(0, 0, 0xE2, 1.3)
    unavailable.data = bytearray(b"\xff" * 8)
    events = decode(pitch, [*status(1000), unavailable, unavailable])
    assert [type(e).__name__ for e in events] == ["DeviceEvent"]  # told once
