"""RawFrames.from_messages: payloads of any length land zero-padded in their own row."""

from __future__ import annotations

import can
import numpy as np
import pytest

from gyrostand.frames.batch import RawFrames


def _padded(messages: list[can.Message]) -> np.ndarray:
    """Each payload's first 8 bytes, zero-padded, frame by frame (the reference)."""
    rows = [list(bytes(m.data[:8])) + [0] * (8 - min(len(m.data), 8)) for m in messages]
    return np.array(rows, dtype=np.uint8).reshape(len(messages), 8)


@pytest.mark.parametrize("lengths", ["mixed", "all eight", "with CAN FD"])
def test_payloads_padded_per_row(lengths: str) -> None:
    rng = np.random.default_rng(7)
    sizes = {
        "mixed": rng.integers(0, 9, 500),  # heartbeats (1), TPDOs (4), error frames (0) ...
        "all eight": np.full(500, 8),
        "with CAN FD": np.r_[rng.integers(0, 9, 499), 64],
    }[lengths]
    messages = [
        can.Message(
            arbitration_id=i,
            data=bytes(rng.integers(1, 256, int(k), dtype=np.uint8)),
            is_fd=bool(k > 8),
        )
        for i, k in enumerate(sizes)
    ]
    raw = RawFrames.from_messages(3, messages)
    np.testing.assert_array_equal(raw.data, _padded(messages))
    np.testing.assert_array_equal(raw.dlc, sizes)
    assert raw.start == 3 and raw.data.shape == (500, 8)


@pytest.mark.parametrize("set_", ["none", "one", "many"])
def test_flags_and_columns_frame_by_frame(set_: str) -> None:
    """Error, remote and extended flags (none set, one set late, many), identifiers and
    timestamps: each column that of its message."""
    rng = np.random.default_rng(11)
    n = 300
    chance = {"none": 0.0, "one": 0.0, "many": 0.3}[set_]
    flags = rng.random((n, 3)) < chance
    if set_ == "one":
        flags[n - 1] = True
    messages = [
        can.Message(
            arbitration_id=int(rng.integers(0, 0x800)) | (0x1000 if ext else 0),
            is_error_frame=bool(err),
            is_remote_frame=bool(rem),
            is_extended_id=bool(ext),
            data=b"" if rem else bytes(8),
            timestamp=float(rng.random() * 1e9),
        )
        for err, rem, ext in flags
    ]
    raw = RawFrames.from_messages(0, messages)
    assert raw.is_error.tolist() == [m.is_error_frame for m in messages]
    assert raw.is_remote.tolist() == [m.is_remote_frame for m in messages]
    assert raw.is_extended.tolist() == [m.is_extended_id for m in messages]
    assert raw.arbitration_id.tolist() == [m.arbitration_id for m in messages]
    assert raw.timestamp.tolist() == [m.timestamp for m in messages]
    assert raw.is_error.dtype == raw.is_remote.dtype == raw.is_extended.dtype == np.bool_
