"""The campaign engine and the simulated stand in lockstep, without a bus or a clock: the stand
advances in fixed stand-time steps, the engine's commands reach it between steps, and every frame
(the commands included, as a raw log holds them) goes to the engine in stream order. Equal seeds
give equal frames, at any machine load (tests and benchmarks)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import can

from gyrostand.acquisition.engine import Command, Engine, Phase
from gyrostand.devices.decoder import SourceDecoder
from gyrostand.frames.batch import BatchDecoder, RawFrames
from gyrostand.stand.engine import HeadingTransmitter, StandEngine
from gyrostand.stand.protocol import Codec
from gyrostand.stand.simconfig import SimConfig


class Lockstep:
    """The engine's commander (`issue`) and its stream of frames (`steps`, `run`)."""

    def __init__(
        self,
        config: SimConfig,
        step_s: float = 5.0,
        codec: Codec | None = None,
        compass: tuple[HeadingTransmitter, Callable[[], SourceDecoder]] | None = None,
    ) -> None:
        """`compass`: a compass speaking another protocol (`devices`) and the decoder of its
        stream (a new one per run)."""
        self.codec = codec or Codec()
        transmitter, self._decoder = compass if compass is not None else (None, None)
        self.stand = StandEngine(config, self.codec, transmitter)
        self.step_s = step_s
        self.stream: list[can.Message] = []  # what `run` fed the engine
        self._pending: list[can.Message] = []

    def issue(self, command: Command, now_ms: int = 0) -> None:
        msg = self.codec.encode_command(
            command.kind, command.direction_deg, command.amplitude_cm, command.period_s
        )
        msg.timestamp = self.stand.stand_time_s
        self._pending += [msg, *self.stand.receive(msg)]

    def steps(self, engine: Engine, max_stand_s: float = 200_000.0) -> Iterator[list[can.Message]]:
        """Feed the engine step by step until it is done (or `max_stand_s`); each step's frames
        after the engine has taken them."""
        decoder: BatchDecoder | SourceDecoder = (
            BatchDecoder(Codec(self.codec.dbc_path, self.codec.signal_map))
            if self._decoder is None
            else self._decoder()
        )
        position, t = 0, 0.0
        while engine.phase is not Phase.DONE and t < max_stand_s:
            t += self.step_s
            frames, self._pending = self._pending + self.stand.advance_to(t), []
            engine.feed(decoder.decode(RawFrames.from_messages(position, frames)))
            position += len(frames)
            yield frames

    def run(self, engine: Engine, max_stand_s: float = 200_000.0) -> None:
        """Run the engine to its end, keeping every frame in `stream`."""
        for frames in self.steps(engine, max_stand_s):
            self.stream += frames
