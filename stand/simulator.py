"""The HIL twin: a simulated gyrocompass + roll stand on any python-can bus.

A background thread advances the `StandEngine` and answers stand commands. Two timings:

- virtual (the default): stand time advances only as far as the controller's SIM_SYNC frames
  allow, and each command takes effect at the stand time its SIM_SYNC names
  (`stand.virtual_time`). Same seed and same controller decisions give the same frames at any
  host load, as fast as both sides can go.
- realtime: stand time runs at `speedup` x wall time, sending the due frames in batches (not one
  sleep per frame), and commands take effect when they arrive (rehearsals, hardware-like timing).

Frames carry stand time, so a receiver behaves the same at any speed-up."""

from __future__ import annotations

import errno
import logging
import threading
import time
from types import TracebackType

import can

from gyrostand.stand.engine import COMPASS_FRAME, HeadingTransmitter, StandEngine
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import (
    CompassParams,
    FaultParams,
    NoiseParams,
    SimConfig,
    StandParams,
)
from gyrostand.stand.virtual_time import ClockEncoder, decode_sync

__all__ = [
    "CompassParams",
    "FaultParams",
    "NoiseParams",
    "SimConfig",
    "Simulator",
    "StandParams",
]

log = logging.getLogger(__name__)

_MIN_BATCH_WALL_S = 0.02  # shortest wall time between batches (commands wake the loop at once)
_MAX_BATCH_WALL_S = 0.05
_SEND_RETRY_WALL_S = 0.2  # how long to retry a frame on a full transmit queue


