"""The simulated serial compass: the stand's headings as sentences, reproducible, with faults."""

import dataclasses
import functools
import os

import numpy as np
import pytest

from gyrostand.devices.framing import byte_time_s
from gyrostand.devices.iec61162 import WRONG_BAUD_KIND, Iec61162Source
from gyrostand.devices.serial_config import LineFaults
from gyrostand.devices.serial_port import SerialReader
from gyrostand.devices.serial_sim import (
    SerialCompass,
    SerialCompassConfig,
    SerialSimError,
    uart_resample,
    write_realtime,
)
from gyrostand.devices.source import ByteChunks
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.simconfig import SimConfig


class StandClock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64)


class Compass:
    """A serial compass on a stand of its own."""

    def __init__(self, rate_hz: float, seed: int, **kw: object) -> None:
        config = SerialCompassConfig(rate_hz=rate_hz, seed=seed, **kw)  # type: ignore[arg-type]
        self.serial = SerialCompass(config)
        self.engine = self.serial.stand(SimConfig(seed=seed, heading_rate_hz=rate_hz))

    def until(self, t_s: float) -> list[tuple[float, bytes]]:
        return self.serial.until(self.engine, t_s)


def compass(rate_hz: float = 10.0, seed: int = 3, **kw: object) -> Compass:
    return Compass(rate_hz, seed, **kw)


def received(pieces: list[tuple[float, bytes]], baud: int) -> ByteChunks:
    """Each piece read whole when its last byte arrived."""
    t = [t + len(d) * byte_time_s(baud) for t, d in pieces]
    return ByteChunks(0, tuple(d for _, d in pieces), np.array(t))


def stand_headings(seed: int, rate_hz: float, until_s: float):  # type: ignore[no-untyped-def]
    engine = StandEngine(SimConfig(seed=seed, heading_rate_hz=rate_hz))
    frames = engine.advance_to(until_s)
    return BatchDecoder(engine.codec).decode(RawFrames.from_messages(0, frames)).headings


def test_virtual_time_is_byte_reproducible() -> None:
    a, b = compass(seed=5), compass(seed=5)
    assert a.until(10.0) == b.until(10.0)
    assert compass(seed=6).until(10.0) != compass(seed=5).until(10.0)


@pytest.mark.parametrize(("rate_hz", "baud"), [(10.0, 4800), (50.0, 38400), (1.0, 4800)])
def test_sentences_read_back_to_the_stand_headings(rate_hz: float, baud: int) -> None:
    pieces = compass(rate_hz, baud=baud, sentences=("THS",)).until(20.0)
    out = Iec61162Source(baud).decode(received(pieces, baud), StandClock())
    truth = stand_headings(3, rate_hz, 20.0)
    assert out.invalid == ()
    # timed by reception: each sentence's first byte at its sample's stand time
    assert out.headings.t_ms.tolist() == truth.t_ms.tolist()
    err = (out.headings.heading_deg - truth.heading_deg + 180.0) % 360.0 - 180.0
    assert np.abs(err).max() <= 0.005 + 1e-9  # THS: two decimals


def test_hdt_and_rot_at_4800_baud() -> None:
    pieces = compass(sentences=("HDT", "ROT")).until(5.0)
    assert len(pieces) == 51
    assert all(d.count(b"$") == 2 for _, d in pieces)
    out = Iec61162Source(4800).decode(received(pieces, 4800), StandClock())
    truth = stand_headings(3, 10.0, 5.0)
    assert np.abs(out.headings.heading_deg - truth.heading_deg).max() <= 0.05 + 1e-9


def test_a_line_too_slow_for_the_sentences_is_refused() -> None:
    with pytest.raises(SerialSimError) as err:
        compass(50.0, baud=4800, sentences=("HDT", "THS", "ROT"))
    assert str(err.value) == "HDT+THS+ROT at 50 Hz need up to 3000 bytes/s; 4800 baud carries 480"
    with pytest.raises(SerialSimError, match="outside 1-50 Hz"):
        SerialCompassConfig(rate_hz=100.0).check()


