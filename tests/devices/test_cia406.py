"""The CiA 406 encoder adapter: position values against canopen's own PDO decoding (the EDS's
mapping) and against struct for another mapping, the heading equation written out, the EDS read
with canopen, and a bad-input table: each frame gives a heading, an invalid frame with its reason,
an event, or nothing (another node's), never a traceback."""

from __future__ import annotations

import struct
from importlib.resources import files
from pathlib import Path

import can
import canopen
import numpy as np
import pytest

from gyrostand.devices.cia406 import Cia406Heading, encoder_info
from gyrostand.devices.clock import NO_CLOCK
from gyrostand.devices.source import UNNUMBERED
from gyrostand.frames.batch import RawFrames
from gyrostand.stand.encoder import Encoder, EncoderError, encoder_from_eds

EDS = Path(str(files("gyrostand.devices") / "data" / "sim-encoder.eds"))
NODE = 5


class Clock:
    """Reception s -> campaign ms; no clock before 1 s of reception time."""

    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.where(rx_s < 1.0, NO_CLOCK, np.round(rx_s * 1000.0)).astype(np.int64)


def frame(t: float, cob_id: int, data: bytes, **kw: bool) -> can.Message:
    return can.Message(timestamp=t, arbitration_id=cob_id, data=data, is_extended_id=False, **kw)


def decode(encoder: Encoder, messages: list[can.Message], start: int = 0):  # type: ignore[no-untyped-def]
    return Cia406Heading(encoder).decode(RawFrames.from_messages(start, messages), Clock())


def test_the_eds_as_canopen_reads_it() -> None:
    encoder = encoder_from_eds(EDS, NODE)
    od = canopen.import_od(str(EDS), NODE)
    assert encoder.counts_per_revolution == od[0x6001].default == 65536
    assert encoder.total_range == od[0x6002].default == 65536 * 4096
    assert encoder.heartbeat_ms == od[0x1017].default == 1000
    assert (encoder.tpdo_id, encoder.offset_bits, encoder.length_bits) == (0x185, 0, 32)
    assert not encoder.on_sync  # transmission type 254: event timer
    plan = encoder_from_eds(EDS, NODE, counts_per_revolution=8192, zero_counts=7, sign=-1)
    assert (plan.counts_per_revolution, plan.zero_counts, plan.sign) == (8192, 7, -1)


@pytest.mark.parametrize(
    ("path", "problem"),
    [
        ("missing.eds", "No such file"),
        (str(files("gyrostand.devices") / "data" / "sim-inclinometer.eds"), "no TPDO maps"),
    ],
)
def test_an_eds_gyrostand_cannot_use_is_one_line(path: str, problem: str) -> None:
    with pytest.raises(EncoderError, match=problem) as raised:
        encoder_from_eds(Path(path), NODE)
    assert "\n" not in str(raised.value)


def test_positions_as_canopens_pdo_decoding() -> None:
    """Random positions through canopen's TPDO1 map of the EDS and through the adapter."""
    encoder = encoder_from_eds(EDS, NODE)
    node = canopen.RemoteNode(NODE, str(EDS))
    canopen.Network().add_node(node)
    node.tpdo.read(from_od=True)
    rng = np.random.default_rng(3)
    counts = rng.integers(0, encoder.total_range, 500)  # type: ignore[arg-type]
    messages = [frame(2.0 + 0.1 * i, 0x185, struct.pack("<I", c)) for i, c in enumerate(counts)]
    theirs = []
    for m in messages:
        node.tpdo[1].on_message(m.arbitration_id, m.data, m.timestamp)
        theirs.append(node.tpdo[1]["Position value"].raw)
    out = decode(encoder, messages)
    expected = (np.array(theirs) % 65536) * 360.0 / 65536  # (zero 0, clockwise)
    np.testing.assert_array_equal(out.headings.heading_deg, expected)
    np.testing.assert_array_equal(out.headings.t_ms, np.round(2000 + 100 * np.arange(500)))
    assert (out.headings.counter == -1).all() and out.invalid == () and out.claimed.all()


def test_another_mapping_zero_and_direction() -> None:
    """A 24-bit position from byte 2 of TPDO2, read counter-clockwise from a zero, against
    struct and the equation written out."""
    encoder = Encoder(
        9, 4096, zero_counts=1000, sign=-1, cob_id=0x289, offset_bits=16, length_bits=24
    )
    rng = np.random.default_rng(4)
    counts = rng.integers(0, 1 << 24, 200)
    payloads = [b"\xaa\xbb" + struct.pack("<I", c)[:3] + b"\xcc" for c in counts]
    out = decode(encoder, [frame(5.0 + i, 0x289, p) for i, p in enumerate(payloads)])
    got = [struct.unpack("<I", p[2:5] + b"\0")[0] for p in payloads]
    expected = ((1000 - np.array(got)) % 4096) * (360.0 / 4096)
    np.testing.assert_allclose(out.headings.heading_deg, expected, rtol=0, atol=1e-12)
    assert ((out.headings.heading_deg >= 0) & (out.headings.heading_deg < 360)).all()


def test_counts_invert_the_heading() -> None:
    encoder = Encoder(NODE, 65536, zero_counts=40000, sign=-1)
    heading = np.linspace(0, 359.99, 1000)
    back = encoder.heading_deg(encoder.counts(heading))
    wrapped = (back - heading + 180.0) % 360.0 - 180.0
    assert np.abs(wrapped).max() <= encoder.resolution_deg / 2 + 1e-9


