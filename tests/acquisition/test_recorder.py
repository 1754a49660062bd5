"""The recorder's queue with frames sent as arrays (the in-process simulated stand in virtual
time) among frames sent one by one: one stream in arrival order, the bound counted in frames."""

from pathlib import Path

import can
import numpy as np

from gyrostand.acquisition.bus import Recorder
from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import read_blf


def frames(first: int, n: int) -> list[can.Message]:
    """n frames whose identifiers count from `first` (their place in the stream)."""
    return [
        can.Message(arbitration_id=first + i, data=bytes([i % 256] * 8), timestamp=first + i)
        for i in range(n)
    ]


def test_arrays_and_messages_drain_in_arrival_order(tmp_path: Path) -> None:
    recorder = Recorder(1000, tmp_path / "raw.blf")
    assert recorder.takes_frames
    recorder.on_messages(frames(0, 3))
    recorder.on_frames(RawFrames.from_messages(0, frames(3, 5)))
    recorder.on_message_received(frames(8, 1)[0])
    recorder.on_frames(RawFrames.from_messages(0, frames(9, 4)))
    raw, msgs = recorder.drain_frames(100, 10_000, 0.0)
    assert msgs is None  # (some came as arrays: the raw log takes the arrays)
    assert raw.start == 100 and raw.arbitration_id.tolist() == list(range(13))
    assert raw.timestamp.tolist() == list(range(13))
    recorder.log(raw, msgs)
    recorder.stop()
    assert recorder.logged == 13
    (logged,) = read_blf(tmp_path / "raw.blf")
    assert logged.arbitration_id.tolist() == list(range(13))
    assert np.array_equal(logged.data, raw.data)


def test_the_bound_counts_the_frames_of_arrays() -> None:
    """Arrays beyond the bound go frame by frame: those that fit are kept, the rest counted as
    dropped where they went missing."""
    recorder = Recorder(10, None)
    recorder.on_frames(RawFrames.from_messages(0, frames(0, 6)))
    recorder.on_frames(RawFrames.from_messages(0, frames(6, 6)))  # 4 fit
    recorder.on_messages(frames(12, 2))  # none fit
    assert recorder.dropped == 4
    raw, _ = recorder.drain_frames(0, 10_000, 0.0)
    assert raw.arbitration_id.tolist() == list(range(10))
    assert [(before, o.frames) for before, o in recorder.overflows] == [(10, 4)]
    recorder.on_frames(RawFrames.from_messages(0, frames(14, 10)))  # room again
    raw, _ = recorder.drain_frames(10, 10_000, 0.0)
    assert raw.arbitration_id.tolist() == list(range(14, 24)) and recorder.dropped == 4


def test_messages_alone_drain_as_messages() -> None:
    """A real bus's frames (one by one) keep their messages, for a raw log of another format."""
    recorder = Recorder(100, None)
    sent = frames(0, 5)
    recorder.on_messages(sent)
    raw, msgs = recorder.drain_frames(0, 100, 0.0)
    assert msgs == sent and raw.arbitration_id.tolist() == list(range(5))
