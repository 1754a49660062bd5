"""Cutting a timed byte stream into sentences: reception times in closed form, junk named."""

import pytest

from gyrostand.devices.framing import GARBAGE, OVERLONG, TRUNCATED, Framer, Received

HDT = b"$HEHDT,119.9,T*2F\r\n"  # 19 bytes
THS = b"$HETHS,231.50,A*11\r\n"  # 20 bytes


def test_one_chunk_times_by_bytes_after_each_start() -> None:
    # 4800 baud: 1/480 s a byte. Chunk of 39 bytes read at t = 10: HDT's '$' (byte 0) started
    # 39 byte times before, THS's (byte 19) 20 byte times before.
    pieces = Framer(4800).feed(10.0, HDT + THS)
    assert pieces == [
        Received(pytest.approx(10.0 - 39 / 480), HDT[:-2]),
        Received(pytest.approx(10.0 - 20 / 480), THS[:-2]),
    ]


def test_sentence_split_over_chunks_takes_its_first_chunk_time() -> None:
    framer = Framer(38400)
    assert framer.feed(5.0, HDT[:7]) == []
    # its '$' was byte 0 of a 7-byte chunk read at 5.0: 7 byte times of 1/3840 s before
    (piece,) = framer.feed(6.0, HDT[7:])
    assert piece.data == HDT[:-2]
    assert piece.time_s == pytest.approx(5.0 - 7 / 3840)


def test_regular_sentences_keep_their_spacing() -> None:
    # a compass sending every 0.1 s, each sentence read whole when its last byte arrives
    framer = Framer(4800)
    times = [framer.feed(0.1 * k + len(HDT) / 480, HDT)[0].time_s for k in range(5)]
    assert times == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])


def test_garbage_truncated_overlong_are_named() -> None:
    framer = Framer(9600)
    data = b"\xfe\x00x" + b"$HEHDT,12" + HDT + b"\r\n" + b"$P" + b"A" * 90 + b"\r\n" + b"$HE"
    pieces = framer.feed(1.0, data) + framer.close()
    assert [(p.junk, p.data) for p in pieces] == [
        (GARBAGE, b"\xfe\x00x"),
        (TRUNCATED, b"$HEHDT,12"),
        (None, HDT[:-2]),
        (OVERLONG, b"$P" + b"A" * 90),
        (TRUNCATED, b"$HE"),
    ]
    n = len(data)
    assert pieces[0].time_s == pytest.approx(1.0 - n / 960)
    assert pieces[1].time_s == pytest.approx(1.0 - (n - 3) / 960)


def test_line_ends_between_sentences_are_not_garbage_but_other_bytes_are() -> None:
    framer = Framer(4800)
    pieces = framer.feed(1.0, b"\r\n\n" + HDT + b"\r\nab\r\ncd")
    assert [(p.junk, p.data) for p in pieces] == [
        (None, HDT[:-2]),
        (GARBAGE, b"abcd"),
    ]
    assert pieces[1].time_s == pytest.approx(1.0 - 6 / 480)


def test_a_line_with_no_end_is_bounded() -> None:
    framer = Framer(4800)
    pieces = framer.feed(1.0, b"$")
    for _ in range(10):
        pieces += framer.feed(1.0, b"9" * 100)
    assert [p.junk for p in pieces] == [OVERLONG] + [GARBAGE] * 6
    assert len(pieces[0].data) == 401  # held up to 4 x 82 bytes, then given up on
    assert sum(len(p.data) for p in pieces) == 1001
