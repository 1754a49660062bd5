"""The numpy BLF reader gives the frames python-can's BLFReader gives, also for a file whose
writer was killed (truncated tail)."""

from pathlib import Path

import can
import numpy as np

from gyrostand.frames.logfile import read_blf, read_raw_frames


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
                    bool(raw.is_error[r]),
                    bool(raw.is_remote[r]),
                    bytes(raw.data[r, : int(raw.dlc[r])]),
                )
            )
    return rows


def expected(messages: list[can.Message]) -> list[tuple]:
    return [
        (m.arbitration_id, m.is_error_frame, m.is_remote_frame, bytes(m.data)) for m in messages
    ]


def test_numpy_blf_reader_equals_python_can(tmp_path: Path) -> None:
    path = tmp_path / "x.blf"
    messages = sample_messages(20_000)
    with can.BLFWriter(path) as writer:
        for m in messages:
            writer.on_message_received(m)
    reference = expected(list(can.BLFReader(path)))
    assert len(reference) == len(messages)
    got = flat(read_blf(path, chunk=3000))
    assert got == reference
    positions = [raw.start for raw in read_blf(path, chunk=3000)]
    assert positions[0] == 0 and positions == sorted(positions)


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


def test_asc_goes_through_python_can(tmp_path: Path) -> None:
    path = tmp_path / "x.asc"
    messages = [m for m in sample_messages(500) if not m.is_error_frame]
    with can.ASCWriter(path) as writer:
        for m in messages:
            writer.on_message_received(m)
    assert flat(read_raw_frames(path, chunk=64)) == expected(messages)


def test_batch_blf_writer_equals_python_can_writer(tmp_path: Path) -> None:
    from gyrostand.frames.batch import RawFrames
    from gyrostand.frames.logfile import BatchBLFWriter

    messages = sample_messages(5000)
    for i, m in enumerate(messages):
        m.timestamp = 1_700_000_000.0 + i * 0.001
    ours, theirs = tmp_path / "ours.blf", tmp_path / "theirs.blf"
    with BatchBLFWriter(ours) as writer:
        for start in range(0, len(messages), 777):
            writer.write_frames(RawFrames.from_messages(start, messages[start : start + 777]))
    with can.BLFWriter(theirs) as writer:
        for m in messages:
            writer.on_message_received(m)
    a, b = list(can.BLFReader(ours)), list(can.BLFReader(theirs))
    assert [
        (
            m.arbitration_id,
            m.is_extended_id,
            m.is_error_frame,
            m.is_remote_frame,
            m.dlc,
            bytes(m.data),
            m.timestamp,
        )
        for m in a
    ] == [
        (
            m.arbitration_id,
            m.is_extended_id,
            m.is_error_frame,
            m.is_remote_frame,
            m.dlc,
            bytes(m.data),
            m.timestamp,
        )
        for m in b
    ]
    assert ours.read_bytes()[144:] == theirs.read_bytes()[144:]  # same containers, byte for byte