def test_the_source_info_states_resolution_and_time_base() -> None:
    info = encoder_info(encoder_from_eds(EDS, NODE))
    assert info.protocol == "cia406" and info.sequence == UNNUMBERED
    assert info.resolution_deg == pytest.approx(360 / 65536)
    assert (
        "reception time" in info.time_base
        and "TPDO 0x185 sent on its event timer" in info.time_base
    )


POSITION = struct.pack("<I", 16384)  # 90 deg
ENCODER = Encoder(NODE, 65536, total_range=65536 * 16, heartbeat_ms=100)
# (frames after a first good TPDO at 2.0 s) -> (headings, invalid reasons, events, claimed)
BAD_INPUT = {
    "short TPDO": (
        [frame(2.1, 0x185, b"\x00\x40")],
        0,
        ["2 bytes, the position 0x6004 needs 4"],
        [],
        1,
    ),
    "position beyond the total range": (
        [frame(2.1, 0x185, struct.pack("<I", 65536 * 16))],
        0,
        ["position 1048576 beyond the total range 0x6002 (1048576)"],
        [],
        1,
    ),
    "before the stand clock": ([frame(0.5, 0x185, POSITION)], 0, ["no clock"], [], 1),
    "another node's TPDO": ([frame(2.1, 0x186, POSITION)], 0, [], [], 0),
    "another node's EMCY and heartbeat": (
        [frame(2.1, 0x86, bytes(8)), frame(2.1, 0x706, b"\x7f")],
        0,
        [],
        [],
        0,
    ),
    "an extended 0x185": (
        [can.Message(timestamp=2.1, arbitration_id=0x185, data=POSITION, is_extended_id=True)],
        0,
        [],
        [],
        0,
    ),
    "a remote request": ([frame(2.1, 0x185, b"", is_remote_frame=True)], 0, [], [], 0),
    "EMCY": (
        [frame(2.1, 0x85, bytes([0x10, 0x31, 0x81, 1, 2, 3, 4, 5]))],
        0,
        [],
        [
            (
                "emcy",
                "error",
                "EMCY: Code 0x3110, Voltage, error register 0x81, manufacturer data 0102030405",
            )
        ],
        1,
    ),
    "EMCY error reset": ([frame(2.1, 0x85, bytes(8))], 0, [], [("emcy", "info", "error reset")], 1),
    "short EMCY": ([frame(2.1, 0x85, b"\x00\x10")], 0, ["EMCY: 2 bytes, not 8"], [], 1),
    "heartbeat of 2 bytes": ([frame(2.1, 0x705, b"\x05\x00")], 0, ["heartbeat: 2 bytes"], [], 1),
    "heartbeat of no NMT state": ([frame(2.1, 0x705, b"\x03")], 0, ["heartbeat: state 3"], [], 1),
    "pre-operational": (
        [frame(2.05, 0x705, b"\x05"), frame(2.1, 0x705, b"\x7f")],
        0,
        [],
        [("nmt state", "warning", "is PRE-OPERATIONAL: no position until OPERATIONAL")],
        2,
    ),
    "silence (heartbeat 100 ms)": (
        [frame(2.05, 0x705, b"\x05"), frame(2.40, 0x185, POSITION), frame(2.45, 0x705, b"\x05")],
        1,
        [],
        [
            ("heartbeat lost", "error", "no heartbeat for 3 producer periods (100 ms each)"),
            ("heartbeat back", "info", "heartbeat back (OPERATIONAL)"),
        ],
        3,
    ),
}


@pytest.mark.parametrize("case", list(BAD_INPUT), ids=list(BAD_INPUT))
def test_bad_input_table(case: str) -> None:
    messages, headings, reasons, events, claimed = BAD_INPUT[case]
    out = decode(ENCODER, [frame(2.0, 0x185, POSITION), *messages])
    assert len(out.headings.t_ms) == 1 + headings
    assert out.headings.heading_deg[0] == 90.0
    assert len(out.invalid) == len(reasons)
    for (pos, bad), reason in zip(out.invalid, reasons, strict=True):
        assert pos >= 1 and reason in bad.reason and f"encoder node {NODE}" in bad.reason
    assert len(out.events) == len(events)
    for (_, event), (kind, severity, text) in zip(out.events, events, strict=True):
        assert (event.kind, event.severity) == (kind, severity) and text in event.message
    assert int(out.claimed.sum()) == 1 + claimed


def test_the_missing_heartbeat_is_told_where_it_is_missing_whatever_the_batches() -> None:
    """Cut into batches anywhere, the stream gives the same events at the same positions."""
    messages = [frame(2.0 + 0.05 * i, 0x185, POSITION) for i in range(40)]
    messages.insert(3, frame(2.1, 0x705, b"\x05"))
    whole = decode(ENCODER, messages).events
    assert [(pos, e.kind) for pos, e in whole] == [
        (10, "heartbeat lost")
    ]  # 2.45 s: > 2.1 + 3 x 0.1
    for cut in (1, 5, 11, 12, 30):
        adapter = Cia406Heading(ENCODER)
        parts = [messages[:cut], messages[cut:]]
        events = [
            e
            for start, part in zip((0, cut), parts, strict=True)
            for e in adapter.decode(RawFrames.from_messages(start, part), Clock()).events
        ]
        assert events == list(whole)
