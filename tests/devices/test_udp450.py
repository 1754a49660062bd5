"""IEC 61162-450 datagrams: the same sentences as on a serial line, on UDP."""

import socket

import numpy as np

from gyrostand.devices.framing import BAD_TAG, GARBAGE, Received
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.nmea0183 import checksum
from gyrostand.devices.udp450 import Udp450Reader, parse_datagram

HDT = b"$HEHDT,119.9,T*2F"


def tag(params: bytes) -> bytes:
    return b"\\%s*%02X\\" % (params, checksum(params))


class Clock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64)


def test_datagram_sentences_without_their_tag_blocks() -> None:
    data = b"UdPbC\x00" + tag(b"s:HE0001,n:1") + HDT + b"\r\n" + tag(b"s:HE0001,n:2") + HDT
    assert parse_datagram(data, 5.0) == [Received(5.0, HDT), Received(5.0, HDT)]


def test_what_is_not_a_sentence_datagram_is_junk() -> None:
    assert parse_datagram(b"RaUdP\x00xyz", 1.0) == [Received(1.0, b"RaUdP\x00xyz", GARBAGE)]
    bad = b"\\s:HE0001*00\\" + HDT
    assert parse_datagram(b"UdPbC\x00" + bad, 1.0) == [Received(1.0, bad, BAD_TAG)]


def test_received_on_udp_decoded_as_serial() -> None:
    with Udp450Reader(0, interface="127.0.0.1") as reader:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(b"UdPbC\x00" + tag(b"s:HE0001") + HDT + b"\r\n", ("127.0.0.1", reader.port))
        pieces = reader.take(wait_s=60.0)  # hang guard: returns on arrival
    out = Iec61162Source(38400, reader.where).decode_pieces(pieces, Clock())
    assert out.headings.heading_deg.tolist() == [119.9] and out.invalid == ()
