"""The BLF log: our writer writes byte for byte the reference files (made by the python-can based
writer it replaced) and what python-can's BLFWriter writes, python-can's BLFReader reads our files
back, our numpy reader gives the frames python-can's BLFReader gives, also for a file whose
writer was killed (truncated tail, or kill -9 during acquisition)."""

import itertools
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import can
import numpy as np
import pytest

from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import ZLIB_LEVEL, BatchBLFWriter, read_blf, read_raw_frames

DATA = Path(__file__).parent / "data"
# made by the writer this module replaced (python-can 4.6.1's BLFWriter plus a numpy batch
# method, commit 58c8595) from reference_batches(): the default 128 KiB containers, and 2 KiB;
# zlib level 6 (python-can's default then; ours is ZLIB_LEVEL, pinned against can.BLFWriter)
REFERENCES = {
    "reference.blf": {"compression_level": 6},
    "reference-2k-containers.blf": {"max_container_size": 2048, "compression_level": 6},
}
REFERENCE_T0 = 1_700_000_000.1234567  # a Unix time: the header holds start and stop dates
REFERENCE_CUTS = (0, 1, 1, 50, 173, 174, 400, 523, 600)  # batch bounds (one batch is empty)


def reference_messages() -> list[can.Message]:
    """600 frames without a random generator (the same on every numpy): 11- and 29-bit frames,
    short payloads, remote frames, error frames (the first frame is one), one frame stamped
    before the file start."""
    out, x = [], 1
    for i in range(600):
        x = (x * 1103515245 + 12345) % 2**31
        payload = x.to_bytes(4, "little") + (x ^ 0x5A5A5A5A).to_bytes(4, "big")
        extended = i % 5 == 0
        ident = (x >> 3) & (0x1FFFFFFF if extended else 0x7FF)
        t = REFERENCE_T0 - 0.5 if i == 300 else REFERENCE_T0 + i * 0.000731 + (x % 1000) * 1e-9
        common = {"timestamp": t, "arbitration_id": ident, "is_extended_id": extended}
        if i % 97 == 0:
            out.append(can.Message(is_error_frame=True, data=payload[: 4 + i % 5], **common))
        elif i % 53 == 0:
            out.append(can.Message(is_remote_frame=True, dlc=4, **common))
        else:
            out.append(can.Message(data=payload[: 8 if i % 13 else x % 9], **common))
    return out


def reference_batches() -> list[RawFrames]:
    messages = reference_messages()
    return [
        RawFrames.from_messages(lo, messages[lo:hi])
        for lo, hi in itertools.pairwise(REFERENCE_CUTS)
    ]


def sample_messages(n: int) -> list[can.Message]:
    rng = np.random.default_rng(5)
    out = []
    for i in range(n):
        if i % 97 == 0:
            out.append(
                can.Message(timestamp=i, is_error_frame=True, arbitration_id=0x40, data=bytes(8))
            )
            continue
        dlc = 8 if i % 13 else int(rng.integers(0, 8))
        out.append(
            can.Message(
                timestamp=i * 0.01,
                arbitration_id=int(rng.integers(0, 0x7FF)) if i % 5 else 0x1ABCDE0 + i,
                is_extended_id=not i % 5,
                is_remote_frame=i % 211 == 0,
                data=rng.integers(0, 256, dlc, dtype=np.uint8).tobytes(),
            )
        )
    return out


def flat(batches) -> list[tuple]:
    rows = []
    for raw in batches:
        for r in range(len(raw)):
            rows.append(
                (
                    int(raw.arbitration_id[r]),
                    bool(raw.is_extended[r]),
                    bool(raw.is_error[r]),
                    bool(raw.is_remote[r]),
                    bytes(raw.data[r, : int(raw.dlc[r])]),
                )
            )
    return rows


def expected(messages: list[can.Message]) -> list[tuple]:
    return [
        (m.arbitration_id, m.is_extended_id, m.is_error_frame, m.is_remote_frame, bytes(m.data))
        for m in messages
    ]


def timestamps(batches) -> np.ndarray:
    return np.concatenate([raw.timestamp for raw in batches])


