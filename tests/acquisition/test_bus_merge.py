"""Two buses: `OnBus` marks each frame with its bus and names it in its errors; `VirtualMerge`:
the frames of the stand's bus and the compass's own bus come through two
notifier threads in any interleaving and in drains of any size; the stream is always the one
order of (stand time, bus), each bus's frames in the order they were sent."""

from __future__ import annotations

import can
import numpy as np
import pytest

from gyrostand.acquisition.bus import BusFault, OnBus, Recorder
from gyrostand.acquisition.bus_merge import VirtualMerge
from gyrostand.frames.batch import COMPASS_BUS, STAND_BUS


def sent_frames(rng: np.random.Generator) -> list[can.Message]:
    """What the simulated stand sends, in its order: stand times nondecreasing across both
    buses (several frames at one instant, on either bus), the stand's bus last."""
    frames, t = [], 0.0
    for _ in range(300):
        t += float(rng.choice([0.0, 0.5]))
        bus = int(rng.random() < 0.4)
        frames.append(can.Message(timestamp=t, arbitration_id=len(frames), channel=bus))
    frames.append(can.Message(timestamp=t + 1, arbitration_id=len(frames), channel=STAND_BUS))
    return frames


class Arrivals:
    """The recorder and the simulated stand as the merge sees them: the frames of each bus
    arrive in their order, the two buses interleaved at random, drained in random sizes; the
    count of compass frames sent is read at least as high as when the last stand frame drained
    was sent (any compass frames sent since may be counted too)."""

    def __init__(self, frames: list[can.Message], rng: np.random.Generator) -> None:
        self.frames, self.rng = frames, rng
        buses = [[m for m in frames if m.channel == b] for b in (STAND_BUS, COMPASS_BUS)]
        order = rng.permutation([b for b, msgs in enumerate(buses) for _ in msgs])
        cursor = [0, 0]
        self.arrival = []
        for b in order.tolist():
            self.arrival.append(buses[b][cursor[b]])
            cursor[b] += 1
        self.drained = 0
        self.latest_stand = -1  # index in `frames` of the last stand frame drained

    def drain(self, limit: int, timeout_s: float) -> list[can.Message]:
        n = min(int(self.rng.integers(0, 40)), limit)
        out = self.arrival[self.drained : self.drained + n]
        self.drained += len(out)
        for m in out:
            if m.channel == STAND_BUS:
                self.latest_stand = max(self.latest_stand, self.frames.index(m))
        return out

    @property
    def compass_frames_sent(self) -> int:
        before = self.frames[: self.latest_stand + 1]
        extra = int(self.rng.integers(0, 5))
        later = self.frames[self.latest_stand + 1 :]
        return sum(m.channel == COMPASS_BUS for m in before + later[:extra])


@pytest.mark.parametrize("seed", range(8))
def test_the_stream_is_the_order_of_stand_time_and_bus(seed: int) -> None:
    rng = np.random.default_rng(seed)
    frames = sent_frames(rng)
    arrivals = Arrivals(frames, rng)
    merge = VirtualMerge(arrivals, arrivals)  # type: ignore[arg-type]
    stream: list[can.Message] = []
    while arrivals.drained < len(frames):
        stream += merge.order(arrivals.drain(50_000, 0.0))
    stream += merge.order([])
    expected = sorted(frames, key=lambda m: (m.timestamp, m.channel))  # (stable: sent order)
    assert [m.arbitration_id for m in stream] == [m.arbitration_id for m in expected]
    assert merge.error is None


def test_each_bus_marks_its_frames_and_names_itself_in_its_errors() -> None:
    recorder = Recorder(10, None)
    stand = OnBus(recorder, STAND_BUS, "the stand's bus (socketcan can0)")
    compass = OnBus(recorder, COMPASS_BUS, "the compass's bus (socketcan can1)")
    compass.on_message_received(can.Message(arbitration_id=1, channel="can1"))
    stand.on_message_received(can.Message(arbitration_id=2, channel="can0"))
    compass.on_error(can.CanOperationError("Network is down"))
    drained = recorder.drain(10, 0.0)
    assert [(m.arbitration_id, m.channel) for m in drained] == [(1, 1), (2, 0)]
    (error,) = recorder.errors
    assert isinstance(error, BusFault)
    assert str(error) == (
        "the compass's bus (socketcan can1): CanOperationError('Network is down')"
    )
