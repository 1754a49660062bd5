"""The bus side of a live campaign: open the bus (or the in-process simulated stand) and the
compass's own bus if it has one, a reception thread per bus feeding one bounded queue, the raw
log, and the stand controller.

Every listener runs on its bus's reception thread; the campaign thread only drains the queue. A
full queue or a listener error is counted and reported as an event, never dropped silently."""

from __future__ import annotations

import queue
import tempfile
import threading
import time
import uuid
from collections import deque
from pathlib import Path
from typing import Any

import can
from can.interfaces.virtual import VirtualBus

from gyrostand.acquisition.bus_merge import VirtualMerge
from gyrostand.devices.nmea2000 import iso_requests
from gyrostand.devices.sim_cia406 import Cia406Encoder
from gyrostand.devices.sim_nmea2000 import simulated_compass
from gyrostand.frames.batch import COMPASS_BUS, STAND_BUS, RawFrames
from gyrostand.frames.logfile import BatchBLFWriter, raw_log_writer
from gyrostand.plan.codec import codec_for, stand_config
from gyrostand.plan.model import BusPlan, CompassPlan, Plan
from gyrostand.stand.controller import StandController
from gyrostand.stand.engine import HeadingTransmitter
from gyrostand.stand.packing import Part
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simulator import Simulator


def transmitter(plan: Plan) -> HeadingTransmitter | None:
    """The simulated compass when it speaks another protocol than the stand's DBC."""
    encoder = plan.compass.encoder()
    if encoder is not None:
        return Cia406Encoder(encoder)
    if plan.compass.protocol != "nmea2000":
        return None
    model, serial = plan.instrument.model, plan.instrument.serial
    return simulated_compass(model, serial, plan.compass.name, plan.bus.seed)


def open_bus(bus: BusPlan | CompassPlan) -> can.BusABC:
    """The plan's python-can bus (a real one: interface, channel, bit rate as given; without
    them python-can's config file / environment)."""
    kwargs: dict[str, Any] = {}
    if bus.interface is not None:
        kwargs["interface"] = bus.interface
    if bus.channel is not None:
        kwargs["channel"] = bus.channel
    if bus.bitrate is not None:
        kwargs["bitrate"] = bus.bitrate
    return can.Bus(**kwargs)


def check_raw_log_dir(plan: Plan) -> None:
    """The plan's raw log folder (made if needed) takes a file: checked before anything is
    written, as the raw log is opened only once the campaign is stored (OSError)."""
    folder = Path(plan.raw_log_dir)
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryFile(dir=folder):
        pass


