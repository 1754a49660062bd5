"""The raw log of a CiA 402 stand: the drive's CANopen traffic as it was on the bus, and its
replay through gyrostand's own master.

A CiA 402 stand sends no stand DBC frames: the engine's acks and statuses are the master's
(`acquisition.cia402_stand`), derived from the drive's answers. So the raw log holds the CANopen
frames between gyrostand and the drive (NMT, SDO, RPDO set-points, SYNC, the drive's TPDO,
EMCY and heartbeats; each stamped with the SYNC-count stand time of its run), the compass's and
the inclinometer's frames as the engine took them, and two records of the master on a channel of
their own (RECORD_BUS, no bus frame): RUN at the start of each run (the campaign clock it starts
from) and STEP at the end of each batch the engine was fed (its stand time). A replay runs the
same master against the logged drive (`LoggedDrive`: each frame the master sends must be the
logged one; the drive's logged answers follow it), so acks, statuses, drive faults and the
measured motion are derived again exactly as live, and each run's clock goes on from its RUN
record (a stopped and resumed campaign's segments are one campaign time).

In the simulation the master waits after each frame it sends until the drive has acted on it
and its answers have been taken (`BusTap`): the log's order is the causal one, the same on every
run whatever the host's load."""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import can
import canopen
import numpy as np

from gyrostand.devices.clock import ReceptionClock
from gyrostand.frames.batch import RawFrames
from gyrostand.frames.logfile import read_raw_frames

RECORD_BUS = 2  # RawFrames.channel of the master's records (BLF channel 3): no bus frame
RECORD_ID = 0x7FF
RUN, STEP = 1, 2  # record kinds: payload byte 0; bytes 1-7 the value (unsigned, little-endian)
WAIT_S = 30.0  # wall-clock bound on the simulated drive's answer (a stuck thread, not a timing)
_DRIVE_FUNCTIONS = (0x080, 0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500, 0x580, 0x600)


class DriveLogError(ValueError):
    """The logged drive traffic does not match what the master sends (one line)."""


class DriveLogEnded(DriveLogError):
    """The master sends past the end of the logged drive traffic (a killed run's log)."""


def record(kind: int, value: int, t_s: float) -> can.Message:
    """A master's record (RUN: the campaign clock in ms; STEP: the run's stand time in us)."""
    data = bytes([kind]) + int(value).to_bytes(7, "little")
    return can.Message(
        timestamp=t_s, arbitration_id=RECORD_ID, is_extended_id=False, data=data, channel=RECORD_BUS
    )


def drive_ids(node_id: int, master_id: int) -> frozenset[int]:
    """The COB-IDs of the traffic between the master and the drive: NMT, SYNC, the drive's
    EMCY, PDOs, SDO and heartbeat, and the master's heartbeat."""
    ids = {0x000, 0x080, 0x700 + node_id, 0x700 + master_id}
    ids.update(f + node_id for f in _DRIVE_FUNCTIONS)
    return frozenset(ids)


def master_sent(arbitration_id: int, node_id: int, master_id: int) -> bool:
    """Whether the master sends this COB-ID (else the drive does)."""
    return arbitration_id in (0x000, 0x080, 0x600 + node_id, 0x700 + master_id) or (
        0x200 <= arbitration_id - node_id <= 0x500 and (arbitration_id - node_id) % 0x100 == 0
    )


def stamped_copy(msg: can.Message, t_s: float) -> can.Message:
    """A copy of a frame sent or received, stamped with the run's stand time `t_s`."""
    return can.Message(
        timestamp=round(t_s, 6),
        arbitration_id=msg.arbitration_id,
        is_extended_id=msg.is_extended_id,
        data=bytes(msg.data),
        channel=0,
    )


class _Counter(can.Listener):
    """The last listener of a network's notifier: counts (and hands on) the frames the
    network's own listeners have acted on."""

    def __init__(self, cond: threading.Condition, then: Callable[[can.Message], None]) -> None:
        self.cond, self.then, self.count = cond, then, 0

    def on_message_received(self, msg: can.Message) -> None:
        with self.cond:
            self.then(msg)
            self.count += 1
            self.cond.notify_all()


def wrap_send(
    network: canopen.Network,
    after: Callable[[can.Message], None],
    before: Callable[[can.Message], None] = lambda msg: None,
) -> None:
    bus = network.bus
    assert bus is not None  # (connected)
    send = bus.send

    def sending(msg: can.Message, timeout: float | None = None) -> None:
        before(msg)
        send(msg, timeout)
        after(msg)

    bus.send = sending  # type: ignore[method-assign]


