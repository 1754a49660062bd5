"""python-can and the project's DBC codec over a real kernel SocketCAN socket."""

from itertools import pairwise

import can
import cantools
import pytest

from gyrostand.stand.protocol import DBC_PATH, Codec, HeadingFrame, InvalidFrame
from tests.socketcan.frames import drain, messages

pytestmark = pytest.mark.socketcan


def key(msg):
    return msg.arbitration_id, msg.is_extended_id, bytes(msg.data)


def test_frames_cross_the_socket_in_order_and_not_back_to_the_sender(open_bus, channel):
    sender, receiver = open_bus(), open_bus()
    sent = messages(600)
    received = []
    for block in range(0, len(sent), 50):  # blocks fit a default-sized socket receive buffer
        for msg in sent[block : block + 50]:
            sender.send(msg)
        received += drain(receiver, len(sent[block : block + 50]))
    assert [key(m) for m in received] == [key(m) for m in sent]
    assert {m.channel for m in received} == {channel}
    assert all(a.timestamp <= b.timestamp for a, b in pairwise(received))
    assert sender.recv(timeout=0.2) is None  # the kernel does not loop frames to their socket


def test_kernel_filter_passes_only_the_heading_id(open_bus):
    codec = Codec()
    heading_id = codec.heading_arbitration_id
    sender = open_bus()
    receiver = open_bus(can_filters=[{"can_id": heading_id, "can_mask": 0x7FF}])
    sent = messages(100, ids=(heading_id, heading_id + 1, 0x7FF))
    for msg in sent:
        sender.send(msg)
    expected = [key(m) for m in sent if m.arbitration_id == heading_id and not m.is_extended_id]
    assert [key(m) for m in drain(receiver, len(expected))] == expected
    assert receiver.recv(timeout=0.2) is None


def test_dbc_heading_frame_round_trip_and_corruption(open_bus):
    codec = Codec()
    dbc = cantools.database.load_file(str(DBC_PATH))  # independent decode of the same bytes
    sender, receiver = open_bus(), open_bus()
    good = codec.encode_heading(stand_time_ms=3_600_123, heading_deg=271.456, valid=True, counter=9)
    sender.send(good)
    flipped = bytearray(good.data)
    flipped[4] ^= 0x01  # one heading bit: the CRC no longer matches
    corrupt = can.Message(arbitration_id=good.arbitration_id, is_extended_id=False, data=flipped)
    sender.send(corrupt)
    got_good, got_corrupt = drain(receiver, 2)

    fields = dbc.decode_message(got_good.arbitration_id, got_good.data)
    assert fields["STAND_TIME"] == 3_600_123
    assert fields["HEADING"] == pytest.approx(271.456, abs=1e-9)
    decoded = codec.decode(got_good)
    assert isinstance(decoded, HeadingFrame)
    assert (decoded.stand_time_ms, decoded.valid, decoded.counter) == (3_600_123, True, 9)
    assert decoded.heading_deg == pytest.approx(271.456, abs=1e-9)

    bad = codec.decode(got_corrupt)
    assert isinstance(bad, InvalidFrame)
    assert "CRC" in bad.reason
    assert bad.raw == bytes(flipped)
