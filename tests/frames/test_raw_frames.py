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