class BusTap:
    """The simulation's lockstep: records the master's traffic with the drive in causal order
    (`take`), each frame stamped by `clock` (the run's stand time)."""

    def __init__(
        self, master: canopen.Network, drive: canopen.Network, clock: Callable[[], float]
    ) -> None:
        self.clock = clock
        self.frames: list[can.Message] = []
        self._cond = threading.Condition()
        self._drive_sent = 0
        self._master_sent = 0
        self._taken = _Counter(
            self._cond, lambda m: self.frames.append(stamped_copy(m, self.clock()))
        )
        self._acted = _Counter(self._cond, lambda m: None)
        assert master.notifier is not None and drive.notifier is not None  # (connected)
        master.notifier.add_listener(self._taken)
        drive.notifier.add_listener(self._acted)
        wrap_send(drive, self._on_drive_sent)
        wrap_send(master, self._on_master_sent, self._master_sends)

    def _on_drive_sent(self, msg: can.Message) -> None:
        with self._cond:
            self._drive_sent += 1

    def _master_sends(self, msg: can.Message) -> None:
        """Recorded before it is on the bus (before any answer to it), after every frame the
        drive sent before (its boot-up)."""
        with self._cond:
            self._wait(lambda: self._taken.count >= self._drive_sent)
            self.frames.append(stamped_copy(msg, self.clock()))
            self._master_sent += 1

    def _on_master_sent(self, msg: can.Message) -> None:
        """Wait until the drive has acted on it and the master has taken every answer."""
        with self._cond:
            self._wait(
                lambda: (
                    self._acted.count >= self._master_sent and self._taken.count >= self._drive_sent
                )
            )

    def _wait(self, done: Callable[[], bool]) -> None:
        if not self._cond.wait_for(done, WAIT_S):
            raise can.CanOperationError(f"the simulated drive did not answer within {WAIT_S:g} s")

    def take(self) -> list[can.Message]:
        with self._cond:
            frames, self.frames = self.frames, []
        return frames


class LoggedDrive:
    """The drive of a replayed run: every frame the master sends must be the next logged one
    (DriveLogError, DriveLogEnded), then the drive's logged frames that followed it are sent
    to the master, which takes them before it goes on."""

    def __init__(self, master: canopen.Network, channel: str, frames: Iterator[can.Message]):
        self.node_id, self.master_id = 0, 0
        self._frames = frames
        self._next: can.Message | None = None
        self._bus = can.Bus(interface="virtual", channel=channel)
        self._cond = threading.Condition()
        self._sent = 0
        self._taken = _Counter(self._cond, lambda m: None)
        assert master.notifier is not None  # (connected)
        master.notifier.add_listener(self._taken)
        wrap_send(master, self._on_master_sent)

    def start(self, node_id: int, master_id: int) -> None:
        """The drive's frames before the master's first one (its boot-up)."""
        self.node_id, self.master_id = node_id, master_id
        self._answer()

    def _pull(self) -> can.Message | None:
        if self._next is None:
            self._next = next(self._frames, None)
        return self._next

    def _answer(self) -> None:
        while (msg := self._pull()) is not None and not master_sent(
            msg.arbitration_id, self.node_id, self.master_id
        ):
            self._next = None
            self._bus.send(msg)
            self._sent += 1
        while self._bus.recv(0) is not None:  # (the master's frames, heard on the channel)
            pass
        with self._cond:
            done = self._cond.wait_for(lambda: self._taken.count >= self._sent, WAIT_S)
        if not done:
            raise can.CanOperationError(f"the master did not take the logged frames in {WAIT_S}s")

    def _on_master_sent(self, msg: can.Message) -> None:
        logged = self._pull()
        if logged is None:
            raise DriveLogEnded("the raw log ends within this run's drive traffic")
        ours = (msg.arbitration_id, bytes(msg.data))
        if ours != (logged.arbitration_id, bytes(logged.data)):
            raise DriveLogError(
                f"at stand time {logged.timestamp:g} s of its run the master sends "
                f"0x{ours[0]:03X} {ours[1].hex()} where the raw log holds "
                f"0x{logged.arbitration_id:03X} {bytes(logged.data).hex()} (a log of another "
                "plan or drive?)"
            )
        self._next = None
        self._answer()

    def close(self) -> None:
        self._bus.shutdown()


@dataclass(frozen=True)
class LoggedRun:
    """One run of a campaign in its raw logs: its campaign clock at the start, its drive
    traffic (lazily, in order) and, per batch the engine was fed, the other frames."""

    clock_ms: int
    drive: Iterator[can.Message]
    steps: Iterator[list[can.Message]]


def _record(data: np.ndarray) -> tuple[int, int]:
    """A master's record: its kind and value."""
    return int(data[0]), int.from_bytes(bytes(data[1:8]), "little")