@pytest.mark.parametrize("name", REFERENCES)
def test_writer_writes_the_reference_bytes(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    with BatchBLFWriter(path, **REFERENCES[name]) as writer:
        for raw in reference_batches():
            writer.write_frames(raw)
    assert path.read_bytes() == (DATA / name).read_bytes()


@pytest.mark.parametrize("name", REFERENCES)
def test_python_can_reads_our_file(name: str) -> None:
    messages = reference_messages()
    reader = can.BLFReader(DATA / name)
    assert (reader.object_count, reader.start_timestamp) == (600, int(REFERENCE_T0 * 1000) / 1000)
    got = list(reader)
    assert expected(got) == expected(messages)
    # the length a remote frame asks for is not kept (RawFrames.dlc is the payload length)
    assert [(m.dlc, m.is_rx, m.channel, m.is_fd) for m in got] == [
        (len(m.data), True, 0, False) for m in messages
    ]
    # BLF keeps ns from a start truncated to ms; a Unix time in a float keeps ~0.24 us
    start = reader.start_timestamp
    want = np.maximum([m.timestamp for m in messages], start)
    np.testing.assert_allclose([m.timestamp for m in got], want, rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", REFERENCES)
def test_our_reader_reads_our_file(name: str) -> None:
    messages = reference_messages()
    batches = list(read_blf(DATA / name, chunk=100))
    assert flat(batches) == expected(messages)
    start = int(REFERENCE_T0 * 1000) / 1000
    want = np.maximum([m.timestamp - start for m in messages], 0)
    np.testing.assert_allclose(timestamps(batches), want, rtol=0, atol=1e-9)


def test_numpy_blf_reader_equals_python_can(tmp_path: Path) -> None:
    """A file of python-can's BLFWriter with other objects than CAN_MESSAGE: error frames
    (CAN_ERROR_EXT), CAN FD frames (CAN_FD_MESSAGE), markers (GLOBAL_MARKER, no frame)."""
    path = tmp_path / "x.blf"
    messages = sample_messages(20_000)
    for i in range(3, len(messages), 301):
        if not (messages[i].is_error_frame or messages[i].is_remote_frame):
            messages[i].is_fd = True
    with can.BLFWriter(path) as writer:
        for i, m in enumerate(messages):
            writer.on_message_received(m)
            if i % 1009 == 0:
                writer.log_event(f"marker {i}", m.timestamp)
    reader = can.BLFReader(path)
    reference = list(reader)
    assert len(reference) == len(messages) and any(m.is_fd for m in reference)
    batches = list(read_blf(path, chunk=3000))
    assert flat(batches) == expected(reference)
    np.testing.assert_allclose(
        timestamps(batches) + reader.start_timestamp,
        [m.timestamp for m in reference],
        rtol=0,
        atol=1e-9,
    )
    positions = [raw.start for raw in batches]
    assert positions[0] == 0 and positions == sorted(positions)


def test_batch_blf_writer_equals_python_can_writer(tmp_path: Path) -> None:
    """Several default (128 KiB) containers, with error frames and remote frames: the objects
    python-can's BLFWriter writes at our zlib level, byte for byte (the header is pinned by the
    references)."""
    messages = sample_messages(5000)
    for i, m in enumerate(messages):
        m.timestamp = 1_700_000_000.0 + i * 0.001
    ours, theirs = tmp_path / "ours.blf", tmp_path / "theirs.blf"
    with BatchBLFWriter(ours) as writer:
        for start in range(0, len(messages), 777):
            writer.write_frames(RawFrames.from_messages(start, messages[start : start + 777]))
    with can.BLFWriter(theirs, compression_level=ZLIB_LEVEL) as writer:
        for m in messages:
            writer.on_message_received(m)
    assert ours.read_bytes()[144:] == theirs.read_bytes()[144:]
    assert ours.read_bytes().count(b"LOBJ") >= 2  # more than one container


def test_truncated_blf_gives_what_was_flushed(tmp_path: Path) -> None:
    path = tmp_path / "killed.blf"
    messages = sample_messages(20_000)
    writer = can.BLFWriter(path)
    for m in messages:
        writer.on_message_received(m)
    writer.file.flush()  # as if the process died here: last container unwritten, no header
    data = path.read_bytes()
    cut = tmp_path / "cut.blf"
    cut.write_bytes(data[: len(data) - 100])  # and a torn last object
    got = flat(read_blf(cut))
    assert 0 < len(got) < len(messages)
    assert got == expected(messages)[: len(got)]
    writer.stop()


def test_our_truncated_file_reads_to_its_last_complete_container(tmp_path: Path) -> None:
    data = (DATA / "reference-2k-containers.blf").read_bytes()
    whole = flat(read_blf(DATA / "reference-2k-containers.blf"))
    lengths = []
    for size in range(144, len(data), 997):
        cut = tmp_path / "cut.blf"
        cut.write_bytes(data[:size])
        got = flat(read_blf(cut))
        assert got == whole[: len(got)]
        lengths.append(len(got))
    assert lengths == sorted(lengths) and 0 < lengths[-1] < len(whole)


KILLED_WRITER = """
import sys
from pathlib import Path
import can
from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import BatchBLFWriter

messages = [
    can.Message(
        timestamp=i * 1e-3,
        arbitration_id=i % 2048,
        is_extended_id=False,
        data=(i * 7919).to_bytes(8, "little"),
    )
    for i in range(3000)
]
writer = BatchBLFWriter(Path(sys.argv[1]), max_container_size=4096)
for lo in range(0, len(messages), 250):
    writer.write_frames(RawFrames.from_messages(lo, messages[lo : lo + 250]))
print("written", flush=True)
sys.stdin.read()  # killed here, never stopped
"""


def test_kill_9_keeps_every_full_container(tmp_path: Path) -> None:
    path = tmp_path / "live.blf"
    proc = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(KILLED_WRITER), str(path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline() == "written\n"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    got = flat(read_blf(path))
    full_containers = 3000 * 48 // 4096  # 48-byte objects, 4 KiB containers
    assert len(got) == full_containers * 4096 // 48
    assert got == [
        (i % 2048, False, False, False, (i * 7919).to_bytes(8, "little")) for i in range(len(got))
    ]


def test_asc_goes_through_python_can(tmp_path: Path) -> None:
    path = tmp_path / "x.asc"
    messages = [m for m in sample_messages(500) if not m.is_error_frame]
    with can.ASCWriter(path) as writer:
        for m in messages:
            writer.on_message_received(m)
    assert flat(read_raw_frames(path, chunk=64)) == expected(messages)


def test_two_buses_channels_as_python_can_writes_and_reads_them(tmp_path: Path) -> None:
    """Frames of a compass on its own bus (`RawFrames.channel` 1) among the stand's (0), error
    frames on both: the objects python-can's BLFWriter writes for messages of `channel` 0 and 1,
    byte for byte (BLF channels 1 and 2); python-can's BLFReader and ours give the channels back;
    a one-bus batch (all 0) is what python-can writes for messages without a channel."""
    messages = sample_messages(3000)
    for i, m in enumerate(messages):
        m.timestamp = 1_700_000_000.0 + i * 0.001
        m.channel = i % 3 % 2  # two of three on the stand's bus
    ours, theirs = tmp_path / "ours.blf", tmp_path / "theirs.blf"
    with BatchBLFWriter(ours) as writer:
        for start in range(0, len(messages), 777):
            batch = messages[start : start + 777]
            writer.write_frames(RawFrames.from_messages(start, batch, channels=True))
    with can.BLFWriter(theirs, compression_level=ZLIB_LEVEL) as writer:
        for m in messages:
            writer.on_message_received(m)
    assert ours.read_bytes()[144:] == theirs.read_bytes()[144:]
    sent = [m.channel for m in messages]
    assert [m.channel for m in can.BLFReader(ours)] == sent
    assert np.concatenate([raw.channel for raw in read_blf(ours)]).tolist() == sent
    assert np.concatenate([raw.channel for raw in read_raw_frames(ours)]).tolist() == sent
    one_bus = RawFrames.from_messages(0, messages)
    assert not one_bus.channel.any()
