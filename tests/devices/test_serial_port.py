"""The serial port reader on pseudo-terminal pairs: chunks, silence, an unplugged port, names."""

import contextlib
import os
import time
from collections.abc import Iterator

import numpy as np
import pytest
from pynmeagps.nmeahelpers import calc_checksum

from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_port import SerialPortError, SerialReader, open_port
from gyrostand.devices.source import ByteChunks

HANG_GUARD_S = 60.0  # only against a hang: every wait below returns as soon as data is there


def line(body: str) -> bytes:
    return f"${body}*{calc_checksum(body)}\r\n".encode()


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    """A pseudo-terminal pair: the master's fd (the 'compass' side) and the port's path."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    yield master, path
    os.close(slave)
    with contextlib.suppress(OSError):
        os.close(master)


class Clock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64)


def read_all(reader: SerialReader, n_bytes: int) -> list[tuple[float, bytes]]:
    got: list[tuple[float, bytes]] = []
    deadline = time.monotonic() + HANG_GUARD_S
    while sum(len(d) for _, d in got) < n_bytes and time.monotonic() < deadline:
        chunks = reader.take(wait_s=1.0)
        got += zip(chunks.t_s.tolist(), chunks.data, strict=True)
    return got


def test_sentences_written_to_the_pty_come_back_as_headings(pty: tuple[int, str]) -> None:
    master, path = pty
    sentences = [line(f"HEHDT,{h:.1f},T") for h in (10.0, 10.1, 10.2)] + [line("HETHS,10.3,A")]
    with SerialReader(path, 4800) as reader:
        for s in sentences:
            os.write(master, s)
        got = read_all(reader, sum(map(len, sentences)))
    assert b"".join(d for _, d in got) == b"".join(sentences)
    times = [t for t, _ in got]
    assert times == sorted(times)
    source = Iec61162Source(4800, path)
    chunks = ByteChunks(0, tuple(d for _, d in got), np.array([t for t, _ in got]))
    out = source.decode(chunks, Clock())
    assert out.headings.heading_deg.tolist() == [10.0, 10.1, 10.2, 10.3]
    assert out.invalid == ()


def test_take_gives_stream_positions_in_order(pty: tuple[int, str]) -> None:
    master, path = pty
    with SerialReader(path, 38400) as reader:
        os.write(master, line("HEHDT,1.0,T"))
        first = reader.take(wait_s=HANG_GUARD_S)
        os.write(master, line("HEHDT,2.0,T"))
        second = reader.take(wait_s=HANG_GUARD_S)
    assert first.start == 0 and len(first.data) >= 1
    assert second.start == len(first.data)


def test_a_silent_port_is_silence_not_an_error(pty: tuple[int, str]) -> None:
    _, path = pty
    with SerialReader(path, 4800) as reader:
        chunks = reader.take(wait_s=0.3)
        assert chunks.data == () and len(chunks.t_s) == 0
        assert reader.alive and reader.error is None


def test_an_unplugged_port_is_one_line_naming_it(pty: tuple[int, str]) -> None:
    master, path = pty
    reader = SerialReader(path, 4800).start()
    os.close(master)  # the far end gone: reads fail with EIO, as a pulled USB adapter's do
    deadline = time.monotonic() + HANG_GUARD_S
    while reader.alive and time.monotonic() < deadline:
        time.sleep(0.01)
    reader.stop()
    assert reader.error is not None
    assert reader.error.startswith(f"serial port {path}: ")
    assert reader.error.endswith("unplugged?")
    assert "\n" not in reader.error


@pytest.mark.parametrize(
    ("port", "why"),
    [
        ("/dev/ttyGYRO9", "No such file or directory"),
        ("/dev/null", "not a serial port"),
    ],
)
def test_a_port_that_cannot_be_opened_is_named(port: str, why: str) -> None:
    with pytest.raises(SerialPortError) as err:
        open_port(port, 4800)
    assert str(err.value) == f"serial port {port}: cannot open it ({why})"