def _offset(path: Path) -> float:
    """The run's stand time minus the log's time: the BLF times of a virtual-time log count
    from its first frame (from its first record)."""
    for raw in read_raw_frames(path):
        rows = np.flatnonzero(raw.channel == RECORD_BUS)
        if len(rows):
            kind, value = _record(raw.data[int(rows[0])])
            return (0.0 if kind == RUN else value / 1e6) - float(raw.timestamp[int(rows[0])])
    return 0.0


def starts_a_run(path: Path) -> bool:
    """Whether a raw log begins with a run's RUN record (a campaign's first log does)."""
    first = next(read_raw_frames(path, chunk=1), None)
    return first is not None and first.channel[0] == RECORD_BUS and first.data[0, 0] == RUN


def compass_frames(
    paths: Sequence[Path], node_id: int, master_id: int, clock: ReceptionClock
) -> Iterator[RawFrames]:
    """The logs' frames but the drive's traffic and the records, as a compass's decoder reads
    them (the report's heading record): times restored to each run's stand time, and `clock`
    (the decoder's) told the campaign clock at each record, as the live statuses told it (a
    run's campaign ms = its RUN clock + its stand time)."""
    ids = np.array(sorted(drive_ids(node_id, master_id)), dtype=np.uint32)
    position, clock_ms = 0, 0
    for path in paths:
        offset = _offset(path)
        for raw in read_raw_frames(path):
            records = raw.channel == RECORD_BUS
            keep = ~records & (raw.is_extended | ~np.isin(raw.arbitration_id, ids))
            cuts = [*np.flatnonzero(records).tolist(), len(raw)]
            start = 0
            for cut in cuts:  # the frames up to each record, then the record's clock
                rows = np.flatnonzero(keep[start:cut]) + start
                part = RawFrames(position, *(getattr(raw, f.name)[rows] for f in fields(raw)[1:]))
                part.timestamp[:] = np.round(part.timestamp + offset, 6)
                position += len(part)
                yield part
                if cut < len(raw):
                    kind, value = _record(raw.data[cut])
                    clock_ms, t_s = (value, 0.0) if kind == RUN else (clock_ms, value / 1e6)
                    if kind == RUN:
                        clock.restart()
                    ms, s = np.array([clock_ms + t_s * 1000.0]), np.array([t_s])
                    clock.observe(np.array([position - 1]), ms, s)  # (frames after it see it)
                start = cut + 1


class _Items:
    """The logs' frames in order as (kind, payload), times restored to the run's stand time."""

    def __init__(self, paths: Sequence[Path], ids: frozenset[int]) -> None:
        self._it = self._read(paths, ids)
        self.drive: deque[can.Message] = deque()
        self.others: list[can.Message] = []
        self.steps: deque[list[can.Message]] = deque()
        self.runs: deque[int] = deque()  # RUN records not yet taken

    def _read(self, paths: Sequence[Path], ids: frozenset[int]) -> Iterator[tuple[str, object]]:
        for path in paths:
            offset = _offset(path)
            for raw in read_raw_frames(path):
                for row in range(len(raw)):
                    msg = raw.message(row)
                    msg.timestamp = round(msg.timestamp + offset, 6)
                    if int(raw.channel[row]) == RECORD_BUS:
                        kind, value = _record(raw.data[row])
                        yield ("run" if kind == RUN else "step"), value
                    elif not msg.is_extended_id and msg.arbitration_id in ids:
                        yield "drive", msg
                    else:
                        msg.channel = None
                        yield "other", msg

    def pull(self) -> bool:
        """Read one item; False at the end of the logs."""
        item = next(self._it, None)
        if item is None:
            return False
        kind, value = item
        if kind == "drive":
            self.drive.append(value)  # type: ignore[arg-type]
        elif kind == "other":
            self.others.append(value)  # type: ignore[arg-type]
        elif kind == "step":
            self.steps.append(self.others)
            self.others = []
        else:
            self.runs.append(value)  # type: ignore[arg-type]
        return True


def logged_runs(paths: Sequence[Path], node_id: int, master_id: int) -> Iterator[LoggedRun]:
    """The runs of a CiA 402 campaign's raw logs (its segments read in order: a killed run's
    log and its continuation are one run). Each run's iterators are read while it is replayed,
    before the next run is taken."""
    items = _Items(paths, drive_ids(node_id, master_id))
    while not items.runs and items.pull():
        pass
    while items.runs:
        clock_ms = items.runs.popleft()

        def within(pending: deque) -> Iterator:  # (until the next RUN record)
            while True:
                if pending:
                    yield pending.popleft()
                elif items.runs or not items.pull():
                    return

        yield LoggedRun(clock_ms, within(items.drive), within(items.steps))
        while not items.runs and items.pull():  # (what the replay of this run left)
            pass
        items.drive.clear()
        items.steps.clear()
        items.others = []
