"""The standard's procedures on a real bus, in real time: the same procedures
(`procedures.run_procedures`) on a compass heard as its frames arrive.

The frames come as the live trials take them (`bus.LiveBus`: the compass's and the stand's
frames into one queue, the raw log written as they are drained) and are decoded by the trials'
decoder (`runner.can_decoder`: a compass timed by its own frames' stand time, or by reception on
the stand clock, `devices.clock`). Campaign time is the stand clock heard: a run-up's "until"
waits for it (real time is the point: a settling test takes hours). Each run-up starts at the
stand time of the first frame heard after the operator's answer to its switch-on prompt (the
stand's protocol has no power control); `switch_on_s` keeps those times, so that a resumed run
goes on with the run-ups under way, fed first the frames the stopped run logged (`earlier`)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from dataclasses import fields
from pathlib import Path

import can
import numpy as np

from gyrostand.acquisition.bus import LiveBus
from gyrostand.acquisition.procedures import RunUp
from gyrostand.acquisition.runner import BATCH_FRAMES, can_decoder
from gyrostand.frames.batch import Headings, RawFrames
from gyrostand.frames.logfile import read_raw_frames
from gyrostand.plan.codec import codec_for
from gyrostand.plan.model import Plan
from gyrostand.stand.controller import StandError
from gyrostand.stand.protocol import AckFrame, CommandFrame

DRAIN_WALL_S = 0.05  # longest wait for a frame in one poll (wall)


class ProcedureBusError(ValueError):
    """The bus failed the procedures: silence, a bus error, a command not acknowledged."""


def _empty() -> Headings:
    none = np.zeros(0, np.int64)
    return Headings(none, none, np.zeros(0), np.zeros(0, bool), none)


def _joined(parts: Sequence[Headings]) -> Headings:
    columns = (np.concatenate([getattr(h, f.name) for h in parts]) for f in fields(Headings))
    return Headings(*columns)


class BusHeadings:
    """The compass's headings heard on the plan's bus, in stream order, taken by the run-ups up
    to a campaign time (`take`, as `procedures.LoggedHeadings` takes a log's: the same
    procedure, the same record). `check()` is called at every poll (a stop raises there)."""

    def __init__(self, plan: Plan, live: LiveBus, check: Callable[[], None]) -> None:
        self.plan, self.live, self.check = plan, live, check
        self.codec = codec_for(plan)
        self._decoder = can_decoder(plan, self.codec)
        self._pending: list[Headings] = []  # heard, not yet taken (joined when taken)
        self._acks: list[AckFrame] = []
        self.now_ms = -np.inf  # the latest stand time heard (statuses and headings)
        self._next_ms: float | None = 0.0  # (None: `next_heard_s` waits for a frame)
        self.position = 0  # frames drained
        self.rocking = False
        self._silence_s = plan.timeouts.bus_silence_s
        self._last_frame = time.monotonic()
        self._heading_ms = -np.inf  # the latest heading heard (stand time)

    def earlier(self, logs: Sequence[Path]) -> None:
        """The headings a stopped run of the procedures heard (its raw logs, in order), before
        the ones heard now: a run-up under way goes on from its switch-on."""
        for path in logs:
            decoder = can_decoder(self.plan, self.codec)  # (each run's reception times anew)
            for raw in read_raw_frames(path):
                self._heard(decoder.decode(raw).headings)

    def _heard(self, headings: Headings) -> None:
        known = headings.t_ms >= 0  # (NO_CLOCK: received before the first stand status)
        if known.any():
            self._pending.append(headings.take(known))
            self._heading_ms = max(self._heading_ms, float(headings.t_ms[known].max()))
            self.now_ms = max(self.now_ms, self._heading_ms)

    def poll(self) -> None:
        """Drain the frames arrived (waiting up to DRAIN_WALL_S for one), log and decode them."""
        self.check()
        live = self.live
        msgs = live.recorder.drain(BATCH_FRAMES, DRAIN_WALL_S)
        if live.recorder.dropped:
            raise ProcedureBusError(
                f"the acquisition's queue overflowed: {live.recorder.dropped} frames dropped"
            )
        if live.recorder.log_error is not None:
            raise ProcedureBusError(f"the raw log cannot be written: {live.recorder.log_error}")
        if live.recorder.errors:
            raise ProcedureBusError(f"bus error: {live.recorder.errors[0]}")
        if not msgs:
            if time.monotonic() - self._last_frame > self._silence_s:
                raise ProcedureBusError(
                    f"bus silence: no frame at all for {self._silence_s:g} s (wall clock)"
                )
            return
        self._last_frame = time.monotonic()
        raw = RawFrames.from_messages(self.position, msgs, channels=live.own_bus)
        batch = self._decoder.decode(raw)
        live.recorder.log(raw, msgs)
        self.position += len(msgs)
        self._heard(batch.headings)
        times = np.concatenate([batch.statuses.t_ms, batch.headings.t_ms])
        times = times[times >= 0]  # (NO_CLOCK: a heading received before any stand status)
        if times.size:
            self.now_ms = max(self.now_ms, float(times.max()))
            if self._next_ms is None:
                self._next_ms = float(times.min())
        self._acks += [f for _, f in batch.others if isinstance(f, AckFrame)]

    def next_heard_s(self) -> float:
        """The stand time of the first frame heard from now on (a stand status or a heading),
        s: the switch-on of a run-up, the operator having just answered."""
        self._next_ms = None
        while self._next_ms is None:
            self.poll()
        return self._next_ms / 1000.0

    def take(self, until_ms: float) -> Headings:
        """The headings not yet taken stamped at or before `until_ms` (campaign ms), once the
        stand clock heard has reached it."""
        since_ms = self.now_ms  # (a run-up's record: its compass on, sending)
        while self.now_ms < until_ms - 1e-6:  # (a reading time's float sum: whole ms)
            self.poll()
            since_ms = since_ms if np.isfinite(since_ms) else self.now_ms
            quiet_s = (self.now_ms - max(self._heading_ms, since_ms)) / 1000.0
            if quiet_s > self._silence_s:  # (as the trials: `timeouts.bus_silence_s`)
                raise ProcedureBusError(
                    f"the compass is silent: no heading for {quiet_s:g} s of stand time while "
                    "the stand's clock went on"
                )
        pending = _joined([_empty(), *self._pending])
        later = np.flatnonzero(pending.t_ms > until_ms + 1e-6)  # (as `LoggedHeadings.take`)
        end = int(later[0]) if later.size else len(pending)
        self._pending = [pending.take(slice(end, None))]
        return pending.take(slice(0, end))

    def command(self, message: can.Message) -> None:
        """A stand command (encoded by the plan's codec) through the stand controller; an error
        unless the stand acknowledges it within [timeouts] ack_s (wall)."""
        frame = self.codec.decode(message)
        assert isinstance(frame, CommandFrame)
        self._acks.clear()
        try:
            seq = self.live.controller.post(
                frame.command, frame.direction_deg, frame.amplitude_cm, frame.period_s
            )
        except (StandError, can.CanError) as exc:
            raise ProcedureBusError(str(exc)) from exc
        timeout_s = self.plan.timeouts.ack_s
        deadline = time.monotonic() + timeout_s
        paired = not self.codec.has_sequence
        while True:
            for ack in self._acks:
                if ack.command == frame.command and (paired or ack.seq == seq):
                    if not ack.accepted:
                        raise ProcedureBusError(f"the stand refused {frame.command}: {ack.reason}")
                    self.rocking = frame.command == "start" or (
                        self.rocking and frame.command != "stop"
                    )
                    return
            if time.monotonic() > deadline:
                raise ProcedureBusError(
                    f"the stand did not acknowledge {frame.command!r} within {timeout_s:g} s"
                )
            self.poll()

    def stop_rocking(self) -> None:
        """The stand told to stop, if the procedures left it rocking (a stop, an error)."""
        if self.rocking:
            # (the bus gone: the stand's own watchdog stops it)
            with contextlib.suppress(StandError, can.CanError):
                self.live.controller.post("stop")
            self.rocking = False


class LiveRunUp(RunUp):
    """Run-up k of a compass on a real bus, switched on at campaign time `at_s` (the operator's
    answer): what `run_procedures` asks of a run-up, in real time. Every frame heard is
    recorded (nothing passes unheard on a real bus); frames before switch-on are not the
    run-up's."""

    def __init__(self, heard: BusHeadings, k: int, at_s: float) -> None:
        self.k, self.at_s = k, at_s
        self.codec = heard.codec
        self._bus = heard
        self._until_s = 0.0
        self._t, self._heading = [], []

    @property
    def now_s(self) -> float:
        # (as `StandEngine`: the time it was advanced to; the bus is heard a batch later, and
        # the readings' times follow from switch-on alone)
        return self._until_s

    @property
    def rehears(self) -> bool:
        return False

    def advance(self, until_s: float) -> None:
        self._until_s = max(self._until_s, until_s)
        heard = self._bus.take(round(self.at_s * 1000.0) + until_s * 1000.0)
        heard = heard.take(heard.t_ms >= round(self.at_s * 1000.0))
        if heard.t_ms.size:
            self._heard(heard)

    def pass_to(self, until_s: float) -> None:
        self.advance(until_s)

    def command(self, message: can.Message) -> None:
        self._bus.command(message)
