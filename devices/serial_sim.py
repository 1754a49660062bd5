"""The simulated gyrocompass speaking IEC 61162-1 on a serial line: HDT, THS and ROT sentences
at a chosen rate and baud, from the simulated stand's physics.

The readings are the simulated stand's own: `SerialCompass` is the stand's heading transmitter
(`stand.engine.StandEngine`), so the same rolling error, transient, noise, drops and silences.
In virtual time `SerialCompass.take` gives (stand time of each sample's first byte, its bytes)
directly, so runs are byte-reproducible; `write_realtime` paces them onto a pseudo-terminal.

Fault knobs of the line itself (`LineFaults`): checksum errors, garbage bytes, a silence of the
compass alone, readings marked not valid (THS mode V, an empty HDT field). A compass sending at
another baud rate than the reader's is what a UART at the reader's rate makes of its bits
(`uart_resample`)."""

from __future__ import annotations

import bisect
import contextlib
import fcntl
import math
import os
import termios
import time
from collections.abc import Callable, Iterator

import can
import numpy as np

from gyrostand.analysis.angles import wrap180
from gyrostand.devices.framing import BITS_PER_BYTE, byte_time_s
from gyrostand.devices.nmea0183 import checksum
from gyrostand.devices.serial_config import (
    SerialCompassConfig,
    SerialSimError,
)
from gyrostand.stand.engine import StandEngine
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import SimConfig


def sentence(body: str) -> bytes:
    """`$body*hh<CR><LF>` with its checksum (IEC 61162-1 §7.2.4)."""
    raw = body.encode("ascii")
    return b"$" + raw + b"*%02X\r\n" % checksum(raw)


class SentenceWriter:
    """Heading samples -> the line's bytes: each sample's sentences back to back, the first
    starting at the sample's time, with the line faults applied."""

    def __init__(self, config: SerialCompassConfig) -> None:
        config.check()
        self.config = config
        checksum_seed, garbage_seed, invalid_seed = np.random.SeedSequence(config.seed).spawn(3)
        self._checksum_rng = np.random.default_rng(checksum_seed)
        self._garbage_rng = np.random.default_rng(garbage_seed)
        self._invalid_rng = np.random.default_rng(invalid_seed)
        self._byte_s = byte_time_s(config.baud)
        self._last: tuple[float, float] | None = None  # time, heading of the last valid sample

    def write(self, t_s: np.ndarray, reading_deg: np.ndarray) -> list[tuple[float, bytes]]:
        """(time of the first byte, bytes) per sample (stand time s, reading deg)."""
        c, f = self.config, self.config.faults
        out: list[tuple[float, bytes]] = []
        for t, deg in zip(t_s.tolist(), reading_deg.tolist(), strict=True):
            valid = bool(self._invalid_rng.random() >= f.not_valid_rate)
            lines = [self._sentence(kind, t, deg, valid) for kind in c.sentences]
            if valid:
                self._last = (t, deg)
            silent_from = f.line_silence_at_s
            if silent_from is not None and silent_from <= t < silent_from + f.line_silence_for_s:
                continue
            data = b"".join(lines)
            if self._garbage_rng.random() < f.garbage_rate:
                n = int(self._garbage_rng.integers(1, 9))
                garbage = self._garbage_rng.integers(0x80, 0x100, n, dtype=np.uint8).tobytes()
                data = garbage + data
                t -= n * self._byte_s  # the sentence itself still starts at the sample time
            if f.sender_baud is not None and f.sender_baud != c.baud:
                data = uart_resample(data, f.sender_baud, c.baud)
            out.append((t, data))
        return out

    def _sentence(self, kind: str, t: float, deg: float, valid: bool) -> bytes:
        c, f = self.config, self.config.faults
        if kind == "HDT":  # IEC 61162-1 HDT has no status: a reading not valid is left empty
            line = sentence(f"{c.talker}HDT,{_angle(deg, 1)},T" if valid else f"{c.talker}HDT,,T")
        elif kind == "THS":
            line = sentence(f"{c.talker}THS,{_angle(deg, 2)},{'A' if valid else 'V'}")
        else:
            rate = 0.0
            if self._last is not None and t > self._last[0]:  # deg/min from the last reading
                rate = float(wrap180(deg - self._last[1])) / (t - self._last[0]) * 60.0
            line = sentence(f"{c.talker}ROT,{rate:.1f},{'A' if valid else 'V'}")
        if self._checksum_rng.random() < f.checksum_error_rate:
            wrong = (int(line[-4:-2], 16) ^ 0x01) & 0xFF
            line = line[:-4] + b"%02X\r\n" % wrong
        return line


