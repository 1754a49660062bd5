"""The serial heading source: chunks -> headings on the campaign clock, invalid pieces, events."""

import numpy as np
import pytest
from pynmeagps.nmeahelpers import calc_checksum

from gyrostand.devices.iec61162 import ALARM_KIND, WRONG_BAUD_KIND, Iec61162Source
from gyrostand.devices.source import NO_SEQUENCE, ByteChunks


def line(body: str) -> bytes:
    return f"${body}*{calc_checksum(body)}\r\n".encode()


class MsClock:
    """Campaign clock = host clock in ms, less an offset."""

    def __init__(self, offset_s: float = 0.0) -> None:
        self.offset_s = offset_s

    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint((rx_s - self.offset_s) * 1000.0).astype(np.int64)


def chunks(start: int, *parts: tuple[float, bytes]) -> ByteChunks:
    return ByteChunks(start, tuple(p[1] for p in parts), np.array([p[0] for p in parts]))


def test_headings_timed_by_first_byte_on_the_campaign_clock() -> None:
    source = Iec61162Source(4800, "/dev/ttyS0")
    a, b = line("HEHDT,120.5,T"), line("HNTHS,121.25,A")
    # read at 100.5 s: a's '$' started (len a + len b) byte times of 1/480 s before
    # (reception times are whole milliseconds, as the raw log keeps them)
    out = source.decode(chunks(7, (100.5, a + b)), MsClock(100.0))
    h = out.headings
    assert h.pos.tolist() == [0, 1]  # serial stream positions number the pieces on the line
    assert h.t_ms.tolist() == [
        round((100.5 - (len(a) + len(b)) / 480) * 1000) - 100_000,
        round((100.5 - len(b) / 480) * 1000) - 100_000,
    ]
    assert h.heading_deg.tolist() == [120.5, 121.25]
    assert h.valid.all() and (h.counter == NO_SEQUENCE).all()
    assert out.invalid == () and out.events == ()
    assert out.claimed.tolist() == [True]
    assert "4800 baud" in source.info.time_base and source.info.sequence.modulo is None


def test_every_unusable_piece_is_an_invalid_frame_with_its_reason() -> None:
    source = Iec61162Source(38400)
    data = [
        line("HEHDT,1.0,T").replace(b"1.0", b"2.0"),  # checksum of another heading
        line("HEHDT,,T"),
        line("HETHS,10.0,V"),
        line("HETHS,10.0,S"),
        b"\xff\x80\x00",
        b"$HEHDT,12",  # cut by the next sentence
        b"$HEHDT,119.9,T*2\r\n",
        line("HEROT,1.5,V"),
        line("HEHDT,10.0,T"),
    ]
    out = source.decode(chunks(0, *((float(i), d) for i, d in enumerate(data))), MsClock())
    reasons = [(pos, f.reason) for pos, f in out.invalid]
    assert reasons == [
        (0, "checksum mismatch"),
        (1, "HDT: heading field empty"),
        (2, "THS mode V (data not valid)"),
        (3, "THS mode S (simulator)"),
        (4, "garbage bytes (3)"),
        (5, "truncated bytes (9)"),
        (6, "malformed checksum"),
        (7, "ROT: status V (not valid)"),
    ]
    assert out.headings.heading_deg.tolist() == [10.0]
    assert out.headings.pos.tolist() == [8]


def test_alarms_are_events_when_they_change() -> None:
    source = Iec61162Source(4800)
    alr_on = line("HEALR,120000.00,001,A,V,GYRO FAIL")
    alr_off = line("HEALR,120030.00,001,V,V,GYRO FAIL")
    hbt = line("HEHBT,10.0,A,1")
    parts = [(1.0, hbt), (2.0, alr_on), (3.0, alr_on), (4.0, hbt), (5.0, alr_off)]
    out = source.decode(chunks(0, *parts), MsClock())
    assert [(e.kind, e.severity, e.message) for _, e in out.events] == [
        (ALARM_KIND, "info", "HEHBT heartbeat: normal operation"),
        (ALARM_KIND, "error", "HEALR alarm 001 active: GYRO FAIL"),
        (ALARM_KIND, "info", "HEALR alarm 001 normal: GYRO FAIL"),
    ]
    assert [pos for pos, _ in out.events] == [0, 1, 4]


def test_a_sentence_cut_between_calls_is_kept() -> None:
    source = Iec61162Source(4800)
    s = line("HEHDT,33.3,T")
    first = source.decode(chunks(0, (1.0, s[:5])), MsClock())
    second = source.decode(chunks(1, (2.0, s[5:])), MsClock())
    assert len(first.headings) == 0
    assert second.headings.pos.tolist() == [0]  # the first piece of the line
    assert second.headings.t_ms.tolist() == [round((1.0 - 5 / 480) * 1000)]
    end = source.decode(chunks(2, (3.0, b"$HETHS,1")), MsClock())
    assert end.invalid == ()
    assert [f.reason for _, f in source.close(MsClock()).invalid] == ["truncated bytes (8)"]


def test_garbage_only_is_named_a_wrong_baud_rate_once() -> None:
    rng = np.random.default_rng(1)
    source = Iec61162Source(4800, "/dev/ttyUSB0")
    noise = rng.integers(128, 256, 600, dtype=np.uint8).tobytes()  # no '$' in it
    out = source.decode(chunks(0, (1.0, noise[:300]), (2.0, noise[300:])), MsClock())
    ((_, event),) = out.events
    assert (event.kind, event.severity) == (WRONG_BAUD_KIND, "error")
    port = "serial port /dev/ttyUSB0"
    assert event.message == f"{port}: no NMEA sentences at 4800 baud: wrong baud rate?"
    assert source.decode(chunks(2, (3.0, noise)), MsClock()).events == ()


def test_a_good_line_with_some_garbage_is_no_wrong_baud() -> None:
    source = Iec61162Source(4800)
    data = line("HEHDT,1.0,T") + b"\xff" * 400
    assert source.decode(chunks(0, (1.0, data)), MsClock()).events == ()
    assert source.stats.good_bytes == len(line("HEHDT,1.0,T")) - 2


@pytest.mark.parametrize("baud", [4800, 38400])
def test_time_base_names_the_baud(baud: int) -> None:
    assert f"{baud} baud" in Iec61162Source(baud).info.time_base