class Simulator:
    """Run the simulated unit on `bus` in a background thread: `start()` ... `stop()`, or
    `with Simulator(bus, config):`. `recorder` (e.g. a `can.Logger`) gets every frame sent.
    `compass_bus`: the compass's own bus (its transmitter's frames, the requests it answers);
    by default the stand's."""

    def __init__(
        self,
        bus: can.BusABC,
        config: SimConfig,
        *,
        codec: Codec | None = None,
        recorder: can.Listener | None = None,
        start_epoch_s: float | None = None,
        clock_ms: int = 0,
        transmitter: HeadingTransmitter | None = None,
        compass_bus: can.BusABC | None = None,
    ) -> None:
        """`clock_ms`: the stand clock at power-up (a resumed campaign's: a stand's clock goes
        on counting); the simulation itself starts at 0 as after a power-up."""
        self.bus = bus
        self.compass_bus = compass_bus
        self.compass_frames_sent = 0  # on `compass_bus`, counted once each is on it
        self.config = config
        self.engine = StandEngine(config, codec, clock_ms, transmitter)
        self._recorder = recorder
        self._epoch_s = time.time() if start_epoch_s is None else start_epoch_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self.frames_sent = 0
        self.frames_failed = 0
        self.receive_errors = 0
        interval_wall_s = 1.0 / (config.heading_rate_hz * config.speedup)
        self._batch_wall_s = min(max(interval_wall_s, _MIN_BATCH_WALL_S), _MAX_BATCH_WALL_S)
        # virtual time: how far the controller lets the stand run, when the next command takes
        # effect, the commands waiting for their stand time, the controller's last progress
        self._clock = ClockEncoder(clock_ms)
        self._horizon_ms = 0
        self._apply_ms: int | None = None
        self._commands: list[tuple[int, can.Message]] = []
        self._processed_ms: int | None = None
        self.late_commands = 0
        # how far the frames are on the bus (stand time), for `wait_until`; fault knobs to take
        # effect at the stand time the thread next sees them (`inject_faults`)
        self._progress = threading.Condition()
        self._sent_to_s = -1.0
        self._faults: list[FaultParams] = []
        # an in-process bus taking the frames as arrays (`acquisition.bus.SimulatorBus` into a
        # campaign's recorder, `send_parts`): no message per frame; one bus, no other recorder
        self._takes_frames = (
            getattr(bus, "takes_frames", False) and recorder is None and compass_bus is None
        )

    @property
    def stand_time_s(self) -> float:
        return self.engine.stand_time_s

    def wait_until(self, stand_s: float, timeout_s: float = 60.0) -> None:
        """Return once every frame up to stand time `stand_s` is on the bus (in virtual time the
        controller must have let the stand run that far). TimeoutError after `timeout_s` of wall
        time (a bound against a hang, not a pace); the thread's error if it failed."""
        with self._progress:
            reached = self._progress.wait_for(
                lambda: self._sent_to_s >= stand_s or self.error is not None, timeout_s
            )
        if self.error is not None:
            raise self.error
        if not reached:
            raise TimeoutError(
                f"the simulated stand did not reach stand time {stand_s:g} s within {timeout_s:g} "
                f"s of wall time (at {self._sent_to_s:g} s)"
            )

    def inject_faults(self, faults: FaultParams) -> None:
        """New fault knobs, taking effect at the stand time the simulator reaches before its next
        frames (in virtual time: the time the controller last let it run to)."""
        with self._progress:
            self._faults.append(faults)

    def _take_faults(self) -> None:
        with self._progress:
            faults, self._faults = self._faults, []
        for f in faults:
            self.engine.set_faults(f)

    def _reached(self, t_s: float) -> None:
        with self._progress:
            self._sent_to_s = max(self._sent_to_s, t_s)
            self._progress.notify_all()

    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("simulator already started")
        self._thread = threading.Thread(target=self._run, name="gyrostand-simulator", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread; re-raise whatever made it fail."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self.error is not None:
            raise self.error

    def __enter__(self) -> Simulator:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def _run(self) -> None:
        try:
            if self.config.timing == "virtual":
                self._run_virtual()
            else:
                self._run_realtime()
        except Exception as exc:  # reported by stop(); the thread must not die silently
            log.exception("simulator stopped")
            self.error = exc
            self._reached(-1.0)  # wakes `wait_until`

    def _run_realtime(self) -> None:
        wall0 = time.monotonic()
        while not self._stop.is_set():
            self._take_faults()
            self._send(self._advance(wall0))
            self._reached(self.engine.stand_time_s)
            msg = self._recv(self._batch_wall_s)
            while msg is not None:  # answer each command at the stand time it arrives
                self._send(self._advance(wall0))
                self._send(self.engine.receive(msg))
                msg = self._recv(0)
            for request in self._compass_requests():
                self._send(self.engine.receive(request))

    def _run_virtual(self) -> None:
        while not self._stop.is_set():
            msg = self._recv(self._batch_wall_s)
            while msg is not None:
                self._on_virtual(msg)
                msg = self._recv(0)
            for request in self._compass_requests():
                self._on_virtual(request)
            self._take_faults()
            # in stand-time order: a compass's request (answered now) may have come after a
            # command for later (its own bus, polled second)
            self._commands.sort(key=lambda c: c[0])
            for at_ms, command in self._commands:
                self._run_to(at_ms / 1000)
                # the command on the bus at the stand time it takes effect, then the answer
                echo = can.Message(
                    arbitration_id=command.arbitration_id,
                    is_extended_id=command.is_extended_id,
                    data=command.data,
                    timestamp=self.engine.stand_time_s,
                    channel=command.channel,  # (on the bus it came from)
                )
                self._send([echo, *self.engine.receive(command)])
            self._commands.clear()
            self._run_to(self._horizon_ms / 1000)
            self._reached(self.engine.stand_time_s)

    def _on_virtual(self, msg: can.Message) -> None:
        """Take in a SIM_SYNC (how far to run, when the next command applies) or a command."""
        sync = decode_sync(msg)
        if sync is not None:
            processed_ms = sync.processed_ms - self.engine.clock_ms  # simulation time
            horizon_ms = sync.horizon_ms - self.engine.clock_ms
            if self._processed_ms is not None and processed_ms < self._processed_ms:
                # a new controller (resume): tell it where the stand clock is
                self._send([self._clock.now(self.engine.stand_time_s)])
            self._processed_ms = processed_ms
            self._horizon_ms = max(self._horizon_ms, horizon_ms)
            self._apply_ms = horizon_ms
            return
        now_ms = round(self.engine.stand_time_s * 1000)
        if self.engine.for_compass(msg):  # (NMEA 2000: a request, a claim): answered now, echoed
            self._commands.append((now_ms, msg))
            return
        if msg.is_error_frame or msg.arbitration_id != self.engine.codec.command_arbitration_id:
            return
        at_ms = self._apply_ms if self._apply_ms is not None else now_ms
        if at_ms < now_ms:  # no SIM_SYNC before it (another controller): as soon as possible
            self.late_commands += 1
            log.warning("command 0x%X after its stand time: applied now", msg.arbitration_id)
            at_ms = now_ms
        self._commands.append((at_ms, msg))
        self._apply_ms = None  # one SIM_SYNC per command

    def _run_to(self, t_s: float) -> None:
        """Advance the stand to t_s, sending its frames and the SIM_CLOCK ticks in time order."""
        if t_s <= self.engine.stand_time_s:
            return
        if self._takes_frames:  # (the ticks last: as the sort below, at the same instant)
            parts = [*self.engine.advance_parts(t_s), self._clock.frames_until(t_s)]
            self.frames_sent += self.bus.send_parts(parts, self._epoch_s)  # type: ignore[attr-defined]
            return
        frames = self.engine.advance_to(t_s) + self._clock.until(t_s)
        frames.sort(key=lambda m: m.timestamp)  # stable: a tick after the stand's same-instant
        self._send(frames)

    def _compass_requests(self) -> list[can.Message]:
        """What came on the compass's own bus (none without one), marked as the compass's."""
        if self.compass_bus is None:
            return []
        frames = []
        while (msg := self.compass_bus.recv(0)) is not None:
            msg.channel = COMPASS_FRAME
            frames.append(msg)
        return frames

    def _recv(self, timeout_s: float) -> can.Message | None:
        """The next command, or None. A receive error (e.g. the kernel's ENETDOWN while the link
        is down) is logged and counted and the stand keeps running, as a real stand does."""
        try:
            return self.bus.recv(timeout=timeout_s)
        except can.CanOperationError as exc:
            self.receive_errors += 1
            log.warning("receive failed: %s", exc)
            self._stop.wait(self._batch_wall_s)
            return None

    def _advance(self, wall0: float) -> list[can.Message]:
        return self.engine.advance_to((time.monotonic() - wall0) * self.config.speedup)

    def _send(self, msgs: list[can.Message]) -> None:
        for msg in msgs:
            msg.timestamp += self._epoch_s
        # an in-process bus that takes a batch at once (`acquisition.bus.SimulatorBus`): each
        # run of frames of one bus, in order
        if getattr(self.bus, "send_batch", None) is not None and self._recorder is None:
            for bus, run in self._runs(msgs):
                bus.send_batch(run)  # type: ignore[attr-defined]
                self.frames_sent += len(run)
                self.compass_frames_sent += len(run) * (bus is self.compass_bus)
            return
        for msg in msgs:
            on_compass_bus = self.compass_bus is not None and msg.channel == COMPASS_FRAME
            if self._send_one(self.compass_bus if on_compass_bus else self.bus, msg):
                self.frames_sent += 1
                self.compass_frames_sent += on_compass_bus
                if self._recorder is not None:
                    self._recorder.on_message_received(msg)
            else:
                self.frames_failed += 1

    def _runs(self, msgs: list[can.Message]) -> list[tuple[can.BusABC, list[can.Message]]]:
        """The frames as runs of one bus each, in order (the compass's on its own bus)."""
        runs: list[tuple[can.BusABC, list[can.Message]]] = []
        for msg in msgs:
            on_compass_bus = self.compass_bus is not None and msg.channel == COMPASS_FRAME
            bus = self.compass_bus if on_compass_bus else self.bus
            if not runs or runs[-1][0] is not bus:
                runs.append((bus, []))
            runs[-1][1].append(msg)
        return runs

    def _send_one(self, bus: can.BusABC, msg: can.Message) -> bool:
        deadline = time.monotonic() + _SEND_RETRY_WALL_S
        while True:
            try:
                bus.send(msg)
                return True
            except can.CanOperationError as exc:
                queue_full = exc.error_code in (None, errno.ENOBUFS)  # worth retrying
                if not queue_full or time.monotonic() > deadline or self._stop.is_set():
                    log.warning("frame 0x%X not sent: %s", msg.arbitration_id, exc)
                    return False
                time.sleep(0.001)
