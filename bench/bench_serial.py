"""Serial heading source: sentences parsed per second on this machine.

The input is an hour of the simulated compass's line (THS+ROT at 50 Hz, 38400 baud: 360 000
sentences, with 1% checksum errors and 1% garbage), cut into the chunks a port would give (64
bytes). Figures: our path (framing + per-sentence checks + pynmeagps fields + the source's
arrays), pynmeagps's own `NMEAReader` over the same bytes (the reference: it frames and parses
but counts no junk and times nothing), and the TAG-block log written and read back. A line at
38400 baud carries at most 3840 bytes/s: ~100 sentences/s at most, the rate to beat by far.
"""

from __future__ import annotations

import io
import tempfile
import time
from pathlib import Path

import numpy as np
from pynmeagps import NMEAReader

from gyrostand.devices.framing import byte_time_s
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.serial_config import LineFaults
from gyrostand.devices.serial_sim import SerialCompass, SerialCompassConfig
from gyrostand.devices.source import ByteChunks
from gyrostand.devices.tagblock import TagBlockWriter, read_tag_log
from gyrostand.stand.simconfig import SimConfig

BAUD = 38400
CHUNK = 64


class Clock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64)


def line(seconds: float) -> tuple[bytes, list[tuple[float, bytes]]]:
    faults = LineFaults(checksum_error_rate=0.01, garbage_rate=0.01)
    config = SerialCompassConfig(rate_hz=50.0, baud=BAUD, sentences=("THS", "ROT"), faults=faults)
    compass = SerialCompass(config)
    pieces = compass.until(compass.stand(SimConfig(heading_rate_hz=50.0)), seconds)
    data = b"".join(d for _, d in pieces)
    end = pieces[-1][0] + len(pieces[-1][1]) * byte_time_s(BAUD)
    # chunks of CHUNK bytes, each read when its last byte was in (back to back at the end)
    starts = range(0, len(data), CHUNK)
    chunks = [
        (end - (len(data) - s - CHUNK) * byte_time_s(BAUD), data[s : s + CHUNK]) for s in starts
    ]
    return data, chunks


def main() -> None:
    data, chunks = line(3600.0)
    n_sentences = data.count(b"$")
    print(f"line: {len(data)} bytes, {n_sentences} sentences, {len(chunks)} chunks of {CHUNK}")

    source = Iec61162Source(BAUD)
    t0 = time.perf_counter()
    batch = 200
    headings = 0
    for k in range(0, len(chunks), batch):
        part = chunks[k : k + batch]
        out = source.decode(
            ByteChunks(k, tuple(d for _, d in part), np.array([t for t, _ in part])), Clock()
        )
        headings += len(out.headings)
    ours = time.perf_counter() - t0
    print(f"ours:      {n_sentences / ours:10.0f} sentences/s ({headings} headings, {ours:.2f} s)")

    t0 = time.perf_counter()
    parsed = sum(1 for _ in NMEAReader(io.BytesIO(data), quitonerror=0))
    ref = time.perf_counter() - t0
    print(f"pynmeagps: {n_sentences / ref:10.0f} sentences/s ({parsed} parsed, {ref:.2f} s)")

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "line.nmea"
        source = Iec61162Source(BAUD)
        pieces = [p for t, d in chunks for p in source.frame(t, d)]
        t0 = time.perf_counter()
        with TagBlockWriter(log) as writer:
            writer.write(pieces)
        wrote = time.perf_counter() - t0
        t0 = time.perf_counter()
        back = list(read_tag_log(log))
        read = time.perf_counter() - t0
        assert len(back) == len(pieces)
        print(
            f"TAG-block log: write {len(pieces) / wrote:10.0f} lines/s, "
            f"read {len(back) / read:10.0f} lines/s ({log.stat().st_size} bytes)"
        )


if __name__ == "__main__":
    main()