class SimulatorBus(VirtualBus):
    """The simulated stand's end of the in-process virtual bus: python-can's `virtual` interface
    without its deep copy of every frame sent (~9 us a frame, a quarter of the paper campaign's
    time end to end). The simulated stand makes a new message for every frame and never touches
    it again, so the receivers can share it; frames keep the stand's timestamps.

    `sink` (virtual time, where the campaign's `Recorder` is the only receiver): the frames go
    straight to it, a batch at a time (`send_batch`), instead of one by one through the
    receiving bus's queue and the reception thread (two lock round trips and a listener call a
    frame, ~3 us: 4 s of the paper campaign); on the one bus, as arrays (`send_parts`: no
    `can.Message` per frame, ~3 us more). The stand still receives commands on the bus."""

    def __init__(self, channel: str, sink: Recorder | None = None, mark: int | None = None) -> None:
        """`mark`: with a `sink`, the `RawFrames.channel` its frames get (two buses: `OnBus`'s
        mark, as the reception thread does not see them)."""
        super().__init__(channel=channel)
        self.sink = sink
        self.mark = mark

    @property
    def takes_frames(self) -> bool:
        """Whether frames may come as arrays (`send_parts`): into a recorder that needs no
        messages, on the one bus."""
        return self.sink is not None and self.mark is None and self.sink.takes_frames

    def send_parts(self, parts: list[Part], epoch_s: float) -> int:
        """The simulated stand's frames as parts (`takes_frames`), in stand-time order, with
        timestamps epoch_s + stand time; how many."""
        self._check_if_open()
        assert self.sink is not None
        raw = RawFrames.from_parts(0, parts)
        raw.timestamp[:] += epoch_s  # (after the sort: as the stand's messages)
        self.sink.on_frames(raw)
        return len(raw)

    def send_batch(self, msgs: list[can.Message]) -> None:
        """Every frame of `msgs`, in order (as `send` one by one)."""
        if self.sink is None:
            for msg in msgs:
                self.send(msg)
            return
        self._check_if_open()
        channel = self.channel_id if self.mark is None else self.mark
        for msg in msgs:
            msg.channel, msg.is_rx = channel, True
        self.sink.on_messages(msgs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.sink is not None:
            self.send_batch([msg])
            return
        self._check_if_open()
        msg.channel, msg.is_rx = self.channel_id, True
        try:
            for bus_queue in self.channel:
                if bus_queue is not self.queue:
                    bus_queue.put(msg, block=True, timeout=timeout)
        except queue.Full:
            raise can.CanOperationError(
                "Could not send message to one or more recipients"
            ) from None


class Overflow:
    """A place in the stream where the full queue dropped frames (`frames` of them in a row):
    a marker queued after the last frame kept, so the campaign knows where they are missing."""

    __slots__ = ("frames",)

    def __init__(self) -> None:
        self.frames = 0


class Recorder(can.Listener):
    """The one path of every frame: received frames (reception threads) and the commands we send
    (campaign thread) enter one bounded FIFO; the campaign thread drains it and writes what it
    drains to the raw log. So the log holds the frames the engine saw, in the order it saw them,
    and a replay of the log takes the same decisions. A full FIFO is counted, never silent.

    A deque with an explicit bound instead of `queue.Queue`: the reception thread's cost per frame
    drops from a lock/condition round trip to one atomic append (about 3x the ingest rate)."""

    def __init__(
        self, maxsize: int, log_path: Path | None, *, log_rest: bool = True, channels: bool = False
    ) -> None:
        self.maxsize = maxsize
        self.log_rest = log_rest  # on stop, log frames never drained (not in virtual time)
        self.channels = channels  # two buses: each frame's `channel` says which (`OnBus`)
        self._frames: deque[can.Message | Overflow] = deque()
        self._ready = threading.Event()  # set by a producer while the consumer waits for it
        self._waiting = False  # (a plain flag: checked for every frame, 40 ns less than is_set())
        self.writer = raw_log_writer(log_path) if log_path is not None else None
        self.dropped = 0
        self._overflow: Overflow | None = None  # the overflow going on (its marker is queued)
        self.overflows: list[tuple[int, Overflow]] = []  # the last drain's: (frames before, o)
        self.errors: list[Exception] = []  # from the bus, through the reception thread
        self.log_error: Exception | None = None  # the raw log stopped being written
        self.logged = 0  # frames written to the raw log
        self._stopped = False
        # frames queued as arrays (`on_frames`): batches and frames in (the producer's counts)
        # and out (the consumer's), so that each count has one writer
        self._batches_in = self._batch_frames_in = 0
        self._batches_out = self._batch_frames_out = 0

    @property
    def takes_frames(self) -> bool:
        """Whether frames may come as arrays (`on_frames`): the raw log needs no messages."""
        return self.writer is None or isinstance(self.writer, BatchBLFWriter)

    def _queued(self) -> int:
        """Frames in the queue (overflow markers counted as frames: a bound, not a count)."""
        batches = self._batches_in - self._batches_out
        return len(self._frames) - batches + self._batch_frames_in - self._batch_frames_out

    def on_message_received(self, msg: can.Message) -> None:
        if (len(self._frames) if not self._batches_in else self._queued()) >= self.maxsize:
            self.dropped += 1
            if self._overflow is None:  # one marker (beyond the bound) where frames go missing
                self._overflow = Overflow()
                self._frames.append(self._overflow)
            self._overflow.frames += 1
            return
        self._overflow = None
        self._frames.append(msg)  # atomic; the only producer-side operation
        if self._waiting:
            self._ready.set()

    def on_frames(self, raw: RawFrames) -> None:
        """Frames received together as arrays (`SimulatorBus.send_parts`; `takes_frames`):
        one queue entry, drained by `drain_frames`."""
        if self._queued() + len(raw) > self.maxsize:  # (frame by frame, counting the dropped)
            for row in range(len(raw)):
                self.on_message_received(raw.message(row))
            return
        self._overflow = None
        self._batch_frames_in += len(raw)
        self._batches_in += 1
        self._frames.append(raw)  # type: ignore[arg-type]
        if self._waiting:
            self._ready.set()

    def on_messages(self, msgs: list[can.Message]) -> None:
        """Frames received together (`SimulatorBus.send_batch`): as one by one, at once."""
        if self._queued() + len(msgs) > self.maxsize:
            for msg in msgs:  # (the bound reached: frame by frame, counting what is dropped)
                self.on_message_received(msg)
            return
        self._overflow = None
        self._frames.extend(msgs)  # atomic
        if self._waiting:
            self._ready.set()

    def on_error(self, exc: Exception) -> None:
        self.errors.append(exc)

    def drain(self, limit: int, timeout_s: float) -> list[can.Message]:
        """Up to `limit` frames in arrival order (waits up to `timeout_s` for the first one).
        The caller logs them (`log`) before using them. Where the full queue dropped frames
        among them: `overflows` (how many of the frames come before each overflow). Frames
        sent as arrays (`on_frames`) are drained by `drain_frames` only."""
        return self._unmark(self._pop(limit, timeout_s))

    def drain_frames(
        self, start: int, limit: int, timeout_s: float
    ) -> tuple[RawFrames, list[can.Message] | None]:
        """`drain`'s frames as one `RawFrames` from stream position `start`, and as messages;
        None for the messages when some came as arrays (`on_frames`: the raw log takes the
        arrays). `limit` counts a batch of arrays as one."""
        items = self._pop(limit, timeout_s)
        if not self._batches_in:  # (read after popping: a batch is counted before it is queued)
            msgs = self._unmark(items)
            return RawFrames.from_messages(start, msgs, channels=self.channels), msgs
        self.overflows = []
        parts: list[RawFrames] = []
        run: list[can.Message] = []  # messages since the last batch of arrays
        n = 0
        for item in items:
            if isinstance(item, RawFrames):
                if run:
                    parts.append(RawFrames.from_messages(0, run, channels=self.channels))
                    run = []
                parts.append(item)
                n += len(item)
                self._batch_frames_out += len(item)
                self._batches_out += 1
            elif isinstance(item, Overflow):
                self.overflows.append((n, item))
            else:
                run.append(item)
                n += 1
        if run:
            parts.append(RawFrames.from_messages(0, run, channels=self.channels))
        return RawFrames.concat(start, parts), None

    def _pop(self, limit: int, timeout_s: float) -> list[Any]:
        """Up to `limit` queue entries (waits up to `timeout_s` for the first one)."""
        if not self._frames:
            self._waiting = True  # (then the check: a frame queued after it sets `_ready`)
            self._ready.clear()
            if not self._frames:
                self._ready.wait(timeout_s)
            self._waiting = False
        pop = self._frames.popleft
        return [pop() for _ in range(min(len(self._frames), limit))]

    def _unmark(self, items: list[Any]) -> list[can.Message]:
        """The frames of `items`, the overflow markers among them noted in `overflows`."""
        self.overflows = []
        if not self.dropped:  # (no marker was ever queued)
            return items
        frames: list[can.Message] = []
        for item in items:
            if isinstance(item, Overflow):
                self.overflows.append((len(frames), item))
            else:
                frames.append(item)
        return frames

    def log(self, raw: RawFrames, msgs: list[can.Message] | None) -> None:
        """Write drained frames to the raw log (BLF: the whole batch at once; `msgs` None: the
        frames came as arrays, `takes_frames`)."""
        if self.writer is None or self._stopped or self.log_error is not None:
            return
        try:
            if isinstance(self.writer, BatchBLFWriter):
                self.writer.write_frames(raw)
            else:
                assert msgs is not None
                for msg in msgs:
                    self.writer.on_message_received(msg)
        except Exception as exc:  # the frames still reach the campaign
            self.log_error = exc
        else:
            self.logged += len(raw)

    def stop(self) -> None:
        """Log what is still queued (frames of the campaign too), then close the log."""
        if self._stopped:
            return
        if self.log_rest:
            rest = self._unmark(list(self._frames))
            self.log(RawFrames.from_messages(0, rest, channels=self.channels), rest)
        if self.writer is not None:
            try:
                self.writer.stop()
            except Exception as exc:  # its last frames did not reach the file
                self.log_error = self.log_error or exc
        self._stopped = True


RECV_TIMEOUT_S = 0.05  # a reception thread's longest wait for a frame before it looks if stopped


class Reception:
    """One bus into one listener on a thread of ours: the public `bus.recv` in a loop, each frame
    to the listener's `on_message_received` in the order received, each error of the bus (once
    per outage) or the listener to its `on_error` and reception going on; `stop()` joins the
    thread, then stops the listener. That is what `can.Notifier` does for one bus and one
    listener (whose thread ends at a bus's first error), without its lock taken for every frame
    and its dispatch through two more Python calls per frame (`Notifier._on_message_received`,
    `Listener.__call__`): 2.8 -> 2.1 us of CPU a frame from a python-can virtual bus into the
    `Recorder` on one core, 0.7 of the 4.9 us a frame of the whole ingest path (bench_ingest,
    issue 37)."""

    def __init__(
        self, bus: can.BusABC, listener: can.Listener, timeout_s: float = RECV_TIMEOUT_S
    ) -> None:
        self.listener = listener
        self._stopped = False
        self._thread = threading.Thread(
            target=self._run,
            args=(bus, timeout_s),
            name=f"gyrostand reception of {bus.channel_info}",
            daemon=True,  # (as python-can's notifier threads: never holding the process open)
        )
        self._thread.start()

    def _run(self, bus: can.BusABC, timeout_s: float) -> None:
        recv, received = bus.recv, self.listener.on_message_received
        failing = False  # a bus error reported and no frame since: the same outage
        while not self._stopped:
            try:
                msg = recv(timeout_s)
            except Exception as exc:  # the bus's: reported once per outage (a link down fails
                if not failing:  # every call at once), tried again after the usual wait
                    self.listener.on_error(exc)
                failing = True
                time.sleep(timeout_s)
                continue
            if msg is None:
                continue
            failing = False
            try:
                received(msg)
            except Exception as exc:  # the listener's: the campaign reports it
                self.listener.on_error(exc)

    def stop(self, timeout_s: float = 5.0) -> None:
        """No more frames: the thread ended (waited for up to `timeout_s`), then the listener
        stopped (the recorder: its raw log's last container written)."""
        self._stopped = True
        self._thread.join(timeout_s)
        self.listener.stop()


class BusFault(can.CanError):
    """An error of one of a campaign's two buses, naming it."""


class OnBus(can.Listener):
    """One of two buses into the recorder: each frame marked with its bus (`RawFrames.channel`,
    set on the bus's reception thread as it arrives), each error naming it (`BusFault`)."""

    def __init__(self, recorder: Recorder, channel: int, label: str) -> None:
        self.recorder, self.channel, self.label = recorder, channel, label

    def on_message_received(self, msg: can.Message) -> None:
        msg.channel = self.channel
        self.recorder.on_message_received(msg)

    def on_error(self, exc: Exception) -> None:
        self.recorder.on_error(BusFault(f"{self.label}: {exc!r}"))


class RecordedSend:
    """The bus as the controller sees it: every frame it sends also enters the stream."""

    def __init__(self, bus: can.BusABC, recorder: can.Listener) -> None:
        self._bus, self._recorder = bus, recorder

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        # recorded first: the stand's answer must not enter the stream before the command
        if not msg.timestamp:
            msg.timestamp = time.time()
        self._recorder.on_message_received(msg)
        self._bus.send(msg, timeout)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._bus, name)


