"""The batch decoder gives the same frames, in the same stream order, as decoding every frame
with `stand.protocol.Codec` one at a time, including broken frames."""

import random

import can
import numpy as np
from crccheck.crc import Crc8SaeJ1850

from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.stand.protocol import (
    Codec,
    CompassStatusFrame,
    HeadingFrame,
    StandStatusFrame,
    crc8_sae_j1850_rows,
)


def random_stream(seed: int, n: int) -> list[can.Message]:
    rng = random.Random(seed)
    codec = Codec()
    out: list[can.Message] = []
    for i in range(n):
        kind = rng.random()
        t = 1000 + 100 * i
        if kind < 0.6:
            msg = codec.encode_heading(
                t, rng.uniform(0, 359.999), rng.random() > 0.1, i % 16, strict=True
            )
        elif kind < 0.8:
            rocking = rng.random() > 0.5
            out.extend(
                codec.encode_status(
                    t, rocking, rng.uniform(0, 359), rng.uniform(0, 30), rng.uniform(0, 9), i, 0
                )
            )
            continue
        elif kind < 0.85:
            msg = codec.encode_ack("start", False, "busy: stop rocking first", seq=i % 16)
        elif kind < 0.88:
            msg = codec.encode_compass_status(rng.random() > 0.3, 40.0, rng.choice([0, 0, 4]))
        elif kind < 0.92:  # corrupt heading payload: one flipped bit
            msg = codec.encode_heading(t, 10.0, True, i % 16)
            msg.data[rng.randrange(8)] ^= 1 << rng.randrange(8)
        elif kind < 0.94:  # out-of-range heading, its CRC good (bad CRCs are corrupt first)
            msg = codec.encode_heading(t, 500.0, True, i % 16, strict=False)
        elif kind < 0.96:  # wrong length
            msg = codec.encode_heading(t, 10.0, True, i % 16)
            msg.data = msg.data[:6]
            msg.dlc = 6
        elif kind < 0.98:
            msg = can.Message(arbitration_id=0x20000080, is_error_frame=True, data=bytes(8))
        else:
            msg = can.Message(arbitration_id=0x7AB, data=bytes(8))  # not ours
        out.append(msg)
    return out


def healthy_compass(frame: object) -> bool:
    """A compass status without a fault carries nothing for acquisition: not passed on."""
    return isinstance(frame, CompassStatusFrame) and frame.rotor_running and not frame.fault_bits


def as_comparable(frame: object) -> object:
    if isinstance(frame, StandStatusFrame):
        f = frame
        return ("status", f.stand_time_ms, f.rocking, f.direction_deg, f.amplitude_cm, f.period_s)
    return frame


def test_batches_equal_codec_frame_by_frame() -> None:
    messages = random_stream(7, 3000)
    codec = Codec()
    expected = [
        as_comparable(f)
        for m in messages
        if (f := codec.decode(m)) is not None and not healthy_compass(f)
    ]

    decoder = BatchDecoder(Codec())
    got: list[tuple[int, object]] = []
    start = 0
    for size in (1, 7, 500, 10_000):  # batch boundaries must not matter
        chunk = messages[start : start + size]
        batch = decoder.decode(RawFrames.from_messages(start, chunk))
        h = batch.headings
        for i in range(len(h)):
            frame = HeadingFrame(
                int(h.t_ms[i]), float(h.heading_deg[i]), bool(h.valid[i]), int(h.counter[i])
            )
            got.append((int(h.pos[i]), frame))
        s = batch.statuses
        got.extend((int(s.pos[i]), as_comparable(s.frame(i))) for i in range(len(s)))
        got.extend(batch.others)
        start += len(chunk)
    assert start == len(messages)
    got.sort(key=lambda item: item[0])
    assert [frame for _, frame in got] == expected
    assert any("CRC" in getattr(f, "reason", "") for f in expected)
    assert any("outside" in getattr(f, "reason", "") for f in expected)


def test_vectorised_crc_matches_crccheck() -> None:
    data = np.random.default_rng(3).integers(0, 256, (200, 8), dtype=np.uint8)
    assert crc8_sae_j1850_rows(data).tolist() == [Crc8SaeJ1850.calc(bytes(r)) for r in data]