def _angle(deg: float, decimals: int) -> str:
    """A heading in [0, 360) with `decimals` decimals (359.96 to one decimal is 0.0, not 360.0)."""
    value = round(deg, decimals)
    return f"{value - 360.0 if value >= 360.0 else value:.{decimals}f}"


class SerialCompass:
    """The simulated stand's compass on a serial line, as the stand's heading transmitter
    (`stand.engine.HeadingTransmitter`): it sends no CAN frame; `take` gives the line's bytes
    of the samples the stand has computed since the last call."""

    def __init__(self, config: SerialCompassConfig) -> None:
        self.config = config
        self._writer = SentenceWriter(config)
        self._pending: list[tuple[float, bytes]] = []

    def frames(
        self, t_s: np.ndarray, reading_deg: np.ndarray, index: np.ndarray
    ) -> list[can.Message]:
        self._pending += self._writer.write(t_s, reading_deg)
        return []

    def take(self) -> list[tuple[float, bytes]]:
        """(stand time of the first byte, bytes) of each sample since the last call."""
        pieces, self._pending = self._pending, []
        return pieces

    def stand(self, config: SimConfig, codec: Codec | None = None) -> StandEngine:
        """A simulated stand whose compass this is (its heading rate: the sentence rate)."""
        if abs(config.heading_rate_hz - self.config.rate_hz) > 1e-9:
            raise SerialSimError(
                f"the stand's heading rate {config.heading_rate_hz:g} Hz is not the "
                f"sentence rate {self.config.rate_hz:g} Hz"
            )
        return StandEngine(config, codec, transmitter=self)

    def until(self, engine: StandEngine, t_s: float) -> list[tuple[float, bytes]]:
        """Advance `engine` (this compass's stand) to stand time t_s; the line's bytes by then."""
        engine.advance_to(t_s)
        return self.take()

    def line(
        self, engine: StandEngine, duration_s: float | None = None, step_s: float = 0.1
    ) -> Iterator[tuple[float, bytes]]:
        """The line's bytes sample by sample, `engine` advanced `step_s` at a time (until
        `duration_s` of stand time, or for ever): for `write_realtime`."""
        t = 0.0
        while duration_s is None or t < duration_s:
            t += step_s
            yield from self.until(engine, t)


class VirtualLine:
    """The simulated compass's line in virtual time: its bytes written to a pseudo-terminal
    at once (the reader gets them through the real port path), and when each would have been
    received (`received`, a `SerialReader`'s line clock): the simulation's times, so a run is
    byte-reproducible however the reads cut the stream."""

    def __init__(self, baud: int) -> None:
        self.master, self._slave = os.openpty()
        self.path = os.ttyname(self._slave)
        self._byte_s = byte_time_s(baud)
        self._starts: list[int] = []  # stream offset of each piece's first byte ...
        self._times: list[float] = []  # ... and its stand time
        self.written = 0

    def write(self, pieces: list[tuple[float, bytes]]) -> None:
        for t, data in pieces:
            self._starts.append(self.written)
            self._times.append(t)
            self.written += len(data)
        data = memoryview(b"".join(d for _, d in pieces))
        while data:  # (blocks while the reader lags)
            data = data[os.write(self.master, data) :]

    def time_at(self, n: int) -> float:
        """When the line's n-th byte had been received (the end of its 10 bits)."""
        i = bisect.bisect_right(self._starts, n - 1) - 1
        return self._times[i] + (n - self._starts[i]) * self._byte_s

    def received(self, offset: int, data: bytes) -> list[tuple[float, bytes]]:
        """Bytes read at stream `offset` as a reader keeping up with the line reads them: cut
        where the line fell idle between samples, each part timed when its last byte was in."""
        end = offset + len(data)
        lo = bisect.bisect_right(self._starts, offset)
        hi = bisect.bisect_left(self._starts, end)
        cuts = [offset, *self._starts[lo:hi], end]
        return [
            (self.time_at(b), data[a - offset : b - offset])
            for a, b in zip(cuts, cuts[1:], strict=False)
            if b > a
        ]

    def close(self) -> None:
        os.close(self.master)
        os.close(self._slave)