def request_identity(bus: can.BusABC | RecordedSend) -> None:
    """Ask the NMEA 2000 devices for their address claim and product information, so that the
    campaign knows a compass that claimed its address before it started. Sent before the
    simulated stand starts: in virtual time it answers at its current stand time, before
    anything else it sends (it echoes the request into the stream, as it does commands)."""
    for msg in iso_requests():
        bus.send(msg)


class LiveBus:
    """Opens everything a live campaign needs on the bus; `close()` releases it in order."""

    def __init__(
        self,
        plan: Plan,
        codec: Codec,
        raw_log: Path | None,
        clock_ms: int = 0,
        compass: HeadingTransmitter | None = None,
    ) -> None:
        """`clock_ms`: the simulated stand's clock at its start (`Simulator`); `compass`: the
        simulated compass when it is not on the bus (a serial line's)."""
        self.plan = plan
        self.virtual = plan.bus.timing == "virtual"
        self.own_bus = plan.compass.own_bus  # the compass on a bus of its own: two buses
        self.simulator: Simulator | None = None
        self.merge: VirtualMerge | None = None
        self.compass_bus: can.BusABC | None = None
        self._buses: list[can.BusABC] = []  # to shut down, in order
        self._receptions: list[Reception] = []  # one per bus: the stand's first
        config = stand_config(plan) if plan.bus.simulated else None
        self.bus, channel = self._open(plan.bus, "sim")
        try:
            self.recorder = Recorder(
                plan.bus.queue_size, raw_log, log_rest=not self.virtual, channels=self.own_bus
            )
            if self.own_bus:
                self.compass_bus, compass_channel = self._open(plan.compass, "compass")
            if config is not None:
                sink = self.recorder if self.virtual else None
                mark = STAND_BUS if self.own_bus else None
                self._sim_bus = SimulatorBus(channel=channel, sink=sink, mark=mark)
                self._buses.append(self._sim_bus)
                sim_compass_bus = None
                if self.own_bus:
                    sim_compass_bus = SimulatorBus(compass_channel, sink, mark=COMPASS_BUS)
                    self._buses.append(sim_compass_bus)
                self.simulator = Simulator(
                    self._sim_bus,
                    config,
                    codec=codec_for(plan),
                    clock_ms=clock_ms,
                    transmitter=compass or transmitter(plan),
                    compass_bus=sim_compass_bus,
                )
            stand_in: can.Listener = self.recorder
            compass_in: can.Listener = self.recorder
            if self.compass_bus is not None:
                stand_in = OnBus(self.recorder, STAND_BUS, f"the stand's bus ({_label(plan.bus)})")
                compass_in = OnBus(self.recorder, COMPASS_BUS, plan.compass.bus_label)
                self._receptions.append(Reception(self.compass_bus, compass_in))
                if self.virtual and self.simulator is not None:
                    self.merge = VirtualMerge(self.simulator, self.recorder)
            # in virtual time the stand repeats each command in the stream at the stand time it
            # takes effect (stand.virtual_time); otherwise the stream records what we send
            sender = self.bus if self.virtual else RecordedSend(self.bus, stand_in)
            self.controller = StandController(
                sender,  # type: ignore[arg-type]
                codec,  # it only encodes (the campaign decodes the stream)
                ack_timeout_s=plan.timeouts.ack_s,
            )
            # the campaign judges acks from the stream: the controller only sends
            self._receptions.insert(0, Reception(self.bus, stand_in))
            if plan.compass.protocol == "nmea2000":
                to_compass = self.compass_bus or self.bus
                if not self.virtual:
                    to_compass = RecordedSend(to_compass, compass_in)  # type: ignore[assignment]
                request_identity(to_compass)
            if self.simulator is not None:
                self.simulator.start()
        except BaseException:
            for reception in self._receptions:
                reception.stop()
            self._shutdown()
            raise

    def _open(self, bus: BusPlan | CompassPlan, role: str) -> tuple[can.BusABC, str]:
        """One of the campaign's buses and its channel's name; beside the simulated stand an
        in-process virtual one with a name of its own, ending in `role` (not in digits: log
        writers would take those for a channel number; the plan's names it in messages only)."""
        if self.plan.bus.simulated:
            channel = f"gyrostand-{uuid.uuid4().hex}-{role}"
            opened = can.Bus(interface="virtual", channel=channel)
        else:
            opened, channel = open_bus(bus), str(bus.channel)
        self._buses.append(opened)
        return opened, channel

    def close(self) -> None:
        """Stop the simulated stand, the reception threads (then the raw log), the buses."""
        try:
            if self.simulator is not None:
                self.simulator.stop()
        finally:
            try:
                for reception in self._receptions:
                    reception.stop()
                self.recorder.stop()
            finally:
                self._shutdown()

    def _shutdown(self) -> None:
        for bus in self._buses:
            bus.shutdown()


def _label(bus: BusPlan) -> str:
    """The stand's bus in messages."""
    if bus.simulated:
        return "simulated"
    return " ".join(str(k) for k in (bus.interface, bus.channel) if k) or "python-can's default"
