"""The serial source's bad-input table: each bad input gives one line (a port) or one invalid
record / one event (a line), with its reason, never a traceback and never silence."""

import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from pynmeagps.nmeahelpers import calc_checksum

from gyrostand.devices.iec61162 import WRONG_BAUD_KIND, Iec61162Source
from gyrostand.devices.serial_port import SerialPortError, SerialReader
from gyrostand.devices.serial_sim import uart_resample
from gyrostand.devices.source import ByteChunks, SourceOutput

GOOD = b"$HEHDT,120.5,T*%s\r\n" % calc_checksum("HEHDT,120.5,T").encode()


class Clock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64)


@dataclass(frozen=True)
class Case:
    name: str
    line: bytes  # received between two good sentences
    reason: str | None = None  # the one invalid record's reason
    event: str | None = None  # or the one event's kind


CASES = [
    Case("corrupt checksum", GOOD.replace(b"120.5", b"121.5"), reason="checksum mismatch"),
    Case("no checksum", b"$HEHDT,120.5,T\r\n", reason="no checksum"),
    Case("truncated sentence", b"$HEHDT,12", reason="truncated bytes (9)"),
    Case("garbage bytes", b"\x80\xff\x13", reason="garbage bytes (3)"),
    Case("overlong sentence", b"$HEHDT," + b"9" * 90 + b"\r\n", reason="overlong bytes (97)"),
    Case(
        "empty heading",
        b"$HEHDT,,T*%s\r\n" % calc_checksum("HEHDT,,T").encode(),
        reason="HDT: heading field empty",
    ),
    Case(
        "THS mode V",
        b"$HETHS,120.50,V*%s\r\n" % calc_checksum("HETHS,120.50,V").encode(),
        reason="THS mode V (data not valid)",
    ),
    Case("non-printable byte", b"$HEHDT,12\x000.5,T*00\r\n", reason="non-printable characters"),
    Case(
        "alarm",
        b"$HEALR,,001,A,V,GYRO*%s\r\n" % calc_checksum("HEALR,,001,A,V,GYRO").encode(),
        event="compass alarm",
    ),
    Case("wrong baud rate", uart_resample(GOOD * 40, 4800, 38400), event=WRONG_BAUD_KIND),
]


def decode_line(source: Iec61162Source, data: bytes) -> SourceOutput:
    return source.decode(ByteChunks(0, (data,), np.array([1.0])), Clock())


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_one_record_each(case: Case) -> None:
    source = Iec61162Source(4800, "/dev/ttyS0")
    if case.event == WRONG_BAUD_KIND:  # a whole line of it: nothing good at all
        out = decode_line(source, case.line)
        assert len(out.headings) == 0
        assert [e.kind for _, e in out.events] == [WRONG_BAUD_KIND]
        assert "serial port /dev/ttyS0: no NMEA sentences at 4800 baud: wrong baud rate?" in [
            e.message for _, e in out.events
        ]
        return
    out = decode_line(source, GOOD + case.line + GOOD)
    assert out.headings.heading_deg.tolist() == [120.5, 120.5]  # the good ones around it kept
    if case.reason is not None:
        assert [f.reason for _, f in out.invalid] == [case.reason] and out.events == ()
    else:
        assert [e.kind for _, e in out.events] == [case.event] and out.invalid == ()


def reader_error(make: Callable[[], SerialReader]) -> str:
    try:
        make()
    except SerialPortError as exc:
        return str(exc)
    raise AssertionError("no error")


def test_absent_and_unplugged_ports_are_one_line() -> None:
    assert reader_error(lambda: SerialReader("/dev/ttyGYRO404", 4800)) == (
        "serial port /dev/ttyGYRO404: cannot open it (No such file or directory)"
    )
    master, slave = os.openpty()
    path = os.ttyname(slave)
    reader = SerialReader(path, 4800).start()
    os.close(master)
    reader._thread.join(60.0)  # hang guard only: the read fails at once
    reader.stop()
    os.close(slave)
    assert reader.error is not None and reader.error.count("\n") == 0
    assert reader.error.startswith(f"serial port {path}: read failed (")
    assert reader.error.endswith("): unplugged?")
