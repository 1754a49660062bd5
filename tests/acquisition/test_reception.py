"""`Reception`, a bus's frames into the recorder on gyrostand's own thread (instead of python-can's
notifier): every frame in the order the bus gave it, a bus error (ENETDOWN) or a listener's error
handed to `on_error` and reception going on, two buses each on a thread of its own with each
frame marked with its bus, and `stop()` ending the thread and stopping the listener (the raw
BLF's last container and header written)."""

from __future__ import annotations

import errno
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import can
import pytest
from can.interfaces.virtual import VirtualBus

from gyrostand.acquisition.bus import BusFault, OnBus, Reception, Recorder
from gyrostand.frames.batch import COMPASS_BUS, STAND_BUS, RawFrames
from gyrostand.frames.logfile import read_blf

N = 2_000
DOWN = "Error receiving: Network is down"  # python-can's SocketCAN bus, ENETDOWN
WAIT_S = 30.0  # a bound against a dead thread, not a pace: the frames are already on the bus


def numbered(n: int, first: int = 0) -> list[can.Message]:
    """n frames whose payload is their place in the stream (identifiers cycle)."""
    return [
        can.Message(
            arbitration_id=(first + i) % 0x800,
            data=(first + i).to_bytes(8, "little"),
            timestamp=1.0 + (first + i) * 1e-4,
        )
        for i in range(n)
    ]


def places(msgs: list[can.Message]) -> list[int]:
    return [int.from_bytes(m.data, "little") for m in msgs]


class Down(VirtualBus):
    """A virtual bus whose link goes down after `after` frames received, as python-can's
    SocketCAN bus reports it (CanOperationError, ENETDOWN, at once on every call), for `calls`
    calls of `recv`; its frames then keep coming."""

    def __init__(self, channel: str, after: int, calls: int) -> None:
        super().__init__(channel=channel, preserve_timestamps=True)
        self.after, self.received, self.calls = after, 0, calls

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.received == self.after and self.calls:
            self.calls -= 1
            raise can.CanOperationError(DOWN, errno.ENETDOWN)
        msg, filtered = super()._recv_internal(timeout)
        self.received += msg is not None
        return msg, filtered


def loaded(
    frames: list[can.Message], after: int | None = None, calls: int = 1
) -> tuple[can.BusABC, can.BusABC]:
    """A receiving bus with `frames` queued on it (and their sender); `after`: its link goes
    down after that many frames, for `calls` calls."""
    channel = f"test-{uuid.uuid4().hex}-x"
    if after is None:
        rx: can.BusABC = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    else:
        rx = Down(channel, after, calls)
    tx = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    for msg in frames:
        tx.send(msg)
    return rx, tx


def drained(recorder: Recorder, n: int) -> list[can.Message]:
    """The first n frames out of the recorder, in its order."""
    msgs: list[can.Message] = []
    deadline = time.monotonic() + WAIT_S
    while len(msgs) < n and time.monotonic() < deadline:
        msgs += recorder.drain(n - len(msgs), 0.05)
    return msgs


def reception_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("gyrostand reception")]


@pytest.fixture
def buses() -> Any:
    opened: list[can.BusABC] = []
    yield opened
    for bus in opened:
        bus.shutdown()


def test_every_frame_in_order_and_stop_completes_the_raw_log(tmp_path: Path, buses) -> None:
    """Every frame reaches the raw BLF in bus order; the file is complete only because `stop`
    stopped the recorder: N frames are fewer than one container, written at `stop`."""
    sent = numbered(N)
    buses.extend(loaded(sent))
    recorder = Recorder(10 * N, tmp_path / "raw.blf")
    reception = Reception(buses[0], recorder)
    assert len(reception_threads()) == 1
    msgs = drained(recorder, N)
    assert places(msgs) == list(range(N))
    recorder.log(RawFrames.from_messages(0, msgs), msgs)
    assert not (tmp_path / "raw.blf").stat().st_size > 144  # (only the file header yet)
    reception.stop()
    assert reception_threads() == []
    (logged,) = read_blf(tmp_path / "raw.blf")
    assert logged.arbitration_id.tolist() == [m.arbitration_id for m in sent]
    assert logged.data.tobytes() == b"".join(m.data for m in sent)
    assert recorder.errors == [] and recorder.dropped == 0


@pytest.mark.parametrize("calls", [1, 10])
def test_a_bus_error_is_handed_on_and_reception_goes_on(buses, calls: int) -> None:
    """The link down after 700 frames, for one call of `recv` or ten in a row: one error in
    `Recorder.errors` (one bus error event of the campaign per outage, not one per failed call),
    and the frames after it still arrive, in order."""
    buses.extend(loaded(numbered(N), after=700, calls=calls))
    recorder = Recorder(10 * N, None)
    reception = Reception(buses[0], recorder)
    try:
        msgs = drained(recorder, N)
    finally:
        reception.stop()
    assert places(msgs) == list(range(N))
    (error,) = recorder.errors
    assert isinstance(error, can.CanOperationError) and error.error_code == errno.ENETDOWN
    assert str(error) == f"{DOWN} [Error Code {errno.ENETDOWN}]"


class Refuses(Recorder):
    """A listener failing on one frame (its place in the stream `bad`)."""

    bad = 300

    def on_message_received(self, msg: can.Message) -> None:
        if int.from_bytes(msg.data, "little") == self.bad:
            raise ValueError(f"frame {self.bad} refused")
        super().on_message_received(msg)


def test_a_listener_error_is_handed_on_and_reception_goes_on(buses) -> None:
    buses.extend(loaded(numbered(N)))
    recorder = Refuses(10 * N, None)
    reception = Reception(buses[0], recorder)
    try:
        msgs = drained(recorder, N - 1)
    finally:
        reception.stop()
    assert places(msgs) == [i for i in range(N) if i != Refuses.bad]
    assert [repr(e) for e in recorder.errors] == ["ValueError('frame 300 refused')"]


def test_two_buses_each_on_its_thread_into_one_stream(buses) -> None:
    """The stand's bus and the compass's own bus: a thread each, each frame marked with its bus,
    each bus's frames in its order; the compass's link going down is named as its bus's."""
    buses.extend(loaded(numbered(N)))
    buses.extend(loaded(numbered(N, first=N), after=500))
    recorder = Recorder(10 * N, None, channels=True)
    stand = Reception(buses[0], OnBus(recorder, STAND_BUS, "the stand's bus (virtual)"))
    compass = Reception(buses[2], OnBus(recorder, COMPASS_BUS, "the compass's bus (virtual)"))
    try:
        assert len(reception_threads()) == 2
        msgs = drained(recorder, 2 * N)
    finally:
        stand.stop()
        compass.stop()
    assert reception_threads() == []
    raw = RawFrames.from_messages(0, msgs, channels=True)
    on = {bus: places([m for m in msgs if m.channel == bus]) for bus in (STAND_BUS, COMPASS_BUS)}
    assert on[STAND_BUS] == list(range(N)) and on[COMPASS_BUS] == list(range(N, 2 * N))
    assert raw.channel.tolist() == [int(p >= N) for p in places(msgs)]
    (error,) = recorder.errors
    assert isinstance(error, BusFault)
    assert str(error).startswith("the compass's bus (virtual): CanOperationError(")
