"""Virtual time with the compass on a bus of its own: the frames of both buses in one stream
whose order depends on the simulation alone, never on which notifier thread ran first.

The order is that of (stand time, bus): by timestamp, the stand's bus first at the same instant,
each bus's frames in the order they were sent. The simulated stand sends the frames of both
buses in stand-time order, counting those on the compass's bus (`Simulator.compass_frames_sent`)
as it sends them. So once the stand's frame of stand time W is in, every compass frame before W
was sent before it: waiting until as many compass frames are in as the count read after W
arrived makes the order of everything before W final. The compass's frames at or after W wait
for the next drain; so do the stand's frames drained while waiting."""

from __future__ import annotations

import heapq
import time
from bisect import bisect_left
from operator import attrgetter
from typing import TYPE_CHECKING

import can

from gyrostand.frames.batch import COMPASS_BUS

if TYPE_CHECKING:
    from gyrostand.acquisition.bus import Recorder
    from gyrostand.stand.simulator import Simulator

WAIT_WALL_S = 60.0  # a bound against a dead notifier, not a pace: the frames are on the bus
_DRAIN_FRAMES = 50_000
_TIME = attrgetter("timestamp")


class VirtualMerge:
    """The stand's and the compass's frames drained from the one recorder -> one ordered
    stream (`order`); `error`: the one line saying the compass's frames never came."""

    def __init__(self, simulator: Simulator, recorder: Recorder) -> None:
        self.simulator, self.recorder = simulator, recorder
        self._stand: list[can.Message] = []  # drained, not yet in the stream
        self._compass: list[can.Message] = []
        self._compass_in = 0  # compass frames drained so far
        self.error: str | None = None

    def order(self, msgs: list[can.Message]) -> list[can.Message]:
        """The frames whose place in the stream is final, in stream order (`msgs`: a drain)."""
        self._take(msgs)
        if not self._stand:
            return []
        release, watermark = len(self._stand), self._stand[-1].timestamp
        sent = self.simulator.compass_frames_sent  # read after the frame at `watermark` came
        deadline = time.monotonic() + WAIT_WALL_S
        while self._compass_in < sent and self.error is None:
            self._take(self.recorder.drain(_DRAIN_FRAMES, 0.05))
            if time.monotonic() > deadline:
                self.error = (
                    f"the simulated compass's bus: {sent - self._compass_in} frames sent on it "
                    f"never came within {WAIT_WALL_S:g} s"
                )
        times = [m.timestamp for m in self._compass]
        before = bisect_left(times, watermark)  # (each bus's frames come in stand-time order)
        stand, self._stand = self._stand[:release], self._stand[release:]
        compass, self._compass = self._compass[:before], self._compass[before:]
        out = list(heapq.merge(stand, compass, key=_TIME))  # ties: the stand's bus first
        return out

    def _take(self, msgs: list[can.Message]) -> None:
        for msg in msgs:
            if msg.channel == COMPASS_BUS:
                self._compass.append(msg)
                self._compass_in += 1
            else:
                self._stand.append(msg)
