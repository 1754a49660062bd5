"""One range rule for the scalar codec and the batch decoder: a lab DBC whose heading has scale
0.1 and maximum 359.9 (359.9 decodes to 3599 * 0.1 = 359.90000000000003) accepts a 359.9 deg
frame on both paths and refuses 360.0 on both."""

from pathlib import Path

import can
import pytest

from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.stand.protocol import DBC_PATH, Codec, HeadingFrame, InvalidFrame, ProtocolError

SHIPPED_HEADING = ' SG_ HEADING : 32|19@1+ (0.001,0) [0|359.999] "deg" CONTROLLER'
LAB_HEADING = ' SG_ HEADING : 32|19@1+ (0.1,0) [0|359.9] "deg" CONTROLLER'


@pytest.fixture
def lab_codec(tmp_path: Path) -> Codec:
    text = DBC_PATH.read_text()
    assert SHIPPED_HEADING in text
    dbc = tmp_path / "lab.dbc"
    dbc.write_text(text.replace(SHIPPED_HEADING, LAB_HEADING))
    return Codec(dbc)


def batch_decode(codec: Codec, msg: can.Message) -> tuple[list[float], list[object]]:
    """The batch path's headings and other frames for one message."""
    batch = BatchDecoder(codec).decode(RawFrames.from_messages(0, [msg]))
    return batch.headings.heading_deg.tolist(), [frame for _, frame in batch.others]


def test_a_heading_at_the_dbc_maximum_is_accepted_by_both_paths(lab_codec: Codec) -> None:
    msg = lab_codec.encode_heading(1000, 359.9, True, 5)
    raw = lab_codec.database.decode_message(msg.arbitration_id, msg.data, scaling=False)
    assert raw["HEADING"] == 3599  # on the wire; 3599 * 0.1 > 359.9 by 3e-14
    frame = lab_codec.decode(msg)
    assert frame == HeadingFrame(1000, pytest.approx(359.9, abs=1e-9), True, 5)
    headings, others = batch_decode(lab_codec, msg)
    assert headings == [pytest.approx(359.9, abs=1e-9)]  # a heading, not an "other" to be lost
    assert others == []


@pytest.mark.parametrize("heading", [360.0, 360.1, 52428.7])
def test_a_heading_past_the_dbc_maximum_is_refused_by_both_paths(
    lab_codec: Codec, heading: float
) -> None:
    with pytest.raises(ProtocolError, match=r"outside the allowed range \[0, 359.9\]"):
        lab_codec.encode_heading(1000, heading, True, 5)
    msg = lab_codec.encode_heading(1000, heading, True, 5, strict=False)
    frame = lab_codec.decode(msg)
    assert isinstance(frame, InvalidFrame) and "outside [0, 359.9]" in frame.reason
    headings, others = batch_decode(lab_codec, msg)
    assert headings == []
    assert others == [frame]
