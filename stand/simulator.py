"""The HIL twin: a simulated gyrocompass + roll stand on any python-can bus.

A background thread advances the `StandEngine` so that stand time runs at `speedup` x wall time,
sending the due frames in batches (not one sleep per frame), and answers stand commands as soon
as they arrive. Frames carry stand time, so a receiver behaves the same at any speed-up."""

from __future__ import annotations

import errno
import logging
import threading
import time
from types import TracebackType

import can

from stand.engine import StandEngine
from stand.protocol import Codec
from stand.simconfig import CompassParams, FaultParams, NoiseParams, SimConfig, StandParams

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
    `with Simulator(bus, config):`. `recorder` (e.g. a `can.Logger`) gets every frame sent."""

    def __init__(
        self,
        bus: can.BusABC,
        config: SimConfig,
        *,
        codec: Codec | None = None,
        recorder: can.Listener | None = None,
        start_epoch_s: float | None = None,
    ) -> None:
        self.bus = bus
        self.config = config
        self.engine = StandEngine(config, codec)
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

    @property
    def stand_time_s(self) -> float:
        return self.engine.stand_time_s

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
            wall0 = time.monotonic()
            while not self._stop.is_set():
                self._send(self._advance(wall0))
                msg = self._recv(self._batch_wall_s)
                while msg is not None:  # answer each command at the stand time it arrives
                    self._send(self._advance(wall0))
                    self._send(self.engine.receive(msg))
                    msg = self._recv(0)
        except Exception as exc:  # reported by stop(); the thread must not die silently
            log.exception("simulator stopped")
            self.error = exc

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
            if self._send_one(msg):
                self.frames_sent += 1
                if self._recorder is not None:
                    self._recorder.on_message_received(msg)
            else:
                self.frames_failed += 1

    def _send_one(self, msg: can.Message) -> bool:
        deadline = time.monotonic() + _SEND_RETRY_WALL_S
        while True:
            try:
                self.bus.send(msg)
                return True
            except can.CanOperationError as exc:
                queue_full = exc.error_code in (None, errno.ENOBUFS)  # worth retrying
                if not queue_full or time.monotonic() > deadline or self._stop.is_set():
                    log.warning("frame 0x%X not sent: %s", msg.arbitration_id, exc)
                    return False
                time.sleep(0.001)