@pytest.mark.parametrize(
    ("faults", "reason"),
    [
        (LineFaults(checksum_error_rate=1.0), "checksum mismatch"),
        (LineFaults(not_valid_rate=1.0), "THS mode V (data not valid)"),
    ],
)
def test_sentence_faults_are_invalid_with_their_reason(faults: LineFaults, reason: str) -> None:
    pieces = compass(sentences=("THS",), faults=faults).until(2.0)
    out = Iec61162Source(4800).decode(received(pieces, 4800), StandClock())
    assert len(out.headings) == 0
    assert {f.reason for _, f in out.invalid} == {reason} and len(out.invalid) == 21


def test_garbage_and_silence() -> None:
    faults = LineFaults(garbage_rate=0.5, line_silence_at_s=1.0, line_silence_for_s=0.5)
    pieces = compass(sentences=("HDT",), faults=faults).until(3.0)
    out = Iec61162Source(4800).decode(received(pieces, 4800), StandClock())
    t = out.headings.t_ms
    assert len(t) == 31 - 5 and not ((t >= 1000) & (t < 1500)).any()
    garbage = [f for _, f in out.invalid]
    assert garbage and all(f.reason.startswith("garbage bytes (") for f in garbage)
    assert 5 <= len(garbage) <= 21


def test_a_compass_at_another_baud_rate_is_named() -> None:
    faults = LineFaults(sender_baud=38400)
    pieces = compass(sentences=("HDT", "ROT"), faults=faults).until(60.0)
    source = Iec61162Source(4800, "/dev/ttyS1")
    out = source.decode(received(pieces, 4800), StandClock())
    assert len(out.headings) == 0
    assert [e.kind for _, e in out.events] == [WRONG_BAUD_KIND]


def test_uart_resample_at_the_same_rate_is_the_identity() -> None:
    data = bytes(range(256))
    assert uart_resample(data, 4800, 4800) == data
    # read at 8x the rate, a sent NUL is low for 72 received bit times then high for 8: bytes
    # start at 0, 9.5, 19, ... 66.5 bit times; the first 7 find their stop bit (at +9.5) low,
    # framing errors read as NUL; the 8th samples bits 0-3 low and 4-7 high, stop high: 0xF0
    assert uart_resample(b"\x00", 4800, 38400) == b"\x00" * 7 + b"\xf0"


def test_write_realtime_paces_by_the_last_byte() -> None:
    now = [100.0]
    waits: list[float] = []

    def sleep(s: float) -> None:
        waits.append(s)
        now[0] += s

    r, w = os.pipe()
    try:
        pieces = [(0.0, b"$A*41\r\n"), (0.1, b"$B*42\r\n")]
        write = functools.partial(os.write, w)
        n = write_realtime(iter(pieces), write, 4800, sleep=sleep, clock=lambda: now[0])
        assert n == 14 and os.read(r, 100) == b"$A*41\r\n$B*42\r\n"
    finally:
        os.close(r)
        os.close(w)
    assert waits == pytest.approx([0.1])  # stand time 0: when the first piece is there


def test_on_a_pty_in_real_time() -> None:
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        sim = compass(50.0, baud=38400, sentences=("THS",))
        pieces = sim.until(0.2)
        with SerialReader(path, 38400) as reader:
            write_realtime(iter(pieces), functools.partial(os.write, master), 38400)
            data = b""
            for _ in range(100):  # hang guard; returns once everything is read
                data += b"".join(reader.take(wait_s=1.0).data)
                if len(data) >= sum(len(d) for _, d in pieces):
                    break
        assert data == b"".join(d for _, d in pieces)
    finally:
        os.close(master)
        os.close(slave)


def test_the_stand_rate_must_be_the_sentence_rate() -> None:
    with pytest.raises(SerialSimError, match="heading rate 10 Hz is not the sentence rate 5 Hz"):
        SerialCompass(SerialCompassConfig(rate_hz=5.0)).stand(SimConfig(heading_rate_hz=10.0))


def test_config_is_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        SerialCompassConfig().baud = 9600  # type: ignore[misc]