class PtyLine:
    """A pseudo-terminal pair as the compass's line: `write` to the master; a reader opens
    `path`, the slave's. The slave stays open here so the path lasts while readers come and go,
    and what nobody has read for a second is dropped (a line keeps no bytes nobody receives)."""

    def __init__(self, baud: int) -> None:
        self.master, self._slave = os.openpty()
        self.path = os.ttyname(self._slave)
        self._keep = baud // BITS_PER_BYTE  # one second of the line
        flags = fcntl.fcntl(self.master, fcntl.F_GETFL)
        fcntl.fcntl(self.master, fcntl.F_SETFL, flags | os.O_NONBLOCK)

    def write(self, data: bytes) -> None:
        pending = int.from_bytes(fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0"), "little")
        if pending > self._keep:
            termios.tcflush(self._slave, termios.TCIFLUSH)
        with contextlib.suppress(BlockingIOError):
            os.write(self.master, data)

    def close(self) -> None:
        os.close(self.master)
        os.close(self._slave)


def uart_resample(data: bytes, tx_baud: int, rx_baud: int) -> bytes:
    """What a UART at rx_baud reads of `data` sent back to back at tx_baud (8N1, idle high):
    it waits for a low level (start bit), samples 8 data bits at their middles, checks the stop
    bit; a byte with a framing error is read as NUL (POSIX termios without IGNPAR/PARMRK)."""
    frame = np.unpackbits(np.frombuffer(data, np.uint8)[:, None], axis=1, bitorder="little")
    bits = np.hstack([np.zeros((len(data), 1), np.uint8), frame, np.ones((len(data), 1), np.uint8)])
    line = bits.ravel()
    end_s = len(line) / tx_baud

    def level(t: float) -> int:
        i = math.floor(t * tx_baud)
        return int(line[i]) if 0 <= i < len(line) else 1

    out = bytearray()
    t = 0.0
    while t < end_s:
        i = math.floor(t * tx_baud)
        low = np.flatnonzero(line[i:] == 0)
        if not len(low):
            break
        start = max(t, (i + int(low[0])) / tx_baud)
        value = sum(level(start + (k + 1.5) / rx_baud) << k for k in range(8))
        out.append(value if level(start + 9.5 / rx_baud) else 0)
        t = start + 9.5 / rx_baud
    return bytes(out)


def write_realtime(
    pieces: Iterator[tuple[float, bytes]],
    write: Callable[[bytes], object],
    baud: int,
    *,
    stop: Callable[[], bool] = lambda: False,
    sleep: Callable[[float], None] = time.sleep,
    clock: Callable[[], float] = time.monotonic,
) -> int:
    """`write` each piece when its last byte would have arrived on a real line (its first
    byte's stand time plus its length on the wire at `baud`); stand time 0 is set when the first
    piece is there (the simulation's start-up is no delay of the line). The bytes written."""
    byte_s = byte_time_s(baud)
    t0: float | None = None
    written = 0
    for t_s, data in pieces:
        if stop():
            break
        offset = t_s + len(data) * byte_s
        if t0 is None:
            t0 = clock() - offset
        wait = t0 + offset - clock()
        if wait > 0:
            sleep(wait)
        write(data)
        written += len(data)
    return written
