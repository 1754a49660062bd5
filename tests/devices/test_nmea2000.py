"""The bulk NMEA 2000 reading against the reference codec (`nmea2000`, canboat) on many frames:
random payloads (not-available and out-of-range values among them), random identifiers."""

from __future__ import annotations

import math

import can
import numpy as np
import pytest
from nmea2000 import NMEA2000Decoder
from nmea2000.decoder import DecoderStaticsMixin

from gyrostand.devices.nmea2000 import (
    ATTITUDE,
    RATE_OF_TURN,
    VESSEL_HEADING,
    Product,
    ReferenceDecoder,
    ReferenceEncoder,
    can_id,
    decode_attitude,
    decode_rate_of_turn,
    decode_vessel_heading,
    encode_attitude,
    encode_rate_of_turn,
    encode_vessel_heading,
    iso_name,
    split_id,
)
from gyrostand.devices.source import NO_SEQUENCE

N = 3000


def payloads(rng: np.random.Generator) -> np.ndarray:
    """Random payloads, a third with each 16-bit field forced to its top values."""
    data = rng.integers(0, 256, (N, 8), dtype=np.uint8)
    top = rng.random((N, 4)) < 0.3
    for k, at in enumerate((1, 3, 5)):
        rows = np.flatnonzero(top[:, k])
        data[rows, at] = rng.choice([0xFC, 0xFD, 0xFE, 0xFF], len(rows))
        data[rows, at + 1] = rng.choice([0x7F, 0xFF], len(rows))
    return data


def reference(pgn: int, data: np.ndarray) -> list[dict[str, object]]:
    decoder = NMEA2000Decoder()
    out = []
    for row in data:
        msg = can.Message(arbitration_id=can_id(pgn, 35, 2), is_extended_id=True, data=bytes(row))
        decoded = decoder.decode(msg)
        assert decoded is not None
        out.append({f.id: f.raw_value for f in decoded.fields})
    return out


def same(mine: np.ndarray, theirs: list[object]) -> None:
    expected = np.array([np.nan if v is None else float(v) for v in theirs])  # type: ignore[arg-type]
    np.testing.assert_array_equal(np.isnan(mine), np.isnan(expected))
    ok = ~np.isnan(expected)
    np.testing.assert_allclose(mine[ok], expected[ok], rtol=0, atol=1e-12)


def agrees(mine: np.ndarray, theirs: list[object]) -> None:
    """As `same` for fields canboat also checks against their range (deviation, attitude: a
    value beyond +-pi reads as none there): not available here is none there, and every value
    there is the value here."""
    expected = np.array([np.nan if v is None else float(v) for v in theirs])  # type: ignore[arg-type]
    assert np.isnan(expected[np.isnan(mine)]).all()
    given = ~np.isnan(expected)
    assert given.mean() > 0.5
    np.testing.assert_allclose(mine[given], expected[given], rtol=0, atol=1e-12)


def test_vessel_heading_as_the_reference() -> None:
    data = payloads(np.random.default_rng(1))
    ref = reference(VESSEL_HEADING, data)
    mine = decode_vessel_heading(data)
    seq = mine.sequence()
    assert ((seq >= 0) & (seq < 253) | (seq == NO_SEQUENCE)).all()
    same(np.where(seq == NO_SEQUENCE, np.nan, seq), [r["sid"] for r in ref])
    same(mine.heading_rad(), [r["heading"] for r in ref])
    assert mine.reference.tolist() == [r["reference"] for r in ref]
    for field in ("deviation", "variation"):
        raw = getattr(mine, field)
        agrees(np.where(raw >= 0x7FFD, np.nan, raw * 1e-4), [r[field] for r in ref])
    # every frame either gives a heading or says why not; not available never a heading
    problems = mine.problems()
    na = np.isnan(mine.heading_rad())
    assert {problems[i] for i in np.flatnonzero(na)} == {"PGN 127250 heading not available"}
    assert sum(na) > 200 and N - len(problems) > 200


def test_rate_of_turn_and_attitude_as_the_reference() -> None:
    data = payloads(np.random.default_rng(2))
    ref = reference(RATE_OF_TURN, data)
    sid, rate = decode_rate_of_turn(data)
    same(np.where(sid >= 253, np.nan, sid), [r["sid"] for r in ref])
    same(rate, [r["rate"] for r in ref])
    ref = reference(ATTITUDE, data)
    sid, ypr = decode_attitude(data)
    for k, field in enumerate(("yaw", "pitch", "roll")):
        agrees(ypr[:, k], [r[field] for r in ref])


def test_encoders_round_trip_through_the_reference() -> None:
    rng = np.random.default_rng(3)
    sid = rng.integers(0, 253, 200)
    heading = rng.uniform(0, 2 * math.pi, 200)
    heading[::17] = np.nan
    ref = reference(VESSEL_HEADING, encode_vessel_heading(sid, heading))
    expected = np.round(heading / 1e-4) * 1e-4
    expected[expected > 6.2831] = 0.0
    same(expected, [r["heading"] for r in ref])
    assert {r["reference"] for r in ref} == {0}
    rate = rng.uniform(-0.5, 0.5, 200)
    ref = reference(RATE_OF_TURN, encode_rate_of_turn(sid, rate))
    same(np.round(rate / 3.125e-8) * 3.125e-8, [r["rate"] for r in ref])
    ypr = rng.uniform(-1, 1, (200, 3))
    ypr[::7, 0] = np.nan
    ref = reference(ATTITUDE, encode_attitude(sid, ypr))
    for k, field in enumerate(("yaw", "pitch", "roll")):
        same(np.round(ypr[:, k] / 1e-4) * 1e-4, [r[field] for r in ref])


def test_identifiers_as_the_reference() -> None:
    ids = np.random.default_rng(4).integers(0, 1 << 29, 5000)
    pgn, source = split_id(ids)
    for i, pg, sa in zip(ids.tolist(), pgn.tolist(), source.tolist(), strict=True):
        ref_pgn, ref_sa, _, _ = DecoderStaticsMixin.extract_header(i)
        assert (pg, sa) == (ref_pgn, ref_sa)
    for p in (VESSEL_HEADING, 60928, 126996, 59904):
        (got,), (sa,) = split_id(np.array([can_id(p, 17, 6)]))
        assert (got, sa) == (p, 17)


@pytest.mark.parametrize("source", [0, 35, 251])
def test_address_claim_and_product_information_through_the_reference(source: int) -> None:
    encoder, decoder = ReferenceEncoder(), ReferenceDecoder()
    name = iso_name(4242)
    (claim,) = encoder.address_claim(name, source, 1.0)
    assert decoder.decode(claim) == name
    product = Product("GX-1 gyrocompass", "SN-0042", "2.1.0")
    frames = encoder.product_information(product, source, 2.0)
    assert len(frames) > 1 and all(f.timestamp == 2.0 for f in frames)  # fast-packet
    got = [decoder.decode(f) for f in frames]
    assert got[:-1] == [None] * (len(frames) - 1) and got[-1] == product
    assert decoder.decode(frames[3]) is None  # a stray continuation frame: nothing, no raise
