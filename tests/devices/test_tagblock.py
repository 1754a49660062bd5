"""TAG-block raw logs: written as IEC 61162-450 lines, read back exactly, a replay equal to live."""

from pathlib import Path

import numpy as np
import pytest

from gyrostand.devices.framing import GARBAGE, Received
from gyrostand.devices.iec61162 import Iec61162Source
from gyrostand.devices.nmea0183 import checksum
from gyrostand.devices.serial_config import LineFaults
from gyrostand.devices.serial_sim import SerialCompass, SerialCompassConfig
from gyrostand.devices.source import ByteChunks
from gyrostand.devices.tagblock import TagBlockWriter, read_tag_log, tag_line
from gyrostand.frames.logfile import LogFileError, sha256_of
from gyrostand.stand.simconfig import SimConfig


class Clock:
    def to_campaign_ms(self, pos: np.ndarray, rx_s: np.ndarray) -> np.ndarray:
        return np.rint(rx_s * 1000).astype(np.int64) - 1_700_000_000_000


def test_tag_block_checksum_as_published() -> None:
    # gpsd's AIVDM documentation (NMEA 4.0 TAG blocks), before an !AIVDM sentence:
    # \g:1-2-73874,n:157036,s:r003669945,c:1241544035*4A\
    assert checksum(b"g:1-2-73874,n:157036,s:r003669945,c:1241544035") == 0x4A


def test_lines() -> None:
    assert tag_line(Received(1700000000.1234, b"$HEHDT,119.9,T*2F")) == (
        b"\\c:1700000000123*%02X\\$HEHDT,119.9,T*2F\r\n" % checksum(b"c:1700000000123")
    )
    junk = tag_line(Received(1.0, b"\xff\\x", GARBAGE))
    assert junk == b"\\c:1000,t:garbage*%02X\\\\xFF\\x5Cx\r\n" % checksum(b"c:1000,t:garbage")


def live_run(tmp_path: Path) -> tuple[Path, list, Iec61162Source]:  # type: ignore[type-arg]
    faults = LineFaults(checksum_error_rate=0.1, garbage_rate=0.2, not_valid_rate=0.1)
    sim = SerialCompass(SerialCompassConfig(sentences=("THS", "ROT"), faults=faults))
    pieces = sim.until(sim.stand(SimConfig(seed=2)), 20.0)
    # as a port would read them: each piece in two chunks, times as UNIX time
    data, times = [], []
    for t, d in pieces:
        data += [d[:5], d[5:]]
        times += [1_700_000_000 + t + 5 / 480, 1_700_000_000 + t + len(d) / 480]
    log = tmp_path / "compass.nmea"
    outputs = []
    with TagBlockWriter(log) as writer:
        source = Iec61162Source(4800, raw_log=writer)
        for k in range(0, len(data), 30):  # decoded in batches, as the acquisition does
            chunks = ByteChunks(k, tuple(data[k : k + 30]), np.array(times[k : k + 30]))
            outputs.append(source.decode(chunks, Clock()))
        outputs.append(source.close(Clock()))
    return log, outputs, source


def test_replay_from_the_log_is_the_live_run(tmp_path: Path) -> None:
    log, live, source = live_run(tmp_path)
    replayed = Iec61162Source(4800).decode_pieces(list(read_tag_log(log)), Clock())
    cat = np.concatenate
    for name in ("pos", "t_ms", "heading_deg", "valid", "counter"):
        a = cat([getattr(o.headings, name) for o in live])
        assert a.tolist() == getattr(replayed.headings, name).tolist(), name
    assert [i for o in live for i in o.invalid] == list(replayed.invalid)
    assert [e for o in live for e in o.events] == list(replayed.events)
    kinds = {r.split(" (")[0] for _, f in replayed.invalid for r in [f.reason]}
    assert kinds >= {"checksum mismatch", "garbage bytes", "THS mode V"}
    assert len(replayed.headings) > 100
    assert len(sha256_of(log)) == 64


def test_a_cut_last_line_ends_the_log(tmp_path: Path) -> None:
    log, _, _ = live_run(tmp_path)
    whole = list(read_tag_log(log))
    data = log.read_bytes()
    log.write_bytes(data[:-7])
    assert list(read_tag_log(log)) == whole[:-1]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"$HEHDT,119.9,T*2F\r\n", "line 1: no TAG block"),
        (b"\\c:1000*00\\$HEHDT,119.9,T*2F\r\n", "line 1: TAG block checksum mismatch"),
        (b"\\s:HE01*%02X\\$A\r\nmore\r\n" % checksum(b"s:HE01"), "line 1: no c: time"),
    ],
)
def test_a_log_that_is_not_ours_is_one_line(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "x.nmea"
    path.write_bytes(content)
    with pytest.raises(LogFileError) as err:
        list(read_tag_log(path))
    assert str(err.value).startswith(f"{path}: {message}")
