"""Raw CAN log files: writing them during acquisition, reading them back for replay.

ASC and other formats go through python-can's writers and readers. BLF, the default, is written
by `BatchBLFWriter` (python-can's BLFWriter plus a method that packs a whole batch of frames with
numpy: python-can packs one frame per call, ~6 us, more than the rest of the ingest path together)
and read by `read_blf`, a numpy parser of its CAN_MESSAGE objects (python-can's BLFReader builds
one `can.Message` per frame, ~10^5 frames/s: a 10^7-frame replay would take minutes).
"""

from __future__ import annotations

import hashlib
import itertools
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path

import can
import numpy as np

from gyrostand.frames.batch import RawFrames

CHUNK_FRAMES = 200_000


def sha256_of(path: Path) -> str:
    """The SHA-256 of a file (the raw log's fingerprint stored with the campaign)."""
    with path.open("rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


# BLF layout (the same constants python-can's can/io/blf.py uses)
_FILE_HEADER = struct.Struct("<4sLBBBBBBBBQQLL8H8H")
_OBJ_HEADER_BASE = struct.Struct("<4sHHLL")
_LOG_CONTAINER = struct.Struct("<H6xL4x")
_LOG_CONTAINER_TYPE = 10
_CAN_MESSAGE = 1
_ZLIB_DEFLATE = 2
# one CAN_MESSAGE object: base header (16), header v1 (16: flags, client, version, timestamp),
# channel u16, flags u8, dlc u8, id u32, data 8
_CAN_MESSAGE_DTYPE = np.dtype(
    [
        ("signature", "S4"),
        ("header_size", "<u2"),
        ("header_version", "<u2"),
        ("obj_size", "<u4"),
        ("obj_type", "<u4"),
        ("flags", "<u4"),
        ("client", "<u2"),
        ("version", "<u2"),
        ("timestamp", "<u8"),
        ("channel", "<u2"),
        ("msg_flags", "u1"),
        ("dlc", "u1"),
        ("can_id", "<u4"),
        ("data", "u1", (8,)),
    ]
)
_CAN_MSG_EXT = 0x80000000
_REMOTE_FLAG = 0x80
_TIME_TEN_MICS = 0x1
_TIME_ONE_NANS = 0x2


def read_raw_frames(path: Path, chunk: int = CHUNK_FRAMES) -> Iterator[RawFrames]:
    """The frames of a log file in stream order, in batches of about `chunk` frames."""
    if path.suffix.lower() == ".blf":
        yield from read_blf(path, chunk)
        return
    start = 0
    reader = can.LogReader(path)
    try:
        iterator = iter(reader)
        while batch := list(itertools.islice(iterator, chunk)):
            yield RawFrames.from_messages(start, batch)
            start += len(batch)
    finally:
        reader.stop()


def read_blf(path: Path, chunk: int = CHUNK_FRAMES) -> Iterator[RawFrames]:
    """BLF frames as arrays. Runs of CAN_MESSAGE objects are viewed with one numpy dtype; any
    other object (error frames, CAN FD, markers) goes through python-can's own object parser,
    so identifiers, flags and payloads are those `can.BLFReader` gives (timestamps are relative
    to the file start: replay times by the stand time inside the frames)."""
    start = 0
    pending: list[RawFrames] = []
    pending_n = 0
    for part in _blf_parts(path):
        pending.append(part)
        pending_n += len(part)
        if pending_n >= chunk:
            yield _concat(start, pending)
            start += pending_n
            pending, pending_n = [], 0
    if pending_n:
        yield _concat(start, pending)


def _concat(start: int, parts: list[RawFrames]) -> RawFrames:
    return RawFrames(
        start,
        np.concatenate([p.arbitration_id for p in parts]),
        np.concatenate([p.dlc for p in parts]),
        np.concatenate([p.data for p in parts]),
        np.concatenate([p.is_error for p in parts]),
        np.concatenate([p.is_remote for p in parts]),
        np.concatenate([p.is_extended for p in parts]),
        np.concatenate([p.timestamp for p in parts]),
    )


def _containers(path: Path) -> Iterator[bytes]:
    """The uncompressed payloads of the file's LOG_CONTAINER objects, in order."""
    with path.open("rb") as f:
        header = f.read(_FILE_HEADER.size)
        if len(header) < _FILE_HEADER.size or header[:4] != b"LOGG":
            raise ValueError(f"{path}: not a BLF file")
        f.seek(_FILE_HEADER.unpack(header)[1])
        while True:
            base = f.read(_OBJ_HEADER_BASE.size)
            if len(base) < _OBJ_HEADER_BASE.size:
                return
            signature, _, _, obj_size, obj_type = _OBJ_HEADER_BASE.unpack(base)
            if signature != b"LOBJ":
                return  # a truncated tail (e.g. the writer was killed)
            body = f.read(obj_size - _OBJ_HEADER_BASE.size)
            f.seek(obj_size % 4, 1)
            if obj_type != _LOG_CONTAINER_TYPE or len(body) < obj_size - _OBJ_HEADER_BASE.size:
                if len(body) < obj_size - _OBJ_HEADER_BASE.size:
                    return
                continue
            method, _ = _LOG_CONTAINER.unpack_from(body)
            data = body[_LOG_CONTAINER.size :]
            yield zlib.decompress(data) if method == _ZLIB_DEFLATE else data


def _blf_parts(path: Path) -> Iterator[RawFrames]:
    tail = b""
    for container in _containers(path):
        data = tail + container
        pos = 0
        size = _CAN_MESSAGE_DTYPE.itemsize
        while pos + size <= len(data):
            run = _can_message_run(data, pos)
            if run:
                yield _frames_of(np.frombuffer(data, _CAN_MESSAGE_DTYPE, run, pos))
                pos += run * size
                continue
            consumed, frames = _other_objects(data, pos)
            if consumed == 0:
                break  # an object continues in the next container
            pos += consumed
            if frames:
                yield RawFrames.from_messages(0, frames)
        tail = data[pos:]


def _can_message_run(data: bytes, pos: int) -> int:
    """How many CAN_MESSAGE objects (v1 header, 48 bytes each) follow back to back at pos."""
    size = _CAN_MESSAGE_DTYPE.itemsize
    count = (len(data) - pos) // size
    if count == 0:
        return 0
    view = np.frombuffer(data, _CAN_MESSAGE_DTYPE, count, pos)
    ok = (
        (view["signature"] == b"LOBJ")
        & (view["obj_type"] == _CAN_MESSAGE)
        & (view["obj_size"] == size)
        & (view["header_version"] == 1)
    )
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if len(bad) else count


def _frames_of(objs: np.ndarray) -> RawFrames:
    can_id = objs["can_id"]
    factor = np.where(objs["flags"] & _TIME_TEN_MICS, 1e-5, 1e-9)
    return RawFrames(
        start=0,
        arbitration_id=(can_id & 0x1FFFFFFF).astype(np.uint32),
        dlc=np.minimum(objs["dlc"], 8).astype(np.int64),
        data=np.ascontiguousarray(objs["data"]),
        is_error=np.zeros(len(objs), dtype=bool),
        is_remote=(objs["msg_flags"] & _REMOTE_FLAG).astype(bool),
        is_extended=(can_id & _CAN_MSG_EXT).astype(bool),
        timestamp=objs["timestamp"].astype(np.float64) * factor,
    )


def _other_objects(data: bytes, pos: int) -> tuple[int, list[can.Message]]:
    """Parse the one object at pos with python-can (whatever its type); bytes consumed (0 when
    it is incomplete) and the frames it holds."""
    signature, _, _, obj_size, _ = _OBJ_HEADER_BASE.unpack_from(data, pos)
    if signature != b"LOBJ":
        nxt = data.find(b"LOBJ", pos + 1)
        return (nxt - pos if nxt > 0 else 0), []
    end = pos + obj_size
    if end > len(data):
        return 0, []
    # python-can's per-object parser, without opening the file again: it needs only these two
    # attributes of a reader
    reader = can.BLFReader.__new__(can.BLFReader)
    reader._pos, reader.start_timestamp = 0, 0.0  # type: ignore[attr-defined]
    frames = list(reader._parse_data(data[pos:end]))  # type: ignore[attr-defined]
    return obj_size + (obj_size % 4), frames


class BatchBLFWriter(can.BLFWriter):
    """python-can's BLFWriter (same file header, containers, compression and closing) with
    `write_frames`, which adds a whole `RawFrames` batch at once."""

    def write_frames(self, raw: RawFrames) -> None:
        """Append every frame of the batch, in order (error frames through python-can)."""
        errors = np.flatnonzero(raw.is_error).tolist()
        start = 0
        for row in [*errors, len(raw)]:
            if row > start:
                self._add_can_messages(raw, start, row)
            if row < len(raw):
                self.on_message_received(raw.message(row))
            start = row + 1

    def _add_can_messages(self, raw: RawFrames, lo: int, hi: int) -> None:
        ts = raw.timestamp[lo:hi]
        if self.start_timestamp is None:  # as BLFWriter._add_object: ms precision
            self.start_timestamp = int(float(ts[0]) * 1000) / 1000
        self.stop_timestamp = float(ts[-1])
        objs = np.zeros(hi - lo, _CAN_MESSAGE_DTYPE)
        objs["signature"] = b"LOBJ"
        objs["header_size"] = 32
        objs["header_version"] = 1
        objs["obj_size"] = _CAN_MESSAGE_DTYPE.itemsize
        objs["obj_type"] = _CAN_MESSAGE
        objs["flags"] = _TIME_ONE_NANS
        objs["timestamp"] = np.maximum(((ts - self.start_timestamp) * 1e9).astype(np.int64), 0)
        objs["channel"] = self.channel
        objs["msg_flags"] = np.where(raw.is_remote[lo:hi], _REMOTE_FLAG, 0)
        objs["dlc"] = raw.dlc[lo:hi]
        ext = np.where(raw.is_extended[lo:hi], np.uint32(_CAN_MSG_EXT), np.uint32(0))
        objs["can_id"] = raw.arbitration_id[lo:hi] | ext
        objs["data"] = raw.data[lo:hi]
        data = objs.tobytes()
        self._buffer.append(data)
        self._buffer_size += len(data)
        self.object_count += hi - lo
        while self._buffer_size >= self.max_container_size:
            self._flush()


def raw_log_writer(path: Path) -> can.io.generic.MessageWriter:
    """The writer for a raw log: BatchBLFWriter for .blf, python-can's choice otherwise."""
    if path.suffix.lower() == ".blf":
        return BatchBLFWriter(path)
    return can.Logger(path)
